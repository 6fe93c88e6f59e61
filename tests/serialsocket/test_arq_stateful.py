"""ARQ fuzzing in ``make test``: the state machine of :mod:`fuzz.arq_machine` with the
CI profile, whole transfers under drawn loss and damage patterns, and pinned bugs.

``make fuzz`` runs the same machine with the deep profile (fuzz/test_arq_stateful.py).
"""

from __future__ import annotations

from collections.abc import Callable

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fuzz.arq_machine import LINGER, LIVENESS_TIMEOUT, ARQMachine, payloads
from serialsocket import (
    MAX_WINDOW,
    Connected,
    ConnectionClosed,
    EndOfStream,
    Endpoint,
    EndpointConfig,
    LocalProtocolError,
    State,
)
from serialsocket._config import MIN_ENDPOINT_PACKET_LENGTH
from serialsocket._endpoint import FINAL_ACK_COPIES
from serialsocket.packets import EIGHT_BIT_CLEAN, PRINTABLE, Encoding, PacketType
from tests.serialsocket.simlink import Filter, SimLink, split_packets


class TestARQ(ARQMachine.TestCase):  # type: ignore[misc,valid-type]
    """200 derandomized runs of 40 steps on top of the loaded (CI) profile."""

    settings = settings(max_examples=200, stateful_step_count=40)


# -- whole transfers under a drawn impairment plan -------------------------------------


def _plan_filter(plans: dict[str, dict[int, int | None]]) -> Filter:
    """A SimLink filter: for the n-th packet in a direction, ``None`` drops it, a
    positive int flips that bit (mod the packet's size), ``-1`` duplicates it."""
    counts = {"ab": 0, "ba": 0}

    def impair(direction: str, packet: bytes, now: float) -> list[bytes]:
        n = counts[direction]
        counts[direction] += 1
        if n not in plans[direction]:
            return [packet]
        action = plans[direction][n]
        if action is None:
            return []
        if action < 0:
            return [packet, packet]
        bit = action % (8 * len(packet))
        damaged = bytearray(packet)
        damaged[bit // 8] ^= 1 << (bit % 8)
        return [bytes(damaged)]

    return impair


def _transfer_and_close(
    config_a: EndpointConfig,
    config_b: EndpointConfig,
    data: dict[str, bytes],
    *,
    delay: float,
    rate: float | None,
    filters: list[Filter],
) -> None:
    """Send ``data`` both ways, half-close both sides, run until both are CLOSED
    (reading everything), and check the exact bytes and events."""
    a, b = Endpoint(config_a), Endpoint(config_b)
    link = SimLink(a, b, delay=delay, rate=rate, filters=filters)
    b.listen()
    a.connect(0.0)
    got = {"a": bytearray(), "b": bytearray()}
    for side, ep in (("a", a), ("b", b)):
        assert ep.send(data[side], 0.0) == len(data[side])
    # Half-close once all data is acknowledged (this scenario measures delivery, not the
    # early-EOF race: test_eof_acked_before_data_does_not_close has that).
    link.run_until(lambda: a.all_acknowledged and b.all_acknowledged, limit=2 * LINGER)
    a.send_eof(link.now)
    b.send_eof(link.now)

    def closed() -> bool:
        got["a"] += a.read(None, link.now)
        got["b"] += b.read(None, link.now)
        return a.state is State.CLOSED and b.state is State.CLOSED

    link.run_until(closed, limit=2 * LINGER)
    assert bytes(got["b"]) == data["a"]
    assert bytes(got["a"]) == data["b"]
    for ep in (a, b):
        assert [type(e) for e in ep.events()] == [Connected, EndOfStream, ConnectionClosed]
        assert ep.at_eof
        assert ep.all_acknowledged


def _config(window: int, length: int, rate: float | None, delay: float) -> EndpointConfig:
    return EndpointConfig(
        window=window,
        max_packet_length=length,
        one_way_delay=delay,
        line_rate=rate,
        dead_after=LIVENESS_TIMEOUT,
        connect_timeout=LIVENESS_TIMEOUT,
        linger=LINGER,
        send_buffer=64 * 1024,  # the whole stream is queued at once (the derived one is smaller)
    )


_windows = st.integers(1, MAX_WINDOW)
_lengths = st.sampled_from([38, 40, 94, 96, 128, 1000])
_rates = st.sampled_from([None, 2400.0, 115200.0])
_delays = st.sampled_from([0.0, 0.02, 1.3])


@given(
    window_a=_windows,
    window_b=_windows,
    length_a=_lengths,
    length_b=_lengths,
    rate=_rates,
    delay=_delays,
    data_a=payloads(3000),
    data_b=payloads(3000),
    drops_ab=st.sets(st.integers(0, 60), max_size=25),
    drops_ba=st.sets(st.integers(0, 60), max_size=25),
)
def test_any_loss_pattern_delivers_everything(
    window_a: int,
    window_b: int,
    length_a: int,
    length_b: int,
    rate: float | None,
    delay: float,
    data_a: bytes,
    data_b: bytes,
    drops_ab: set[int],
    drops_ba: set[int],
) -> None:
    """Losing any set of packets (by their index on the line, init, data, ACKs,
    NAKs and EOFs alike) still delivers both streams exactly and closes cleanly."""
    plans: dict[str, dict[int, int | None]] = {
        "ab": dict.fromkeys(drops_ab),
        "ba": dict.fromkeys(drops_ba),
    }
    _transfer_and_close(
        _config(window_a, length_a, rate, delay),
        _config(window_b, length_b, rate, delay),
        {"a": data_a, "b": data_b},
        delay=delay,
        rate=rate,
        filters=[_plan_filter(plans)],
    )


_actions = st.one_of(st.none(), st.just(-1), st.integers(0, 1 << 16))


@given(
    window=_windows,
    length=_lengths,
    encoding=st.sampled_from([PRINTABLE, EIGHT_BIT_CLEAN]),
    data_a=payloads(2000),
    data_b=payloads(2000),
    plan_ab=st.dictionaries(st.integers(0, 50), _actions, max_size=20),
    plan_ba=st.dictionaries(st.integers(0, 50), _actions, max_size=20),
)
def test_any_loss_damage_and_duplication_delivers_everything(
    window: int,
    length: int,
    encoding: Encoding,
    data_a: bytes,
    data_b: bytes,
    plan_ab: dict[int, int | None],
    plan_ba: dict[int, int | None],
) -> None:
    """Dropped, bit-flipped and duplicated packets, in any mix, in both directions."""
    config = EndpointConfig(
        window=window,
        max_packet_length=length,
        encoding=encoding,
        one_way_delay=0.02,
        dead_after=LIVENESS_TIMEOUT,
        connect_timeout=LIVENESS_TIMEOUT,
        linger=LINGER,
    )
    _transfer_and_close(
        config,
        config,
        {"a": data_a, "b": data_b},
        delay=0.02,
        rate=None,
        filters=[_plan_filter({"ab": plan_ab, "ba": plan_ba})],
    )


# -- bugs found by the fuzzer, pinned -------------------------------------------------


def test_smallest_packet_length_can_connect() -> None:
    with pytest.raises(LocalProtocolError, match="init packet must fit"):
        EndpointConfig(max_packet_length=MIN_ENDPOINT_PACKET_LENGTH - 1)
    config = EndpointConfig(max_packet_length=MIN_ENDPOINT_PACKET_LENGTH)
    a, b = Endpoint(config), Endpoint(config)
    b.listen()
    a.connect(0.0)
    b.receive_data(a.data_to_send(0.0), 0.0)
    assert b.state is State.ESTABLISHED
    a.receive_data(b.data_to_send(0.0), 0.0)
    assert a.state is State.ESTABLISHED


def test_dead_link_timer_fires_when_due() -> None:
    config = EndpointConfig(dead_after=2.0)
    a, b = Endpoint(config), Endpoint(config)
    b.listen()
    a.connect(0.0)
    b.receive_data(a.data_to_send(0.0), 0.0)
    a.receive_data(b.data_to_send(0.0), 0.03)  # Last heard at 0.03; B then falls silent.
    assert a.statistics().state == State.ESTABLISHED.value
    seen: list[float] = []
    for _ in range(10):
        timer = a.get_timer()
        assert timer is not None
        assert timer not in seen, f"timer {timer} handled and still due: {seen}"
        seen.append(timer)
        a.handle_timer(timer)
        a.data_to_send(timer)
        if a.state is State.DEAD:
            break
    assert a.state is State.DEAD
    assert seen == pytest.approx([0.53, 1.03, 1.53, 2.03])


def _drop_to_back_off_then_lose_last_ack() -> tuple[Filter, Callable[[], int]]:
    """Lose A's EOF twice (A's timeout backs off to 4x), then B's ACK of the third
    copy, with the copies B sends of the ACK that completes its close."""
    eofs = 0
    acks_dropped = 0

    def impair(direction: str, packet: bytes, now: float) -> list[bytes]:
        nonlocal eofs, acks_dropped
        if direction == "ab" and packet[3] == ord(PacketType.EOF.value):
            eofs += 1
            if eofs <= 2:
                return []
        lost = acks_dropped <= FINAL_ACK_COPIES
        if direction == "ba" and eofs == 3 and lost and packet[3] == ord("Y"):
            acks_dropped += 1
            return []
        return [packet]

    return impair, lambda: eofs


def test_linger_outlasts_peer_eof_retransmission() -> None:
    config = EndpointConfig(one_way_delay=0.01, dead_after=1000.0)
    a, b = Endpoint(config), Endpoint(config)
    impair, eofs = _drop_to_back_off_then_lose_last_ack()
    link = SimLink(a, b, delay=0.01, filters=[impair])
    b.listen()
    a.connect(0.0)
    link.run_until(lambda: a.state is State.ESTABLISHED and b.state is State.ESTABLISHED)
    b.send_eof(link.now)
    link.run_until(lambda: a.at_eof and b.all_acknowledged)
    a.send_eof(link.now)
    # B's ACK of A's third EOF is lost; B must still be there to answer the fourth.
    link.run_until(lambda: a.state is State.CLOSED and b.state is State.CLOSED)
    assert eofs() == 4
    assert [type(e) for e in a.events()] == [Connected, EndOfStream, ConnectionClosed]


def test_eof_acked_before_data_does_not_close() -> None:
    config = EndpointConfig(window=2)
    a, b = Endpoint(config), Endpoint(config)
    b.listen()
    a.connect(0.0)
    b.receive_data(a.data_to_send(0.0), 0.0)
    a.receive_data(b.data_to_send(0.0), 0.0)
    b.send_eof(0.0)
    a.send(b"x", 0.0)
    a.send_eof(0.0)
    _lost_data, eof = split_packets(a.data_to_send(0.0))
    b.receive_data(eof, 0.01)
    a.receive_data(b.data_to_send(0.01), 0.02)  # B's EOF, ACK of A's EOF, NAK of the data.
    assert not a.all_acknowledged
    assert a.state is State.ESTABLISHED, [type(e).__name__ for e in a.events()]
    assert a.data_to_send(0.02).endswith(_lost_data)  # The NAKed packet goes again.
