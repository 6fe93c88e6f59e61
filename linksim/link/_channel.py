"""In-memory impaired link: two connected trio streams with a :class:`LinkDirection` each way.

::

    async with open_impaired_link(LinkConfig.preset("moon")) as (a, b):
        await a.send_all(b"MOVE 1 2 3\\n")
        print(await b.receive_some())  # 1.3 s and 11 character times later

Everything runs on trio time, so under ``trio.testing.MockClock(autojump_threshold=0)``
hours of link time pass in moments.  Link time 0 (the origin of outages) is
the moment the link is created.  There is no background task: a receiver
waiting in ``receive_some`` sleeps until the engine's next arrival time (or
until a write wakes it), so each byte arrives at exactly its modelled time and
an idle link costs nothing.

Buffering is bounded the way a real line is:

* ``tx_buffer`` (default 4096 bytes, a typical tty output buffer): on a line
  with a rate, ``send_all`` blocks while the UART backlog is that full, so a
  writer is paced by the line rate exactly as on a real serial port.  Like
  Linux's n_tty (``WAKEUP_CHARS``), a blocked writer resumes once 256 bytes
  (at most half the buffer) have drained, not after every character;
* ``rx_buffer`` (default 64 KiB): bytes accepted but not yet read by the far
  end (in flight plus arrived and unread).  ``send_all`` also blocks while it
  is reached, like RTS/CTS hardware flow control -- without it a line with no
  rate could buffer without limit.  64 KiB exceeds every preset's
  bandwidth-delay product (9600 bit/s x 1.3 s is about 1.3 KB), so it never
  throttles a line that has a rate.

A reader blocked in ``receive_some`` is woken at the exact arrival of the next
byte, which on a rate-limited line means once per character.  ``read_latency``
(default 0: exact) makes it wake that many seconds after the first byte
arrives and take everything that has arrived by then, like a UART's FIFO
receive timeout or a tty's ``VTIME``: arrival times (and statistics) are
unchanged, bulk transfers cost far fewer wakeups.
"""

from __future__ import annotations

import math
import operator
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass

import trio

from ._config import LinkConfig
from ._impair import DirectionStatistics, LinkDirection

__all__ = ["ImpairedLink", "LinkEnd", "LinkStatistics", "open_impaired_link"]

DEFAULT_TX_BUFFER = 4096
DEFAULT_RX_BUFFER = 65536
# receive_some's default chunk: large enough to drain a burst in one call.
_DEFAULT_RECEIVE = 65536
# Linux n_tty's WAKEUP_CHARS: a writer blocked on a full buffer wakes when this
# much room has opened, so pacing costs one wakeup per 256 bytes, not per byte.
_WAKEUP_CHARS = 256


@dataclass(frozen=True, slots=True)
class LinkStatistics:
    """Counters of both directions of an :class:`ImpairedLink`."""

    a_to_b: DirectionStatistics
    b_to_a: DirectionStatistics


class _Direction:
    """Shared state of one direction: the engine and what the two ends wait on."""

    __slots__ = (
        "engine",
        "eof_at",
        "eof_delivered",
        "receiver_closed",
        "rx",
        "rx_lot",
        "tx_lot",
    )

    def __init__(self, engine: LinkDirection) -> None:
        self.engine = engine
        self.rx = bytearray()  # arrived, not yet read
        self.eof_at: float | None = None  # link time the EOF reaches the receiver
        self.eof_delivered = False
        self.receiver_closed = False
        self.rx_lot = trio.lowlevel.ParkingLot()  # the receiver waiting for data/EOF
        self.tx_lot = trio.lowlevel.ParkingLot()  # the sender waiting for room


class ImpairedLink:
    """A full-duplex impaired line between ends :attr:`a` and :attr:`b`.

    Create it inside a trio run (its link time starts then) and use the ends;
    :func:`open_impaired_link` also closes them when you are done.
    """

    def __init__(
        self,
        config: LinkConfig,
        *,
        tx_buffer: int = DEFAULT_TX_BUFFER,
        rx_buffer: int = DEFAULT_RX_BUFFER,
        read_latency: float = 0.0,
    ) -> None:
        if tx_buffer < 1 or rx_buffer < 1:
            raise ValueError("tx_buffer and rx_buffer must be >= 1")
        if not read_latency >= 0.0:
            raise ValueError("read_latency must be >= 0")
        self.config = config
        self.tx_buffer = tx_buffer
        self.rx_buffer = rx_buffer
        self.read_latency = read_latency
        self._origin = trio.current_time()
        ab = _Direction(LinkDirection(config.a_to_b, seed=config.seed, direction=0))
        ba = _Direction(LinkDirection(config.b_to_a, seed=config.seed, direction=1))
        self._dirs = (ab, ba)
        self.a = LinkEnd(self, out=ab, inp=ba)
        self.b = LinkEnd(self, out=ba, inp=ab)

    def now(self) -> float:
        """Link time: seconds since the link was created."""
        return trio.current_time() - self._origin

    def deadline(self, link_time: float) -> float:
        """The trio clock value of ``link_time``."""
        return self._origin + link_time

    def statistics(self) -> LinkStatistics:
        """Counters of both directions."""
        return LinkStatistics(self._dirs[0].engine.statistics(), self._dirs[1].engine.statistics())

    def _pull(self, d: _Direction, now: float) -> None:
        """Move what has arrived by ``now`` into the receive buffer; settle EOF."""
        data = d.engine.receive(now)
        if data and not d.receiver_closed:
            d.rx += data
        if d.eof_at is not None and now >= d.eof_at and d.engine.pending() == 0:
            d.eof_delivered = True

    def _next_event(self, d: _Direction) -> float:
        """Link time a blocked reader of ``d`` should wake: next byte (+ read latency) or EOF."""
        t = d.engine.next_delivery()
        if t is not None:
            return t + self.read_latency
        if d.eof_at is not None and not d.eof_delivered:
            return d.eof_at
        return math.inf


class LinkEnd(trio.abc.HalfCloseableStream):
    """One end of an :class:`ImpairedLink` (a :class:`trio.abc.HalfCloseableStream`)."""

    def __init__(self, link: ImpairedLink, *, out: _Direction, inp: _Direction) -> None:
        self._link = link
        self._out = out
        self._in = inp
        self.closed = False
        self._sending = False
        self._receiving = False

    def send_statistics(self) -> DirectionStatistics:
        """Counters of the direction this end sends on."""
        return self._out.engine.statistics()

    def receive_statistics(self) -> DirectionStatistics:
        """Counters of the direction this end receives from."""
        return self._in.engine.statistics()

    # -- sending ---------------------------------------------------------------

    def _check_can_send(self) -> None:
        if self.closed or self._out.eof_at is not None:
            raise trio.ClosedResourceError("this end is closed for sending")
        if self._out.receiver_closed:
            raise trio.BrokenResourceError("the far end is closed")

    def _room(self, now: float) -> int:
        link, engine = self._link, self._out.engine
        room = link.rx_buffer - engine.pending() - len(self._out.rx)
        if engine.config.rate is not None:
            room = min(room, link.tx_buffer - engine.queued(now))
        return room

    async def _wait_room(self) -> float:
        """Block until there may be room; returns the link time to use next."""
        link, engine = self._link, self._out.engine
        target = math.inf
        if engine.config.rate is not None and engine.queued(link.now()) >= link.tx_buffer:
            wakeup = max(1, min(_WAKEUP_CHARS, link.tx_buffer // 2))
            target = engine.drained_at(link.tx_buffer - wakeup)
        with trio.move_on_at(link.deadline(target)) as scope:
            await self._out.tx_lot.park()
        return max(link.now(), target) if scope.cancelled_caught else link.now()

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        """Queue ``data`` on the line, blocking while the buffers are full (see module doc)."""
        if self._sending:
            raise trio.BusyResourceError("another task is already sending on this end")
        self._sending = True
        try:
            await trio.lowlevel.checkpoint_if_cancelled()
            self._check_can_send()
            view = memoryview(data).cast("B")
            now = self._link.now()
            while view:
                room = self._room(now)
                if room > 0:
                    self._out.engine.send(view[:room], now)
                    view = view[room:]
                    self._out.rx_lot.unpark_all()  # the receiver may have a new deadline
                else:
                    now = await self._wait_room()
                    self._check_can_send()
            await trio.lowlevel.cancel_shielded_checkpoint()
        finally:
            self._sending = False

    @property
    def can_discard_output(self) -> bool:
        """:meth:`discard_output` can drop something: the line has a rate
        (a UART that holds what it has not sent)."""
        return self._out.engine.config.rate is not None

    def discard_output(self) -> int:
        """Drop what this end wrote that has not left its UART yet, as a
        serial port's output flush does (:meth:`serialsocket.SerialPort.discard_output`);
        returns the bytes dropped.  A no-op on a line without a rate: its
        bytes leave the moment they are written.

        Raises:
            trio.ClosedResourceError: this end is closed.
        """
        if self.closed:
            raise trio.ClosedResourceError("this end is closed")
        dropped = self._out.engine.discard(self._link.now())
        if dropped:
            self._out.tx_lot.unpark_all()  # room for a blocked sender
            self._out.rx_lot.unpark_all()  # the receiver's next arrival moved
        return dropped

    async def wait_send_all_might_not_block(self) -> None:
        """Return once :meth:`send_all` can queue at least one byte without blocking."""
        if self._sending:
            raise trio.BusyResourceError("another task is already sending on this end")
        self._sending = True
        try:
            await trio.lowlevel.checkpoint_if_cancelled()
            if self.closed:
                raise trio.ClosedResourceError("this end is closed")
            now = self._link.now()
            while self._room(now) <= 0 and not self._out.receiver_closed and not self.closed:
                now = await self._wait_room()
            if self.closed:
                raise trio.ClosedResourceError("this end is closed")
            await trio.lowlevel.cancel_shielded_checkpoint()
        finally:
            self._sending = False

    async def send_eof(self) -> None:
        """Half-close: the far end reads everything sent so far, then EOF, one delay later."""
        if self._sending:
            raise trio.BusyResourceError("another task is sending on this end")
        await trio.lowlevel.checkpoint()
        if self.closed:
            raise trio.ClosedResourceError("this end is closed")
        self._mark_eof()

    def _mark_eof(self) -> None:
        out = self._out
        if out.eof_at is None:
            out.engine.flush()
            now = self._link.now()
            out.eof_at = max(now, out.engine.transmit_done_at()) + out.engine.config.delay
            out.rx_lot.unpark_all()

    # -- receiving -------------------------------------------------------------

    async def receive_some(self, max_bytes: int | None = None) -> bytes:
        """Bytes that have arrived (at most ``max_bytes``), or b"" after the far end's EOF."""
        max_bytes = _DEFAULT_RECEIVE if max_bytes is None else operator.index(max_bytes)
        if max_bytes < 1:
            raise ValueError("max_bytes must be >= 1")
        if self._receiving:
            raise trio.BusyResourceError("another task is already receiving on this end")
        self._receiving = True
        try:
            await trio.lowlevel.checkpoint_if_cancelled()
            inp, link = self._in, self._link
            now = link.now()
            while True:
                if self.closed:
                    raise trio.ClosedResourceError("this end is closed")
                link._pull(inp, now)
                if inp.rx:
                    chunk = bytes(inp.rx[:max_bytes])
                    del inp.rx[:max_bytes]
                    inp.tx_lot.unpark_all()  # the far sender may have room again
                    await trio.lowlevel.cancel_shielded_checkpoint()
                    return chunk
                if inp.eof_delivered:
                    await trio.lowlevel.cancel_shielded_checkpoint()
                    return b""
                target = link._next_event(inp)
                with trio.move_on_at(link.deadline(target)) as scope:
                    await inp.rx_lot.park()
                # Woken by the timer: it is (at least) the target time, even if
                # origin + target - origin rounds to a hair below it.
                now = max(link.now(), target) if scope.cancelled_caught else link.now()
        finally:
            self._receiving = False

    # -- closing ---------------------------------------------------------------

    async def aclose(self) -> None:
        """Close this end: data already sent still arrives, then EOF; the far end's
        sends raise :class:`trio.BrokenResourceError`."""
        if not self.closed:
            self._mark_eof()
            self.closed = True
            self._in.receiver_closed = True
            self._in.rx.clear()
            for lot in (self._out.tx_lot, self._in.rx_lot, self._in.tx_lot):
                lot.unpark_all()
        await trio.lowlevel.checkpoint()


@asynccontextmanager
async def open_impaired_link(
    config: LinkConfig | None = None,
    *,
    tx_buffer: int = DEFAULT_TX_BUFFER,
    rx_buffer: int = DEFAULT_RX_BUFFER,
    read_latency: float = 0.0,
) -> AsyncIterator[tuple[LinkEnd, LinkEnd]]:
    """Two connected streams ``(a, b)`` with ``config``'s impairments between them.

    On exit both ends are closed.  Statistics stay readable through the ends.
    """
    link = ImpairedLink(
        config or LinkConfig(), tx_buffer=tx_buffer, rx_buffer=rx_buffer, read_latency=read_latency
    )
    try:
        yield link.a, link.b
    finally:
        with trio.CancelScope(shield=True):
            await link.a.aclose()
            await link.b.aclose()
