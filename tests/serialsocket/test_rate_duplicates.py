"""Duplicates and bunched ACKs never make the line look faster than it is.

The ACK clock measures the line from the time between two ACKs.  An ACK that
waited at the far end -- behind the peer's other ACKs (a line that
duplicates them, or duplicates our data so that the peer answers each copy),
or in a receiver that stalled and then read a burst -- makes the next
interval short by the wait: the ACKs come back to back, spaced by the peer's
line and not by ours, and a 300 bit/s line with 39-character packets and
16-character ACKs "measured" 2.4 times its rate.  The deep stateful fuzzer
found it (measured 615-1170 bit/s on a 300 bit/s line); paced at that, the
sender flooded the line, every packet was resent before its ACK came, and
with no packet acknowledged on its only copy nothing measured the line
again: the connection never closed after the line healed.

Now a sample shows the line at most a little faster than its bytes were
handed over (:data:`serialsocket._rate.SEND_SLACK`), and a raise no later
busy run confirmed is undone by the next retransmission timeout, with the
packets still queued timed from when they will really leave.  And any
packet's time from handing to ACK bounds the round trip the others are judged
by, so an init answer held up at the far end no longer makes every later one
look impossible.  Virtual time, deterministic.
"""

from __future__ import annotations

import heapq
import random
from dataclasses import dataclass

from serialsocket import Endpoint, EndpointConfig, State
from serialsocket._rate import RateEstimator

from .simlink import Direction, Filter, SimLink

RATE = 300
"""The line, bit/s (10 bits per character: 30 characters a second)."""


def test_acks_bunched_at_the_far_end_never_measure_a_faster_line() -> None:
    """A paced sender on a 30 char/s line; the receiver stalls for 20 s, then
    reads the burst and answers it with ACKs back to back on its own line."""
    line, packet, ack = RATE / 10, 39, 16
    tx, ack_tx = packet / line, ack / line
    est = RateEstimator(line)
    est.hand(38)  # the init
    start = 2 * 38 / line
    est.start(start, start)
    events: list[tuple[float, int, int]] = []
    back_free = 0.0
    for k in range(60):
        handed = start + k * tx  # paced: one packet per transmit time
        arrives = handed + tx
        if 20.0 <= arrives < 40.0:
            arrives = 40.0  # the receiver reads the stalled burst at once
        back_free = max(back_free, arrives) + ack_tx  # its ACKs queue on its line
        heapq.heappush(events, (handed, 0, k))
        heapq.heappush(events, (back_free, 1, k))
    marks = {}
    worst = 0.0
    while events:
        now, kind, k = heapq.heappop(events)
        if kind == 0:
            est.hand(packet)
            marks[k] = est.mark(now)
            continue
        mark = marks[k]
        assert mark is not None
        departed = start + k * tx + tx
        est.on_delivery(mark, now, now - departed, 1.0, fast=False, wire_bytes=packet)
        worst = max(worst, est.measured or 0.0, est.rate or 0.0)
    # Before: 73 char/s (the ACK clock of the peer's line: 39 characters per
    # 16-character ACK), and the pacer followed it.  Now at most SEND_SLACK
    # (1.1) times the rate the bytes were handed at.
    assert worst <= 1.15 * line, worst


@dataclass
class _StalledReceiver(Direction):
    """A line whose far end stops reading from ``stall[0]`` to ``stall[1]``:
    what arrives meanwhile waits in its input buffer and is read at once."""

    stall: tuple[float, float] = (0.0, 0.0)

    def schedule(self, now: float, data: bytes) -> float:
        arrives = super().schedule(now, data)
        if self.stall[0] <= arrives < self.stall[1]:
            return self.stall[1]
        return arrives


@dataclass
class _Run:
    done: bool
    seconds: float
    timeouts: int
    peak_measured: float
    rate: float | None


def _transfer(
    *,
    hint: float | None,
    delay: float,
    max_len: int,
    size: int,
    filters: list[Filter] | None = None,
    stall: tuple[float, float] | None = None,
    time_cap: float = 2_000.0,
) -> _Run:
    """``size`` random bytes from a to b at RATE, both ends told ``hint``."""
    cfg = EndpointConfig(one_way_delay=delay, line_rate=hint, window=31, max_packet_length=max_len)
    a, b = Endpoint(cfg), Endpoint(cfg)
    link = SimLink(a, b, delay=delay, rate=RATE, filters=filters)
    if stall is not None:
        link.dirs["ab"] = _StalledReceiver(delay, RATE, stall=stall)
    b.listen()
    a.connect(0.0)
    link.run_until(lambda: a.state is State.ESTABLISHED and b.state is State.ESTABLISHED)
    data = random.Random(size).randbytes(size)
    sent, got, peak = 0, bytearray(), 0.0
    while len(got) < size and link.now < time_cap:
        sent += a.send(data[sent:], link.now)
        if not link.step():
            break
        got += b.read(None, link.now)
        peak = max(peak, a.statistics().measured_rate or 0.0)
    assert bytes(got) == data[: len(got)]
    st = a.statistics()
    return _Run(len(got) == size, link.now, st.timeouts, peak, st.line_rate)


def test_a_line_that_duplicates_the_acks_is_not_measured_faster() -> None:
    """For a minute the line carries every ACK five times (a modem repeating
    them): the peer's line backs up with ACKs, and when the copies stop the
    backlog drains 16-character ACKs for 60-character packets back to back.
    Before: measured 494 bit/s, 35 timeouts."""

    def five_acks(direction: str, packet: bytes, now: float) -> list[bytes]:
        return [packet] * 5 if direction == "ba" and 20 <= now < 80 else [packet]

    run = _transfer(hint=RATE, delay=0.0, max_len=60, size=6_000, filters=[five_acks])
    assert run.done
    assert run.peak_measured <= 1.25 * RATE, run
    assert run.timeouts <= 10, run


def test_duplicated_acks_do_not_start_a_retransmission_storm() -> None:
    """Every ACK twice for a minute, 1.3 s one way.  Before: 120 timeouts, the
    rate left at twice the line, and the 6000 bytes took 670 s; the line
    needs 430."""

    def two_acks(direction: str, packet: bytes, now: float) -> list[bytes]:
        return [packet] * 2 if direction == "ba" and 20 <= now < 80 else [packet]

    run = _transfer(hint=RATE, delay=1.3, max_len=60, size=6_000, filters=[two_acks])
    assert run.done
    assert run.seconds < 500, run
    assert run.timeouts <= 10, run


def test_a_stalled_receiver_does_not_make_the_sender_flood() -> None:
    """The receiver reads nothing for 20 s, then the burst; its ACKs go back
    to back.  Before: measured 719 bit/s on the 300 bit/s line, paced by it,
    every packet resent before its ACK came (1801 timeouts), and 6000 bytes
    not delivered in 2000 s."""
    run = _transfer(hint=RATE, delay=1.3, max_len=38, size=6_000, stall=(30.0, 50.0))
    assert run.done, run
    assert run.seconds < 600, run
    assert run.peak_measured <= 1.15 * RATE, run
    assert run.timeouts <= 30, run


def test_a_raise_from_bunched_acks_is_undone_and_its_queue_drained() -> None:
    """No hints: the first flight goes out at once, and the stalled
    receiver's ACKs for it come back to back, so the busy run measuring the
    line sees six times its rate.  Nothing queued could disprove it: the
    packets paced at that rate were all resent before their ACKs (paced at
    1766 bit/s, 1784 timeouts, 6000 bytes not delivered in 2000 s).  The first timeout
    now takes the unconfirmed raise back, and the packets still in the queue
    it built are timed from when they will leave.

    Since rate pairs (PROTOCOL.md 4.6) the first flight's pair measures the
    line at 14.7 s, before the stall; the busy run that spans the stall then
    measures 125 bit/s, and early ACKs take 70 s to ramp back to the line:
    541 s where the line needs 430 (under 500 before pairs).  Not a storm
    (three timeouts), but a busy run across a receiver's stall is still
    taken for the line."""
    run = _transfer(hint=None, delay=1.3, max_len=94, size=6_000, stall=(20.0, 40.0))
    assert run.done, run
    assert run.seconds < 600, run
    assert run.timeouts <= 10, run
    assert run.rate is not None
    assert abs(run.rate - RATE) <= 0.05 * RATE, run


def test_a_held_up_init_answer_does_not_blind_the_estimator() -> None:
    """The init's answer waits 60 s at the far end (its reader stalled as the
    connection opened): the init exchange measures a 60 s round trip on a
    9600 bit/s line with no delay.  That round trip is the reference every
    later one is judged by, and all of them came out "impossible": none gave
    a sample, the base round trip stayed 60 s (so no queue could ever show),
    the rate ramped to four times the line, and the pacer, seeing a long idle
    line, filled it with 1346 copies of packets already on their way.  Found
    by the deep stateful fuzzer at 115 200 bit/s, where the copies still
    queued on the line kept it from closing in bounded time.  Any packet's
    time from handing to ACK bounds the path, as the init's does."""
    rate = 9600
    cfg = EndpointConfig(one_way_delay=0.0, line_rate=rate, window=31, max_packet_length=38)
    a, b = Endpoint(cfg), Endpoint(cfg)
    link = SimLink(a, b, delay=0.0, rate=rate)
    link.dirs["ba"] = _StalledReceiver(0.0, rate, stall=(0.0, 60.0))
    b.listen()
    a.connect(0.0)
    link.run_until(lambda: a.state is State.ESTABLISHED and b.state is State.ESTABLISHED)
    data = random.Random(1).randbytes(20_000)
    sent, got = 0, bytearray()
    while len(got) < len(data) and link.now < 1_000:
        sent += a.send(data[sent:], link.now)
        link.step()
        got += b.read(None, link.now)
    assert bytes(got) == data
    st = a.statistics()
    assert st.base_rtt is not None
    assert st.base_rtt < 0.5, st  # 38 + 13 characters at 960 a second, and no delay
    assert st.smoothed_rtt is not None
    assert st.smoothed_rtt < 1.0, st
    assert st.idle_copies <= 10, st
    assert st.line_rate is not None
    assert abs(st.line_rate - rate) < 0.01 * rate, st
