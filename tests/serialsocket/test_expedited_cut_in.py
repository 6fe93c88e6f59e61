"""An expedited packet cuts in (PROTOCOL.md 11, "Cutting in"): with a port
that can drop what it has not sent (``Endpoint.line_discards``), the packet
waits behind none of the data in the UART -- not even the packet on the
wire -- and everything the drop cut is sent again, so the stream stays
exact.  Two endpoints over the impairment engine's line
(:class:`linksim.link.LinkDirection`), whose ``discard`` is the flush.
"""

from __future__ import annotations

import math
import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from linksim.link import DirectionConfig, LinkDirection
from serialsocket import Endpoint, EndpointConfig, State

MOON = EndpointConfig(one_way_delay=1.3, line_rate=2400)
CHAR = 10 / 2400
PACKET = 129 * CHAR  # a full 128-character packet and its CR


class _Wire:
    """Two endpoints, two impaired directions, explicit time; the sender's
    flush requests (``take_discard``) reach its direction's ``discard``."""

    def __init__(self, *, discards: bool, ber: float = 0.0, seed: int = 1) -> None:
        line = DirectionConfig(rate=2400, delay=1.3, byte_error_rate=ber)
        self.a, self.b = Endpoint(MOON), Endpoint(MOON)
        self.a.line_discards = self.b.line_discards = discards
        self.ab = LinkDirection(line, seed=seed, direction=0)
        self.ba = LinkDirection(line, seed=seed, direction=1)
        self.now = 0.0
        self.stream = bytearray()
        self.lane: list[tuple[float, bytes]] = []
        self.flushes = 0
        self.payload = b""
        self.pos = 0
        self.b.listen()
        self.a.connect(0.0)

    def feed(self, payload: bytes) -> None:
        """The stream ``a`` sends, as fast as its send buffer takes it."""
        self.payload = payload
        self.pos = self.a.send(payload, self.now)

    @property
    def done(self) -> bool:
        """The whole payload arrived, and ``a`` knows it."""
        return len(self.stream) >= len(self.payload) and self.a.all_acknowledged

    def _out(self) -> None:
        if self.pos < len(self.payload) and self.a.state is State.ESTABLISHED:
            self.pos += self.a.send(memoryview(self.payload)[self.pos :], self.now)
        for ep, line in ((self.a, self.ab), (self.b, self.ba)):
            data = ep.data_to_send(self.now)
            if ep.take_discard():
                self.flushes += 1
                line.discard(self.now)
            line.send(data, self.now)

    def step(self) -> None:
        self._out()
        times = [
            t
            for ep in (self.a, self.b)
            for t in (ep.get_timer(), ep.get_send_timer())
            if t is not None
        ]
        times += [t for t in (self.ab.next_delivery(), self.ba.next_delivery()) if t is not None]
        assert times, "nothing left to happen"
        self.now = max(self.now, min(times))
        self.b.receive_data(self.ab.receive(self.now), self.now)
        self.a.receive_data(self.ba.receive(self.now), self.now)
        for ep in (self.a, self.b):
            t = ep.get_timer()
            if t is not None and t <= self.now:
                ep.handle_timer(self.now)
        self.stream += self.b.read(None, self.now)
        while (m := self.b.read_expedited()) is not None:
            self.lane.append((self.now, m))
        self._out()

    def run_until(self, cond: object, limit: float = 3600.0) -> None:
        assert callable(cond)
        while not cond():
            assert self.now < limit, f"not reached by t={self.now:.3f}"
            self.step()

    def run_to(self, t: float) -> None:
        self.run_until(lambda: self.now >= t or self._next() > t)
        self.now = max(self.now, t)
        self._out()

    def _next(self) -> float:
        times = [
            x
            for ep in (self.a, self.b)
            for x in (ep.get_timer(), ep.get_send_timer())
            if x is not None
        ]
        times += [x for x in (self.ab.next_delivery(), self.ba.next_delivery()) if x is not None]
        return min(times, default=math.inf)


def _stop_during_bulk(*, discards: bool, at: float) -> tuple[_Wire, bytes, float]:
    w = _Wire(discards=discards)
    w.run_until(lambda: w.a.state is State.ESTABLISHED)
    data = random.Random(1).randbytes(6000)
    w.feed(data)
    w.run_to(at)
    sent_at = w.now
    w.a.send_expedited(b"EMERGENCY STOP", w.now)
    w.run_until(lambda: bool(w.lane))
    w.run_until(lambda: w.done)
    return w, data, w.lane[0][0] - sent_at


@pytest.mark.parametrize("phase", range(8))
def test_the_message_cuts_in_at_every_moment_of_a_packet(phase: int) -> None:
    """Sent at eight moments across a data packet's transmission: it arrives
    one way plus its own line time after it was sent, plus at most the
    character in the shift register and one of rounding -- where, without
    the drop, it waited behind the packet on the wire and the pacer's
    horizon too.  The stream is exact and the packet length did not pay
    for the packets the drop cut (no loss counted on a clean line)."""
    at = 8.0 + phase * PACKET / 8
    own = 30 * CHAR  # the lane packet: 14 bytes and its framing, under 30 characters
    w, data, latency = _stop_during_bulk(discards=True, at=at)
    assert latency <= 1.3 + own + 2 * CHAR, latency
    assert [m for _, m in w.lane] == [b"EMERGENCY STOP"]
    assert bytes(w.stream) == data
    stats = w.a.statistics()
    assert stats.preemptions == w.flushes == 1
    assert stats.preempted_resends >= 1
    assert stats.byte_error_rate == 0.0
    assert stats.timeouts == 0
    assert w.b.statistics().duplicates_received <= stats.preempted_resends
    assert 2.6 <= (stats.smoothed_rtt or 0.0) < 3.5


def test_without_a_port_that_drops_nothing_is_cut_and_the_message_waits() -> None:
    latencies = []
    for phase in range(8):
        w, data, latency = _stop_during_bulk(discards=False, at=8.0 + phase * PACKET / 8)
        assert bytes(w.stream) == data
        assert w.flushes == 0
        assert w.a.statistics().preemptions == 0
        assert w.a.statistics().preempted_resends == 0
        latencies.append(latency)
    # Behind the packet on the wire, sometimes most of it.
    assert max(latencies) > 1.3 + PACKET / 2


def test_an_idle_line_has_nothing_to_drop() -> None:
    w = _Wire(discards=True)
    w.run_until(lambda: w.a.state is State.ESTABLISHED)
    w.run_to(w.now + 5.0)
    w.a.send_expedited(b"stop", w.now)
    w.run_until(lambda: bool(w.lane))
    assert w.flushes == 0
    assert w.a.statistics().preemptions == 0


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    ber=st.sampled_from([0.0, 1e-4, 1e-3]),
    times=st.lists(st.floats(0.0, 40.0), min_size=1, max_size=6),
)
def test_property_cuts_in_noise_keep_the_stream_exact_and_each_message_once(
    seed: int, ber: float, times: list[float]
) -> None:
    w = _Wire(discards=True, ber=ber, seed=seed)
    data = random.Random(seed).randbytes(8000)
    w.run_until(lambda: w.a.state is State.ESTABLISHED)
    w.feed(data)
    messages = []
    for i, t in enumerate(sorted(times)):
        w.run_to(max(w.now, 3.0 + t))
        message = f"stop {i}".encode()
        w.a.send_expedited(message, w.now)
        messages.append(message)
    w.run_until(lambda: w.done and w.a.expedited_settled, limit=7200.0)
    w.run_to(w.now + 30.0)  # late copies arrive as duplicates: never delivered again
    assert bytes(w.stream) == data
    assert [m for _, m in w.lane] == messages
    assert w.a.state is State.ESTABLISHED


def test_a_stream_of_expedited_messages_does_not_starve_the_stream() -> None:
    """A message every 0.3 s during a bulk transfer: were every one to cut
    the packet on the wire, no data packet would ever leave whole.  A drop
    never cuts a lane packet or a packet sent again after the last drop, so
    the stream advances between drops: it completes, every message arrives
    once, and far fewer drops happen than messages."""
    w = _Wire(discards=True)
    w.run_until(lambda: w.a.state is State.ESTABLISHED)
    data = random.Random(3).randbytes(4000)
    w.feed(data)
    messages = []
    t = w.now
    while not w.done:
        t += 0.3
        w.run_to(t)
        if len(messages) < 400 and not w.a.statistics().expedited_unacknowledged > 20:
            messages.append(f"m{len(messages)}".encode())
            w.a.send_expedited(messages[-1], w.now)
        assert w.now < 600.0, (len(w.stream), w.a.statistics())
    w.run_until(lambda: w.a.expedited_settled)
    w.run_to(w.now + 10.0)
    assert bytes(w.stream) == data
    assert [m for _, m in w.lane] == messages
    stats = w.a.statistics()
    assert 0 < stats.preemptions < len(messages) / 2, (stats.preemptions, len(messages))


@pytest.mark.parametrize("discards", [True, False])
def test_an_abort_cuts_in_too(discards: bool) -> None:
    """The application aborts mid-transfer: its E packet says why.  With a
    port that drops what it has not sent, nothing the UART holds matters
    any more and the E goes first: the peer hears it one way after the
    abort.  Without, it waits behind the packet on the wire and the
    pacer's horizon."""
    from serialsocket import ConnectionAborted

    w = _Wire(discards=discards)
    w.run_until(lambda: w.a.state is State.ESTABLISHED)
    w.feed(random.Random(4).randbytes(6000))
    w.run_to(8.0 + PACKET / 2)
    aborted_at = w.now
    w.a.abort("operator pressed Ctrl-C", w.now)
    heard: list[float] = []

    def told() -> bool:
        if any(isinstance(e, ConnectionAborted) and e.by_peer for e in w.b.events()):
            heard.append(w.now)
        return bool(heard)

    w.run_until(told, limit=60.0)
    latency = heard[0] - aborted_at
    if discards:
        assert latency <= 1.3 + 40 * CHAR, latency
        assert w.flushes == 1
    else:
        assert latency > 1.3 + PACKET / 4, latency
        assert w.flushes == 0
