"""The trio glue: move bytes and time between a stream and a sans-I/O connection.

Three small tasks per connection -- reader, writer, timer -- and nothing else.
Everything the protocol decides happens in the connection object; the pump
only feeds it and delivers what it produces.  The writer is its own task so
that producers (the executor finishing a command, telemetry, a heartbeat) never
wait for a slow line: they append to the connection and :meth:`Pump.kick`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Protocol, runtime_checkable

import trio

from ._connection import _Connection
from ._events import CloseReason, Event
from ._packet import PACKET_SIZE
from ._ratelimit import TokenBucket
from ._state import SessionState, Side

__all__ = ["ExpeditedStream", "LatestStream", "Pump", "expedited_lane", "latest_lane"]

log = logging.getLogger(__name__)

RECEIVE_CHUNK = 16 * PACKET_SIZE
"""Bytes asked of the stream per read: a burst of pipelined replies in one wake-up."""

MAX_PENDING_BYTES = 256 * PACKET_SIZE
"""Output waiting (not yet taken by the writer) for a peer that does not read.
The arm produces at most three packets per command (accepted, completed or
failed, plus a telemetry slot that is skipped while output is pending), and
the queue holds 33 commands, so an honest peer never gets near 256 packets;
past it the peer is not reading and the connection is given up rather than
letting memory grow."""

_NO_LINGER = frozenset(
    {
        CloseReason.SILENCE,
        CloseReason.HANDSHAKE_TIMEOUT,
        CloseReason.GARBAGE,
        CloseReason.PEER_EOF,
        CloseReason.STALLED,
    }
)

CLOSE_TIMEOUT = 5.0
"""Seconds to let the final BYE drain before the stream is closed regardless."""


@runtime_checkable
class ExpeditedStream(Protocol):
    """A stream with an expedited lane beside it (``serialsocket.SerialSocket``):
    short messages that overtake the bytes queued on the stream, delivered
    whole and exactly once (serialsocket/PROTOCOL.md section 11)."""

    @property
    def expedited(self) -> bool:
        """The lane is there on this connection (both ends agreed to it)."""
        ...

    async def send_expedited(self, message: bytes) -> None: ...

    async def receive_expedited(self) -> bytes: ...


def expedited_lane(stream: trio.abc.Stream) -> ExpeditedStream | None:
    """``stream`` as an :class:`ExpeditedStream` if it has a working lane, else None."""
    if isinstance(stream, ExpeditedStream) and stream.expedited:
        return stream
    return None


@runtime_checkable
class LatestStream(Protocol):
    """A stream with a latest-value lane beside it (``serialsocket.SerialSocket``,
    or the teleoperation channel of a mux over one): a series of values, each
    superseding the last, where a lost value never holds up a newer one
    (serialsocket/PROTOCOL.md section 12)."""

    @property
    def latest(self) -> bool:
        """The lane is there on this connection (both ends agreed to it)."""
        ...

    @property
    def latest_waiting(self) -> bool:
        """A value given to :meth:`send_latest` has not yet reached the line."""
        ...

    def send_latest(self, value: bytes) -> None: ...

    async def receive_latest(self) -> bytes: ...


def latest_lane(stream: trio.abc.Stream) -> LatestStream | None:
    """``stream`` as a :class:`LatestStream` if it has a working lane, else None."""
    if isinstance(stream, LatestStream) and stream.latest:
        return stream
    return None


class Pump:
    """Runs one connection over one stream until the session is CLOSED.

    When the stream has an expedited lane (:func:`expedited_lane`) the
    connection is told so, and two more tasks carry the lane: the
    controller's EMERGENCY_STOP goes out there, the arm reads it there
    (PROTOCOL.md section 15).
    """

    def __init__(
        self,
        stream: trio.abc.Stream,
        conn: _Connection,
        on_event: Callable[[Event], None],
        *,
        read_limit: TokenBucket | None = None,
    ) -> None:
        """``read_limit``, if given, counts bytes: the reader takes no more than it
        holds and sleeps while it is short of one packet (see ``_ratelimit``)."""
        self.stream = stream
        self.conn = conn
        self._on_event = on_event
        self._wake = trio.Event()
        self._timer_wake = trio.Event()
        self._timer_deadline = math.inf
        self._sending = False
        self._done = trio.Event()
        self._reader_done = trio.Event()
        self._scope: trio.CancelScope | None = None
        self._close_by: float | None = None
        """When the session closed plus the linger time: flushing and lingering
        together end by then."""
        self._read_limit = read_limit
        self._lane = expedited_lane(stream)
        conn.expedited = self._lane is not None
        self._lane_wake = trio.Event()
        self.bytes_in = 0
        self.bytes_out = 0
        self.throttles = 0
        """Times the reader paused because the peer sent faster than ``read_limit``."""
        self.throttled_for = 0.0
        """Seconds the reader spent in those pauses."""
        self.stream_error: BaseException | None = None
        """The first error the stream raised (its ``__cause__`` says why: a dead
        serial link, a reset TCP connection), for the reports; None if it ended
        cleanly."""

    @property
    def idle(self) -> bool:
        """Nothing being written or waiting: telemetry may go out without delaying replies."""
        return not self._sending and not self._wake.is_set()

    def kick(self) -> None:
        """Call after anything that made the connection produce output or move its timer."""
        if self.conn.buffered > MAX_PENDING_BYTES:
            # The writer is stuck in send_all: the peer is not reading.  Give up
            # rather than let memory grow; the run's scope stops the writer.
            log.warning("peer is not reading; dropping the connection")
            self.conn.abandon(CloseReason.STALLED, "the peer stopped reading")
            if self._scope is not None:
                self._scope.cancel()
        self.drain_events()
        if self.conn.expedited_pending:
            self._lane_wake.set()
        if self.conn.closed and self._scope is not None and self._scope.deadline == math.inf:
            # Over: the last packets get a bounded time to go out.  A peer that
            # stopped reading would otherwise hold the writer -- and this
            # connection's slot -- in send_all forever.
            self._close_by = trio.current_time() + self._linger()
            self._scope.deadline = self._close_by
        self._wake.set()
        # Wake the timer only if its deadline moved earlier (a state change):
        # sends and receives only push heartbeat and silence deadlines later,
        # and waking it for those would cost two task switches per packet.
        deadline = self.conn.get_timer()
        if deadline is None or deadline < self._timer_deadline:
            self._timer_wake.set()

    def drain_events(self) -> None:
        while (event := self.conn.next_event()) is not None:
            self._on_event(event)

    def close(self, reason: CloseReason, message: str = "") -> None:
        """End the session from this side (BYE goes out, then the stream closes)."""
        self.conn.close(reason, trio.current_time(), message)
        self.kick()

    async def run(self) -> None:
        """Pump until the session is CLOSED and its last packet is written; close the stream."""
        try:
            async with trio.open_nursery() as nursery:
                self._scope = nursery.cancel_scope
                nursery.start_soon(self._reader)
                nursery.start_soon(self._timer)
                if self._lane is not None:
                    nursery.start_soon(self._lane_writer, self._lane)
                    if self.conn.side is Side.SERVER:
                        nursery.start_soon(self._lane_reader, self._lane)
                await self._writer()
                nursery.cancel_scope.cancel()
        finally:
            await self._close_stream()
            self._done.set()

    def _linger(self) -> float:
        params = self.conn.parameters
        return max(CLOSE_TIMEOUT, params.dead_time if params is not None else 0.0)

    async def _close_stream(self) -> None:
        """Lingering close: half-close, let the peer's last bytes drain, then close.

        Closing outright while the peer still sends makes some streams throw
        away what was in flight *towards us as well as from us* (TCP answers
        with a reset; a serial socket refuses the data and aborts), so a BYE or
        a final COMPLETED could be lost.  Lingering, then the stream's own
        close, are each bounded by the dead time (the peer hears the BYE
        within a round trip) and never shorter than CLOSE_TIMEOUT.
        """
        close_by = self._close_by
        if close_by is None:
            close_by = trio.current_time() + self._linger()
        errors = (trio.BrokenResourceError, trio.ClosedResourceError, OSError)
        # Lingering is for a peer that is alive and closing too; one that fell
        # silent, never finished the handshake or sent garbage gets no grace.
        lingers = self.conn.close_reason not in _NO_LINGER
        with trio.move_on_at(close_by) as scope:
            scope.shield = True
            if lingers and isinstance(self.stream, trio.abc.HalfCloseableStream):
                try:
                    await self.stream.send_eof()
                    while await self.stream.receive_some(RECEIVE_CHUNK):
                        pass  # after CLOSED nothing more is read; just let it drain
                except errors as exc:
                    log.debug("lingering close ended early: %r", exc)
        # The close itself gets the linger time again, counted from here: a
        # serial socket's aclose waits for its backlog to be acknowledged and
        # for the peer's EOF -- a round trip or two on a slow, far line, more
        # than CLOSE_TIMEOUT -- and a cancelled one aborts the link under the
        # peer's own close (linksim demo exited 1 about one run in three).
        # It still ends within the dead time: a live peer is heard by then.
        with trio.move_on_after(self._linger()) as scope:
            scope.shield = True
            try:
                await self.stream.aclose()
            except errors as exc:
                # A TLS close_notify into a dead socket, say: closed anyway.
                log.debug("closing the stream failed: %r", exc)

    async def _reader(self) -> None:
        try:
            await self._read()
        finally:
            self._reader_done.set()

    async def _read(self) -> None:
        conn = self.conn
        limit = self._read_limit
        while conn.state is not SessionState.CLOSED:
            want = RECEIVE_CHUNK
            if limit is not None:
                want = await self._allowance(limit)
            try:
                data = bytes(await self.stream.receive_some(want))
            except (trio.BrokenResourceError, trio.ClosedResourceError) as exc:
                log.debug("stream failed: %r", exc)
                self.stream_error = self.stream_error or exc
                data = b""
            if limit is not None:
                limit.spend(len(data), trio.current_time())
            self.bytes_in += len(data)
            conn.receive_data(data, trio.current_time())
            self.kick()
            if not data:
                return

    async def _allowance(self, limit: TokenBucket) -> int:
        """Bytes the reader may ask for now, after sleeping until that is at least
        one packet.  The sleep is where a flooding peer's cost lands: its bytes
        wait in the transport, which in turn stops accepting them."""
        wait = limit.wait_for(PACKET_SIZE, trio.current_time())
        if wait > 0:
            if not self.throttles:
                log.info("the peer sends faster than its packet-rate limit; reading it more slowly")
            self.throttles += 1
            self.throttled_for += wait
            await trio.sleep(wait)
        return max(PACKET_SIZE, min(RECEIVE_CHUNK, int(limit.available(trio.current_time()))))

    async def _timer(self) -> None:
        conn = self.conn
        while conn.state is not SessionState.CLOSED:
            # Fresh event, then the deadline, with no checkpoint between: a kick
            # that moves the deadline cannot slip in unseen.
            self._timer_wake = trio.Event()
            deadline = conn.get_timer()
            self._timer_deadline = math.inf if deadline is None else deadline
            with trio.move_on_at(self._timer_deadline):
                await self._timer_wake.wait()
                continue
            conn.handle_timer(trio.current_time())
            self.kick()

    async def _writer(self) -> None:
        conn = self.conn
        while True:
            await self._wake.wait()
            # One scheduling round before taking the output: whatever else is
            # ready in this batch (an instant command's COMPLETED right after its
            # ACCEPTED) goes out in the same write and segment.
            await trio.lowlevel.cancel_shielded_checkpoint()
            self._wake = trio.Event()
            data = conn.data_to_send()
            if data:
                self._sending = True
                try:
                    await self.stream.send_all(data)
                except (trio.BrokenResourceError, trio.ClosedResourceError) as exc:
                    self.stream_error = self.stream_error or exc
                    # The peer may have written its last words (a REFUSE, a BYE)
                    # and closed before reading ours: let the reader take them
                    # before the end of the stream is declared.
                    log.debug("stream failed while sending: %r", exc)
                    with trio.move_on_after(CLOSE_TIMEOUT):
                        await self._reader_done.wait()
                    conn.receive_data(b"", trio.current_time())
                    self.drain_events()
                    return
                finally:
                    self._sending = False
                self.bytes_out += len(data)
            if conn.state is SessionState.CLOSED and not self._wake.is_set():
                return

    async def _lane_writer(self, lane: ExpeditedStream) -> None:
        """Hands each expedited packet to the lane as soon as it is queued --
        never behind the stream writer, which may be waiting on a full line."""
        while True:
            await self._lane_wake.wait()
            self._lane_wake = trio.Event()
            for message in self.conn.expedited_to_send():
                try:
                    await lane.send_expedited(message)
                except (trio.BrokenResourceError, trio.ClosedResourceError) as exc:
                    # The stream has failed too; its reader and writer report it.
                    log.debug("expedited lane failed: %r", exc)
                    return
                self.bytes_out += len(message)

    async def _lane_reader(self, lane: ExpeditedStream) -> None:
        """Feeds the arm's connection what arrives on the lane."""
        conn = self.conn
        while conn.state is not SessionState.CLOSED:
            try:
                message = await lane.receive_expedited()
            except (trio.BrokenResourceError, trio.ClosedResourceError) as exc:
                log.debug("expedited lane ended: %r", exc)
                return
            self.bytes_in += len(message)
            conn.receive_expedited(message, trio.current_time())
            self.kick()

    async def wait_done(self) -> None:
        await self._done.wait()
