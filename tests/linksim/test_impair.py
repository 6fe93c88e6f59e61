"""The sans-I/O impairment engine: exact timing, statistics with fixed seeds, faults."""

from __future__ import annotations

import numpy as np
import pytest

from linksim import DirectionConfig, Outage
from linksim.link import FaultAction, GilbertElliott, LinkDirection, ScriptedFault

N = 1_000_000


def run(config: DirectionConfig, data: bytes, *, seed: int = 1, chunk: int = 4096) -> bytes:
    """Write ``data`` at t=0 in ``chunk``-byte writes; everything that arrives."""
    d = LinkDirection(config, seed=seed)
    for i in range(0, len(data), chunk):
        d.send(data[i : i + chunk], 0.0)
    d.flush()
    out = d.receive(1e12)
    assert d.next_delivery() is None
    return out


def test_clean_line_is_transparent_and_instant() -> None:
    d = LinkDirection(DirectionConfig(), seed=0)
    d.send(b"hello", 3.0)
    assert d.next_delivery() == 3.0
    assert d.receive(3.0) == b"hello"
    assert d.next_delivery() is None
    s = d.statistics()
    assert (s.bytes_sent, s.bytes_delivered, s.bytes_in_flight, s.bytes_delayed) == (5, 5, 0, 0)


def test_byte_arrives_at_t_plus_delay_plus_char_time_exactly() -> None:
    d = LinkDirection(DirectionConfig(rate=2400, delay=1.3), seed=0)
    t = 5.0
    d.send(b"a", t)
    assert d.next_delivery() == t + 1.3 + 10 / 2400
    assert d.receive(t + 1.3) == b""
    assert d.receive(t + 1.3 + 10 / 2400) == b"a"
    assert d.transmit_done_at() == t + 10 / 2400


def test_uart_queues_back_to_back_and_reports_backlog() -> None:
    c = 10 / 1280  # 1/128 s: exact in binary
    d = LinkDirection(DirectionConfig(rate=1280, delay=0.5), seed=0)
    d.send(b"abcd", 1.0)
    assert d.queued(1.0) == 4
    d.send(b"ef", 1.0 + c)  # while the UART is still busy: queued behind
    assert d.transmit_done_at() == 1.0 + 6 * c
    assert d.queued(1.0 + c) == 5
    assert d.queued(1.0 + 6 * c) == 0
    assert d.drained_at(2) == 1.0 + 4 * c
    times = []
    while (t := d.next_delivery()) is not None:
        times.append(t)
        d.receive(t)
    assert times == [1.5 + k * c for k in range(1, 7)]
    # an idle line restarts at the write time, not at the previous departure
    d.send(b"g", 10.0)
    assert d.next_delivery() == 10.0 + 0.5 + c


def test_jitter_never_reorders_and_is_seeded() -> None:
    config = DirectionConfig(rate=9600, delay=0.25, jitter=0.2)
    data = bytes(range(256)) * 40
    d = LinkDirection(config, seed=5)
    d.send(data, 0.0)
    arrivals = []
    got = bytearray()
    while (t := d.next_delivery()) is not None:
        arrivals.append(t)
        got += d.receive(t)
    assert bytes(got) == data
    assert arrivals == sorted(arrivals)
    s = d.statistics()
    base_last = 0.25 + len(data) * 10 / 9600
    assert base_last < arrivals[-1] <= base_last + 0.2
    assert s.max_latency > 0.25 + 0.1  # jitter really added delay


def test_same_seed_same_output_other_seed_differs() -> None:
    config = DirectionConfig(
        loss=0.01,
        byte_error_rate=0.01,
        noise=0.01,
        jitter=0.01,
        rate=19200,
        burst=GilbertElliott(0.001, 0.1, error_bad=0.5),
    )
    data = bytes(range(256)) * 400
    assert run(config, data, seed=3) == run(config, data, seed=3)
    assert run(config, data, seed=3) != run(config, data, seed=4)
    # the other direction of the same seed draws from its own streams
    a = LinkDirection(config, seed=3, direction=0)
    b = LinkDirection(config, seed=3, direction=1)
    a.send(data, 0.0)
    b.send(data, 0.0)
    assert a.receive(1e9) != b.receive(1e9)


def test_loss_rate_within_tolerance() -> None:
    p = 0.01
    out = run(DirectionConfig(loss=p), bytes(N))
    measured = 1 - len(out) / N
    # 5 sigma of a binomial proportion: sqrt(p(1-p)/N) ~ 1e-4
    assert abs(measured - p) < 5 * (p * (1 - p) / N) ** 0.5
    assert measured == pytest.approx(0.010027, abs=1e-6)  # pinned: seed 1


def test_byte_error_rate_within_tolerance_and_bits_flipped() -> None:
    p = 1e-3
    data = bytes(range(256)) * (N // 256)
    out = run(DirectionConfig(byte_error_rate=p), data)
    assert len(out) == len(data)
    diff = np.frombuffer(out, np.uint8) ^ np.frombuffer(data, np.uint8)
    measured = np.count_nonzero(diff) / len(data)
    assert abs(measured - p) < 5 * (p / len(data)) ** 0.5
    # masks are uniform over 1..255: about 4 bits flipped per damaged byte
    bits = np.unpackbits(diff[diff != 0]).sum() / np.count_nonzero(diff)
    assert 3.8 < bits < 4.2


def test_noise_inserts_bytes_at_the_configured_rate() -> None:
    p = 1e-3
    d = LinkDirection(DirectionConfig(noise=p), seed=2)
    d.send(bytes(N), 0.0)
    out = d.receive(0.0)
    inserted = d.statistics().inserted_noise
    assert len(out) == N + inserted
    assert abs(inserted / N - p) < 5 * (p / N) ** 0.5


def test_gilbert_elliott_bursts_match_parameters() -> None:
    p_gb, p_bg = 0.01, 0.1
    config = DirectionConfig(burst=GilbertElliott(p_gb, p_bg, error_good=0.0, error_bad=1.0))
    d = LinkDirection(config, seed=3)
    for _ in range(N // 1000):
        d.send(bytes(1000), 0.0)  # run lengths must not care about write boundaries
    err = np.frombuffer(d.receive(0.0), np.uint8) != 0
    edges = np.diff(np.concatenate([[0], err.astype(np.int8), [0]]))
    runs = np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)
    s = d.statistics()
    assert s.bursts == len(runs)
    assert s.corrupted_burst == s.burst_bytes == err.sum()
    # bad fraction p_gb / (p_gb + p_bg) = 0.0909; mean burst 1/p_bg = 10 bytes
    assert err.mean() == pytest.approx(p_gb / (p_gb + p_bg), rel=0.05)
    assert runs.mean() == pytest.approx(1 / p_bg, rel=0.05)
    # geometric: P(length 1) = p_bg, P(length > 20) = (1 - p_bg)^20
    assert np.mean(runs == 1) == pytest.approx(p_bg, abs=0.01)
    assert np.mean(runs > 20) == pytest.approx((1 - p_bg) ** 20, abs=0.01)
    # and the good-state sojourns average 1/p_gb
    gaps = np.flatnonzero(edges == 1)[1:] - np.flatnonzero(edges == -1)[:-1]
    assert gaps.mean() == pytest.approx(1 / p_gb, rel=0.05)


def _burst_errors(d: LinkDirection, times: np.ndarray) -> np.ndarray:
    """Send one zero byte at each time; which of them arrived corrupted."""
    for t in times.tolist():
        d.send(b"\0", t)
    return np.frombuffer(d.receive(1e12), np.uint8) != 0


def _runs(err: np.ndarray) -> np.ndarray:
    edges = np.diff(np.concatenate([[0], err.astype(np.int8), [0]]))
    return np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)


def test_gilbert_elliott_steps_in_line_time_not_per_byte_sent() -> None:
    """On a rated line the chain steps once per character time, sent on or idle.
    Back-to-back bytes see the per-byte chain; bytes one second apart on a 2400
    bit/s line (240 character times) see nearly independent states -- a fade of
    10 character times must not swallow ten one-a-second ACKs in a row."""
    p_gb, p_bg = 0.01, 0.1
    burst = GilbertElliott(p_gb, p_bg, error_good=0.0, error_bad=1.0)
    config = DirectionConfig(rate=2400, burst=burst)
    c = config.char_time
    d = LinkDirection(config, seed=3)
    for k in range(200):
        d.send(bytes(1000), k * 1000 * c)  # back to back, in 1000-byte writes
    busy = np.frombuffer(d.receive(1e12), np.uint8) != 0
    assert _runs(busy).mean() == pytest.approx(1 / p_bg, rel=0.05)
    assert busy.mean() == pytest.approx(p_gb / (p_gb + p_bg), rel=0.08)

    d = LinkDirection(config, seed=4)
    sparse = _burst_errors(d, np.arange(20_000) * 1.0)
    assert sparse.mean() == pytest.approx(p_gb / (p_gb + p_bg), rel=0.1)
    # Two bytes a second apart are both bad with about the stationary chance,
    # so bad runs of sparse bytes are ~1.1 long, not 1/p_bg = 10.
    assert _runs(sparse).mean() < 1.3
    # A 10-character burst never spans two bytes 240 character times apart.
    assert d.statistics().bursts == sparse.sum()


def test_gilbert_elliott_crosses_long_idle_gaps_exactly_and_reproducibly() -> None:
    """Gaps far longer than a good-bad cycle (hours of idle line) are crossed in
    one step drawn from the exact n-step transition: the states of bytes an
    hour apart follow the stationary law, and the same seed and times give the
    same states."""
    p_gb, p_bg = 0.02, 0.2
    burst = GilbertElliott(p_gb, p_bg, error_good=0.0, error_bad=1.0)
    config = DirectionConfig(rate=9600, burst=burst)
    times = np.arange(5000) * 3600.0
    first = _burst_errors(LinkDirection(config, seed=8), times)
    again = _burst_errors(LinkDirection(config, seed=8), times)
    assert (first == again).all()
    assert first.mean() == pytest.approx(p_gb / (p_gb + p_bg), abs=0.02)
    # A mix of back-to-back writes and long gaps keeps write boundaries irrelevant
    # within a busy stretch: 100 bytes in one write or in ten are hit at the same
    # places (with error_bad = 1 a hit is exactly a bad state).
    c = config.char_time
    one, ten = LinkDirection(config, seed=2), LinkDirection(config, seed=2)
    for hour in range(50):
        one.send(bytes(100), hour * 3600.0)
        for k in range(10):
            ten.send(bytes(10), hour * 3600.0 + 10 * k * c)
    hit_one = np.frombuffer(one.receive(1e12), np.uint8) != 0
    hit_ten = np.frombuffer(ten.receive(1e12), np.uint8) != 0
    assert hit_one.any()
    assert (hit_one == hit_ten).all()


def test_burst_drop_mode_removes_bytes() -> None:
    config = DirectionConfig(burst=GilbertElliott(0.01, 0.1, error_bad=1.0, drop=True))
    d = LinkDirection(config, seed=9)
    d.send(bytes(100_000), 0.0)
    out = d.receive(0.0)
    s = d.statistics()
    assert s.dropped_burst == s.burst_bytes > 0
    assert len(out) == 100_000 - s.dropped_burst


def test_outage_drops_exactly_the_bytes_on_the_wire() -> None:
    # c = 1/128 s, delay 0.5 s, outage [2, 3): byte k is on the wire from k/128
    # to 0.5 + (k+1)/128, so bytes 191..383 are lost.
    config = DirectionConfig(rate=1280, delay=0.5, outages=(Outage(2.0, 3.0),))
    data = bytes(range(256)) * 4
    d = LinkDirection(config, seed=0)
    d.send(data, 0.0)
    assert d.in_outage(2.0)
    assert not d.in_outage(3.0)
    assert d.receive(100.0) == data[:191] + data[384:]
    assert d.statistics().dropped_outage == 193


def soh_packets(n: int) -> list[bytes]:
    return [b"\x01" + bytes([0x20 + i]) + b"%dY" % i + b"payload\r" for i in range(n)]


@pytest.mark.parametrize("chunk", [1, 7, 4096])
def test_drop_third_packet_that_starts_with_soh(chunk: int) -> None:
    packets = soh_packets(6)
    fault = ScriptedFault(FaultAction.DROP, packet=3)
    out = run(DirectionConfig(faults=(fault,)), b"noise" + b"".join(packets), chunk=chunk)
    assert out == b"noise" + b"".join(packets[:2] + packets[3:])


@pytest.mark.parametrize("chunk", [1, 3, 4096])
def test_wildcard_selects_the_second_ack(chunk: int) -> None:
    # Kermit-like: SOH LEN SEQ TYPE ...; ACKs have type 'Y' at offset 3
    pkts = [b"\x01#%cD..\r" % (32 + i) if i % 2 else b"\x01#%cY\r" % (32 + i) for i in range(8)]
    fault = ScriptedFault(FaultAction.DROP, packet=2, starts_with=b"\x01??Y", wildcard=ord("?"))
    out = run(DirectionConfig(faults=(fault,)), b"".join(pkts), chunk=chunk)
    assert out == b"".join(pkts[:2] + pkts[3:])  # pkts[0] is the 1st ACK, pkts[2] the 2nd


def test_corrupt_byte_1000_and_nothing_else() -> None:
    data = bytes(range(256)) * 8
    fault = ScriptedFault(FaultAction.CORRUPT, byte=1000, xor=0x04)
    out = run(DirectionConfig(faults=(fault,)), data, chunk=333)
    expected = bytearray(data)
    expected[1000] ^= 0x04
    assert out == bytes(expected)


def test_insert_and_packet_corrupt() -> None:
    packets = soh_packets(4)
    faults = (
        ScriptedFault(FaultAction.INSERT, byte=0, data=b"GARBAGE"),
        ScriptedFault(FaultAction.CORRUPT, packet=2, offset=4),
        ScriptedFault(FaultAction.INSERT, packet=4, data=b"\x01\x01"),
    )
    d = LinkDirection(DirectionConfig(faults=faults), seed=0)
    d.send(b"".join(packets), 0.0)
    second = bytearray(packets[1])
    second[4] ^= 0xFF
    assert (
        d.receive(0.0) == b"GARBAGE" + packets[0] + second + packets[2] + b"\x01\x01" + (packets[3])
    )
    s = d.statistics()
    assert (s.faults_fired, s.inserted_scripted, s.corrupted_scripted) == (3, 9, 1)


def test_held_prefix_is_released_by_flush() -> None:
    fault = ScriptedFault(FaultAction.DROP, packet=1, starts_with=b"\x01??Y", wildcard=ord("?"))
    d = LinkDirection(DirectionConfig(faults=(fault,)), seed=0)
    d.send(b"abc\x01#", 0.0)
    assert d.receive(0.0) == b"abc"  # "\x01#" might start an ACK: held
    assert d.statistics().bytes_held == 2
    d.flush()
    assert d.receive(0.0) == b"\x01#"


def test_statistics_account_for_every_byte() -> None:
    config = DirectionConfig(
        loss=0.02,
        byte_error_rate=0.02,
        noise=0.02,
        burst=GilbertElliott(0.01, 0.2, error_bad=0.5, drop=True),
        outages=(Outage(0.5, 0.6),),
        rate=115200,
        delay=0.1,
    )
    d = LinkDirection(config, seed=11)
    data = bytes(range(256)) * 100
    d.send(data, 0.0)
    half = d.receive(1.0)
    s = d.statistics()
    assert s.bytes_sent == len(data)
    assert s.bytes_dropped == s.dropped_loss + s.dropped_burst + s.dropped_outage > 0
    assert s.bytes_inserted == s.inserted_noise > 0
    assert s.bytes_delivered == len(half)
    assert s.bytes_delivered + s.bytes_in_flight == len(data) - s.bytes_dropped + s.bytes_inserted
    assert s.bytes_corrupted == s.corrupted_random > 0


@pytest.mark.parametrize("offset", [-1, 0, 1])
def test_gilbert_elliott_jump_threshold_is_the_same_inside_and_across_calls(offset: int) -> None:
    """An idle gap right at the jump threshold is crossed the same way whether it
    falls between two calls or inside one (white-box: held-back bytes are the
    only way a gap lands inside one call through the public API)."""
    burst = GilbertElliott(0.1, 0.4, error_good=0.0, error_bad=1.0)
    config = DirectionConfig(rate=9600, burst=burst)
    far = int(64 * (1 / 0.1 + 1 / 0.4))
    first = np.arange(1, 51)
    second = 50 + far + offset + np.arange(1, 51)
    deps = np.concatenate([first, second, second[-1] + 5 + np.arange(1, 2001)]) * config.char_time

    def states(cut: int) -> tuple[np.ndarray, int]:
        d = LinkDirection(config, seed=5)
        got = np.concatenate([d._burst_states(deps[:cut]), d._burst_states(deps[cut:])])
        return got, d.statistics().bursts

    across, bursts_across = states(50)  # the gap between the calls
    inside, bursts_inside = states(100)  # the gap inside the first call
    assert (across == inside).all()
    assert bursts_across == bursts_inside


# -- an output flush (discard) -----------------------------------------------------------


def test_discard_drops_what_has_not_left_the_uart_and_keeps_the_rest() -> None:
    c = 10 / 2400
    d = LinkDirection(DirectionConfig(rate=2400, delay=1.3), seed=0)
    d.send(b"A" * 100, 0.0)
    # At 0.1 s, 24 characters have left and the 25th is in the shift register.
    assert d.discard(0.1) == 75
    assert d.transmit_done_at() == pytest.approx(0.1 + c)
    assert d.statistics().bytes_discarded == 75
    d.send(b"B" * 10, 0.2)  # an idle UART: leaves at once, one delay later
    assert d.next_delivery() == pytest.approx(c + 1.3)
    assert d.receive(0.2 + 1.3 + 10 * c + 1e-9) == b"A" * 25 + b"B" * 10
    assert d.pending() == 0


def test_discard_keeps_the_far_ends_timing_of_what_is_left() -> None:
    """Bytes written after a flush arrive one delay after they leave, not
    behind the arrival times of the bytes that were dropped."""
    c = 10 / 2400
    d = LinkDirection(DirectionConfig(rate=2400, delay=1.3, jitter=0.0), seed=0)
    d.send(b"x" * 480, 0.0)  # two seconds of line
    d.discard(0.5)
    d.send(b"y", 0.5)
    got = d.receive(0.5 + c + c + 1.3 + 1e-9)
    assert got.endswith(b"y")
    assert got.count(b"x") == 121


def test_discard_on_a_noisy_line_drops_whole_decided_runs() -> None:
    cfg = DirectionConfig(rate=9600, delay=0.2, byte_error_rate=1e-2, noise=1e-2)
    d = LinkDirection(cfg, seed=3)
    for i in range(10):
        d.send(bytes([65 + i]) * 200, 0.0)
    dropped = d.discard(0.5)
    left = d.receive(100.0)
    assert dropped > 0
    # What was kept left the UART by 0.5 s (plus the character in flight): at
    # most 481 written bytes, give or take the noise the line inserted.
    assert len(left) < 481 * 1.05
    assert d.pending() == 0
    assert d.statistics().bytes_discarded == dropped


def test_discard_is_a_no_op_without_a_rate_or_with_nothing_queued() -> None:
    d = LinkDirection(DirectionConfig(delay=1.0), seed=0)
    d.send(b"abc", 0.0)
    assert d.discard(0.0) == 0
    assert d.receive(1.0) == b"abc"
    e = LinkDirection(DirectionConfig(rate=2400), seed=0)
    e.send(b"abc", 0.0)
    assert e.discard(1.0) == 0
    assert e.receive(1.0) == b"abc"


def test_discard_also_drops_bytes_held_for_a_scripted_match() -> None:
    fault = ScriptedFault(action=FaultAction.DROP, packet=2, starts_with=b"\x01 ")
    d = LinkDirection(DirectionConfig(rate=2400, faults=(fault,)), seed=0)
    d.send(b"hello\x01", 0.0)  # the MARK is held: it may start a match
    assert d.statistics().bytes_held == 1
    assert d.discard(0.0) == 5  # everything after the first character
    assert d.statistics().bytes_held == 0
    d.flush()
    assert d.receive(10.0) == b"h"
