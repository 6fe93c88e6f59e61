"""A deterministic discrete-event wire between two sans-I/O endpoints (test helper).

Each direction models a UART (line rate, bits per char) and a fixed delay; it
never reorders.  Filters see every packet as written and may drop it, replace
it (corrupt), or duplicate it, which lets scenario tests name exactly which
packet is lost.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable
from dataclasses import dataclass, field

from serialsocket import Endpoint, EndpointConfig, State

Filter = Callable[[str, bytes, float], list[bytes]]
"""(direction "ab"/"ba", one packet's wire bytes, time) -> packets to put on the line."""


def split_packets(data: bytes) -> list[bytes]:
    """Split concatenated wire output at each MARK (SOH)."""
    out: list[bytes] = []
    start = 0
    for i in range(1, len(data)):
        if data[i] == 1:
            out.append(data[start:i])
            start = i
    if data:
        out.append(data[start:])
    return out


@dataclass
class Direction:
    delay: float = 0.0
    rate: float | None = None
    bits: int = 10
    free_at: float = 0.0
    log: list[tuple[float, bytes]] = field(default_factory=list)

    def schedule(self, now: float, data: bytes) -> float:
        start = max(now, self.free_at)
        tx = 0.0 if self.rate is None else len(data) * self.bits / self.rate
        self.free_at = start + tx
        return self.free_at + self.delay


class SimLink:
    """Two endpoints joined by a simulated line, driven on explicit time."""

    def __init__(
        self,
        a: Endpoint,
        b: Endpoint,
        *,
        delay: float = 0.0,
        rate: float | None = None,
        filters: list[Filter] | None = None,
    ) -> None:
        self.a, self.b = a, b
        self.now = 0.0
        self.dirs = {"ab": Direction(delay, rate), "ba": Direction(delay, rate)}
        self.filters = filters or []
        self._heap: list[tuple[float, int, str, bytes]] = []
        self._n = 0
        self.sent: dict[str, list[tuple[float, bytes]]] = {"ab": [], "ba": []}

    def _ep(self, name: str) -> Endpoint:
        return self.a if name == "a" else self.b

    def flush(self) -> None:
        """Move whatever both endpoints want to send onto the line."""
        for direction, ep in (("ab", self.a), ("ba", self.b)):
            data = ep.data_to_send(self.now)
            for pkt in split_packets(data):
                self.sent[direction].append((self.now, pkt))
                outs = [pkt]
                for f in self.filters:
                    outs = [o for p in outs for o in f(direction, p, self.now)]
                for o in outs:
                    arrive = self.dirs[direction].schedule(self.now, o)
                    heapq.heappush(self._heap, (arrive, self._n, direction, o))
                    self._n += 1

    def next_time(self) -> float:
        times = [
            t
            for ep in (self.a, self.b)
            for t in (ep.get_timer(), ep.get_send_timer())
            if t is not None
        ]
        if self._heap:
            times.append(self._heap[0][0])
        return min(times) if times else math.inf

    def step(self) -> bool:
        """Advance to the next event and process it; False when nothing is left."""
        self.flush()
        t = self.next_time()
        if t == math.inf:
            return False
        self.now = max(self.now, t)
        while self._heap and self._heap[0][0] <= self.now:
            _, _, direction, data = heapq.heappop(self._heap)
            (self.b if direction == "ab" else self.a).receive_data(data, self.now)
        for ep in (self.a, self.b):
            timer = ep.get_timer()
            if timer is not None and timer <= self.now:
                ep.handle_timer(self.now)
        self.flush()
        return True

    def run_until(
        self, cond: Callable[[], bool], *, limit: float = 10_000.0, max_steps: int = 1_000_000
    ) -> None:
        """Step until ``cond()`` holds; fail if simulated time or steps run out."""
        for _ in range(max_steps):
            if cond():
                return
            if not self.step() or self.now > limit:
                break
        if not cond():
            raise AssertionError(f"condition not reached by t={self.now:.3f}")

    def run_for(self, seconds: float) -> None:
        end = self.now + seconds
        while self.next_time() <= end:
            self.step()
        self.now = end
        self.flush()


MOON_HINTS = EndpointConfig(one_way_delay=1.3, line_rate=2400)
"""Hints that match the default :func:`connected_pair` line: 2400 bit/s, 1.3 s one way."""


def connected_pair(
    cfg_a: EndpointConfig = MOON_HINTS,
    cfg_b: EndpointConfig = MOON_HINTS,
    *,
    delay: float = 1.3,
    rate: float | None = 2400,
    filters: list[Filter] | None = None,
) -> tuple[Endpoint, Endpoint, SimLink]:
    """Two endpoints, ``a`` connected to listening ``b``, established on a :class:`SimLink`."""
    a, b = Endpoint(cfg_a), Endpoint(cfg_b)
    link = SimLink(a, b, delay=delay, rate=rate, filters=filters)
    b.listen()
    a.connect(0.0)
    link.run_until(lambda: a.state is State.ESTABLISHED and b.state is State.ESTABLISHED)
    return a, b, link


class QueuedRun:
    """``a`` queues ``data`` (what fits), connects to listening ``b`` at t = 0 on
    a 2400 bit/s :class:`SimLink`, and queues the rest as room appears (early
    data, PROTOCOL.md 13; a first flight, 14)."""

    def __init__(
        self,
        data: bytes,
        cfg_a: EndpointConfig = MOON_HINTS,
        cfg_b: EndpointConfig = MOON_HINTS,
        filters: list[Filter] | None = None,
        *,
        delay: float = 1.3,
    ) -> None:
        self.a, self.b = Endpoint(cfg_a), Endpoint(cfg_b)
        self.link = SimLink(self.a, self.b, delay=delay, rate=2400, filters=filters)
        self.b.listen()
        self.data = data
        self.queued = self.a.send(data, 0.0)
        self.a.connect(0.0)

    def step(self) -> bool:
        if self.queued < len(self.data) and self.a.state is not State.FAILED:
            self.queued += self.a.send(self.data[self.queued :], self.link.now)
        return self.link.step()

    def read_all(self, n: int | None = None) -> tuple[bytes, float | None]:
        """Run until ``b`` has read ``n`` bytes (all of ``data``); the bytes and
        when the first came.  Fails if either side fails or 900 s pass."""
        n = len(self.data) if n is None else n
        got = bytearray()
        first = None
        while len(got) < n:
            assert self.step(), "the link went quiet"
            chunk = self.b.read()
            if chunk and first is None:
                first = self.link.now
            got += chunk
            assert self.link.now < 900
            assert self.b.state is not State.FAILED
            assert self.a.state is not State.FAILED
        return bytes(got), first


def drop_nth(kind: bytes, which: set[int], direction: str) -> Filter:
    """A filter dropping the packets of type ``kind`` numbered ``which`` (from
    1) in ``direction``; for ``Y``, init answers only (a long data field)."""
    seen = 0

    def f(d: str, pkt: bytes, now: float) -> list[bytes]:
        nonlocal seen
        if d == direction and pkt[3:4] == kind and (kind != b"Y" or len(pkt) > 20):
            seen += 1
            if seen in which:
                return []
        return [pkt]

    return f
