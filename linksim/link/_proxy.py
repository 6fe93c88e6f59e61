"""The TCP impairment proxy (``linksim proxy``): a bad line in front of a real TCP server.

A client connects to the proxy; the proxy connects to the server and carries
each direction through a model of the line, in real time: client to server
is the line's ``a_to_b`` direction ("up"), server to client ``b_to_a``
("down").  The same :class:`~linksim.link.LinkConfig` and presets as the pty
relay describe the line.

TCP repairs what a line damages, so the proxy delivers what TCP would make of
it rather than damaged bytes (which no TCP stack ever hands to a program):

* rate: segments leave one after another at the line rate (``bits_per_char``
  bits a byte);
* delay and jitter: each segment arrives ``delay`` plus up to ``jitter``
  later, never before the segment ahead of it (TCP delivers in order);
* loss, byte errors, noise and Gilbert-Elliott bursts: a segment that any of
  them hits is lost and arrives one retransmission timeout later (doubling
  for each further loss of the same segment), and everything behind it waits
  for it -- a stall, as on a real connection;
* outages: a segment on the wire during one is lost, and its retransmission
  leaves once the outage is over;
* cuts (:class:`Cut`): after a given number of bytes in one direction the
  proxy resets both connections (TCP RST), the way a NAT timeout or a modem
  drop ends a session mid-packet.

The timing model (:class:`TcpDirection`) is sans-I/O and seeded: the same
seed and the same writes give the same arrival times.  Link time starts when
the proxy starts listening (outages are counted from there).
"""

from __future__ import annotations

import contextlib
import math
import random
import socket
import struct
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import trio

from ._config import DirectionConfig, LinkConfig

__all__ = ["Cut", "ProxyStatistics", "TcpDirection", "run_proxy"]

SEGMENT = 1460
"""Bytes per modelled TCP segment (an Ethernet MSS): the unit of loss."""
MIN_RTO = 0.2
"""The smallest retransmission timeout (s), Linux's floor."""
BUFFER = 1 << 16
"""Bytes a direction holds before it stops reading its source (back-pressure)."""
CONNECT_TIMEOUT = 10.0
"""Seconds to reach the server for a new client before giving that client up."""
_DIRECTIONS = ("up", "down")


@dataclass(frozen=True, slots=True)
class Cut:
    """Reset a connection after ``after`` bytes have passed ``direction``
    (``"up"``: client to server, ``"down"``: server to client).

    The bytes before the offset are delivered; then both sides see the
    connection reset."""

    direction: str
    after: int

    def __post_init__(self) -> None:
        if self.direction not in _DIRECTIONS:
            raise ValueError(f"a cut's direction is up or down, got {self.direction!r}")
        if not (isinstance(self.after, int) and self.after >= 0):
            raise ValueError(f"a cut's offset is a byte count >= 0, got {self.after!r}")

    @classmethod
    def parse(cls, text: str) -> Cut:
        """``up:N`` or ``down:N`` (``--cut``)."""
        direction, _, offset = text.partition(":")
        try:
            return cls(direction, int(offset))
        except ValueError as exc:
            raise ValueError(f"--cut wants up:BYTES or down:BYTES, got {text!r} ({exc})") from None


class TcpDirection:
    """When each segment written to one direction arrives (sans-I/O).

    :meth:`send` takes a segment's length and the time it is written, and
    returns its arrival time; arrival times never decrease.  ``rtt`` is the
    connection's round trip, for the retransmission timeout (default: twice
    the delay)."""

    def __init__(
        self, config: DirectionConfig, rng: random.Random, *, rtt: float | None = None
    ) -> None:
        self.config = config
        self._rng = rng
        # A steady path's RTO: the round trip plus the 200 ms floor on its
        # variance (srtt + max(4 rttvar, 200 ms), RFC 6298 as Linux runs it).
        self._rto = (2 * config.delay if rtt is None else rtt) + MIN_RTO
        self._line_free = 0.0  # when the line has sent everything written so far
        self._last_arrival = 0.0
        self._bad = False  # the Gilbert-Elliott chain's state
        self.segments = 0
        self.retransmissions = 0
        self.held_by_outage = 0

    def send(self, length: int, now: float) -> float:
        """Arrival time of ``length`` bytes written at ``now``."""
        c = self.config
        airtime = length * c.char_time
        departure = max(now, self._line_free)
        self._line_free = departure + airtime
        arrival = departure + airtime + c.delay + self._rng.uniform(0.0, c.jitter)
        rto = self._rto
        while True:
            outage = self._outage_during(arrival - c.delay - airtime, arrival)
            if outage is not None:
                # Lost in the outage; the retransmission leaves after it.
                self.held_by_outage += 1
                arrival = outage + rto + airtime + c.delay
                continue
            if not self._damaged(length):
                break
            self.retransmissions += 1
            arrival += rto
            rto *= 2
        arrival = max(arrival, self._last_arrival)  # in order, as TCP delivers
        self._last_arrival = arrival
        self.segments += 1
        return arrival

    def _outage_during(self, start: float, end: float) -> float | None:
        """The end of an outage overlapping [start, end], if one does."""
        for o in self.config.outages:
            if o.start <= end and start < o.end:
                return o.end
        return None

    def _damaged(self, length: int) -> bool:
        c = self.config
        clean = (1 - c.loss) * (1 - c.byte_error_rate) * (1 - c.noise)
        hit = self._rng.random() >= clean**length
        burst = c.burst
        if burst is not None:
            # The chain steps once a byte here (a segment is back-to-back bytes).
            for _ in range(length):
                flip = burst.p_bad_to_good if self._bad else burst.p_good_to_bad
                if self._rng.random() < flip:
                    self._bad = not self._bad
                error = burst.error_bad if self._bad else burst.error_good
                if error and self._rng.random() < error:
                    hit = True
        return hit


@dataclass(slots=True)
class ProxyStatistics:
    """Counters of a proxy run, kept up to date while it runs."""

    connections: int = 0
    failed_upstream: int = 0
    """Clients whose server connection could not be made (closed at once)."""
    cuts: int = 0
    bytes_up: int = 0
    bytes_down: int = 0
    segments: int = 0
    retransmissions: int = 0
    """Segments the line model lost and TCP resent (each a stall)."""
    held_by_outage: int = 0
    errors: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, object]:
        return {
            "connections": self.connections,
            "failed_upstream": self.failed_upstream,
            "cuts": self.cuts,
            "bytes_up": self.bytes_up,
            "bytes_down": self.bytes_down,
            "segments": self.segments,
            "retransmissions": self.retransmissions,
            "held_by_outage": self.held_by_outage,
        }


class _CutReached(Exception):
    """A cut's offset was reached: reset both connections."""


class _Pipe:
    """One direction of one connection: read, schedule, write at arrival time."""

    def __init__(
        self,
        name: str,
        source: trio.SocketStream,
        sink: trio.SocketStream,
        model: TcpDirection,
        clock: Callable[[], float],
        stats: ProxyStatistics,
        cut_after: int | None,
    ) -> None:
        self.name = name
        self.source, self.sink = source, sink
        self.model, self.clock, self.stats = model, clock, stats
        self.cut_after = cut_after
        self.queue: deque[tuple[float, bytes]] = deque()
        self.queued = 0
        self.passed = 0  # bytes read from the source (and accepted for delivery)
        self.eof = False
        self.changed = trio.Event()

    def _notify(self) -> None:
        self.changed.set()
        self.changed = trio.Event()

    async def reader(self) -> None:
        while not self.eof:
            while self.queued >= BUFFER:
                await self.changed.wait()
            data = await self.source.receive_some(SEGMENT)
            if not data:
                self.eof = True
            elif self.cut_after is not None and self.passed + len(data) >= self.cut_after:
                data = data[: self.cut_after - self.passed]
                self.eof = True  # what follows the offset never crosses
            for i in range(0, len(data), SEGMENT):
                segment = data[i : i + SEGMENT]
                self.queue.append((self.model.send(len(segment), self.clock()), segment))
                self.queued += len(segment)
            self.passed += len(data)
            self._notify()

    async def writer(self) -> None:
        while True:
            if not self.queue:
                if self.eof:
                    break
                await self.changed.wait()
                continue
            arrival, segment = self.queue[0]
            await trio.sleep(max(0.0, arrival - self.clock()))
            self.queue.popleft()
            self.queued -= len(segment)
            await self.sink.send_all(segment)
            if self.name == "up":
                self.stats.bytes_up += len(segment)
            else:
                self.stats.bytes_down += len(segment)
            self._notify()
        if self.cut_after is not None and self.passed >= self.cut_after:
            raise _CutReached(self.name)
        await self.sink.send_eof()


def _reset(stream: trio.SocketStream) -> None:
    """Close with an RST (SO_LINGER 0) rather than an orderly FIN."""
    with contextlib.suppress(OSError):  # already gone: the close is all there is to do
        stream.socket.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))


async def _serve(
    client: trio.SocketStream,
    target: tuple[str, int],
    config: LinkConfig,
    cut: Cut | None,
    number: int,
    clock: Callable[[], float],
    stats: ProxyStatistics,
) -> None:
    """Carry one client connection to the server and back until both ends close."""
    try:
        with trio.fail_after(CONNECT_TIMEOUT):
            server = await trio.open_tcp_stream(*target)
    except (OSError, trio.TooSlowError) as exc:
        stats.failed_upstream += 1
        stats.errors.append(
            f"connection {number}: cannot reach {target[0]}:{target[1]}: {exc or 'timed out'}"
        )
        _reset(client)
        await client.aclose()
        return
    seeds = random.Random(f"{config.seed}/{number}")
    rtt = config.a_to_b.delay + config.b_to_a.delay
    models = [
        TcpDirection(config.a_to_b, random.Random(seeds.getrandbits(64)), rtt=rtt),
        TcpDirection(config.b_to_a, random.Random(seeds.getrandbits(64)), rtt=rtt),
    ]
    cuts = [cut.after if cut is not None and cut.direction == d else None for d in _DIRECTIONS]
    pipes = [
        _Pipe("up", client, server, models[0], clock, stats, cuts[0]),
        _Pipe("down", server, client, models[1], clock, stats, cuts[1]),
    ]
    try:
        async with trio.open_nursery() as nursery:
            for pipe in pipes:
                nursery.start_soon(pipe.reader)
                nursery.start_soon(pipe.writer)
    except* _CutReached:
        stats.cuts += 1
        _reset(client)
        _reset(server)
    except* (trio.BrokenResourceError, trio.ClosedResourceError, OSError):
        # One end went away abruptly: the other sees it end the same way.
        _reset(client)
        _reset(server)
    finally:
        for model in models:
            stats.segments += model.segments
            stats.retransmissions += model.retransmissions
            stats.held_by_outage += model.held_by_outage
        with trio.CancelScope(shield=True):
            await client.aclose()
            await server.aclose()


async def run_proxy(
    config: LinkConfig,
    *,
    listen: tuple[str, int],
    target: tuple[str, int],
    cuts: Sequence[Cut] = (),
    on_ready: Callable[[str, int], None] | None = None,
    duration: float | None = None,
    stop: trio.Event | None = None,
) -> ProxyStatistics:
    """Listen on ``listen`` (port 0: any free port) and carry every connection
    to ``target`` through ``config``'s line, until ``duration`` seconds have
    passed or ``stop`` is set (then it returns the counters), or until
    cancelled.

    ``cuts[i]`` applies to the i-th connection (counting from 0); connections
    past the list are not cut.  ``on_ready(host, port)`` is called once the
    proxy listens.  Raises ``OSError`` when it cannot listen.
    """
    stats = ProxyStatistics()
    listeners = await trio.open_tcp_listeners(listen[1], host=listen[0] or None)
    origin = trio.current_time()

    def clock() -> float:
        return trio.current_time() - origin

    async with trio.open_nursery() as nursery:
        if on_ready is not None:
            host, port = listeners[0].socket.getsockname()[:2]
            on_ready(host, port)

        async def accept_loop() -> None:
            async with listeners[0]:
                number = 0
                while True:
                    client = await listeners[0].accept()
                    cut = cuts[number] if number < len(cuts) else None
                    stats.connections += 1
                    nursery.start_soon(_serve, client, target, config, cut, number, clock, stats)
                    number += 1

        for extra in listeners[1:]:
            await extra.aclose()  # one address family is enough for a test proxy
        nursery.start_soon(accept_loop)
        with trio.move_on_after(math.inf if duration is None else duration):
            if stop is not None:
                await stop.wait()
            else:
                await trio.sleep_forever()
        nursery.cancel_scope.cancel()
    return stats
