"""The driver under a serial socket: one port, one sans-I/O endpoint, three tasks.

* the reader feeds everything read from the port into the endpoint;
* the writer sends whatever the endpoint releases, waking on any change or
  on the endpoint's pacing timer (``get_send_timer``);
* the timer task calls ``handle_timer`` at ``get_timer()``.

After any of these, waiters are woken through one "something changed" event,
and every waiter re-checks its own condition (no lost wake-ups: trio is
single-threaded, and a waiter takes the event before it awaits it).

The causes chained to ``trio.BrokenResourceError`` when a link breaks
(:class:`LinkBroken` and its kinds), which the driver records and the
sockets raise, live in :mod:`serialsocket._outcome` (the asyncio adapter
raises the same ones) and are re-exported here.  :mod:`serialsocket._socket`
builds the sessions on top.
"""

from __future__ import annotations

import contextlib
import logging
import math
from collections.abc import Callable

import trio

from ._endpoint import Endpoint
from ._events import ConnectionAborted, LinkDead
from ._outcome import LineFailed, LinkBroken, LinkDeadError, PeerAborted

__all__ = ["LineFailed", "LinkBroken", "LinkDeadError", "PeerAborted"]

log = logging.getLogger(__name__)

_READ_SIZE = 65536
"""Bytes asked of the port per read: one read can hold many packets."""

_FLUSH_GRACE = 0.5
"""Seconds (plus the line time of what is pending) allowed to push out a last
E or ACK when a session is torn down; a local I/O bound, not a protocol timer."""


class _Driver:
    """One port, one endpoint, three tasks (see the module docstring)."""

    def __init__(self, port: trio.abc.Stream, endpoint: Endpoint, *, owns_port: bool) -> None:
        self.port = port
        self.ep = endpoint
        # A port that can drop what it has not sent lets an expedited packet
        # cut in ahead of it (PROTOCOL.md 11).
        discard = getattr(port, "discard_output", None)
        self._discard: Callable[[], object] | None = (
            discard if callable(discard) and getattr(port, "can_discard_output", False) else None
        )
        endpoint.line_discards = self._discard is not None
        self.owns_port = owns_port
        self.generation = 0
        self.broken: LinkBroken | None = None
        self.ended_by_us: str | None = None
        """Why this side aborted the current connection (our own E packet), if it did."""
        self._changed = trio.Event()
        self._cancel = trio.CancelScope()
        self._stopped = trio.Event()
        self._writer_idle = True
        self._writer_running = False  # the writer task is alive
        self._flushing = 0  # flush() calls waiting for the writer to go idle
        self._timer_scope: trio.CancelScope | None = None  # the timer task's sleep
        self.reads = self.writes = self.bytes_in = self.bytes_out = 0

    # -- change notification ----------------------------------------------------

    def notify(self) -> None:
        """Wake every waiter; each re-checks its own condition.

        The timer task is not among them: it sleeps until the endpoint's
        deadline, and is only woken (its sleep's deadline moved) when a
        change brought that deadline earlier.  Waking it on every change
        cost a task switch per packet for nothing.
        """
        self._changed.set()
        self._changed = trio.Event()
        scope = self._timer_scope
        if scope is not None:
            deadline = self.ep.get_timer()
            if deadline is not None and deadline < scope.deadline:
                scope.deadline = deadline

    async def changed(self) -> None:
        """Wait for the next :meth:`notify`."""
        await self._changed.wait()

    def now(self) -> float:
        return trio.current_time()

    def after_input(self) -> None:
        """Collect endpoint events that end the connection, then wake waiters."""
        for event in self.ep.events():
            if isinstance(event, ConnectionAborted) and not event.by_peer:
                self.ended_by_us = self.ended_by_us or event.reason
            elif isinstance(event, ConnectionAborted) and self.broken is None:
                self.broken = PeerAborted(event.reason)
            elif isinstance(event, LinkDead) and self.broken is None:
                self.broken = LinkDeadError(event)
            log.debug("endpoint event: %s", event)
        self.notify()

    @property
    def stopped(self) -> bool:
        """The tasks have ended (:meth:`stop`, or their nursery was cancelled)."""
        return self._stopped.is_set()

    def fail(self, cause: LinkBroken) -> None:
        if self.broken is None:
            self.broken = cause
        self.notify()

    # -- tasks ------------------------------------------------------------------

    async def run(self, *, task_status: trio.TaskStatus[None] = trio.TASK_STATUS_IGNORED) -> None:
        """Run the three tasks until :meth:`stop` (never raises port errors)."""
        try:
            with self._cancel:
                async with trio.open_nursery() as nursery:
                    nursery.start_soon(self._reader)
                    nursery.start_soon(self._writer)
                    nursery.start_soon(self._timer)
                    task_status.started()
        finally:
            self._stopped.set()
            self.notify()

    async def _reader(self) -> None:
        while True:
            try:
                data = await self.port.receive_some(_READ_SIZE)
            except (trio.BrokenResourceError, trio.ClosedResourceError, OSError) as exc:
                cause = LineFailed(f"reading the line failed: {exc!r}")
                cause.__cause__ = exc
                self.fail(cause)
                return
            if not data:
                self.fail(LineFailed("the line reached EOF: the other end of the port closed"))
                return
            self.reads += 1
            self.bytes_in += len(data)
            held = self.ep.input_held
            self.ep.receive_data(data, self.now())
            if self.ep.input_held < held + len(data):
                self.after_input()
            # Else the bytes only extended a packet still arriving (a long
            # packet comes in several reads from a pty: 4 KB at most): no
            # waiter's condition changed, and waking them all cost two task
            # switches per read.

    async def _writer(self) -> None:
        self._writer_running = True
        try:
            await self._write_loop()
        finally:
            self._writer_running = False

    async def _write_loop(self) -> None:
        while True:
            data = self.ep.data_to_send(self.now())
            if data:
                self._writer_idle = False
                try:
                    await self._put(data)
                except (trio.BrokenResourceError, trio.ClosedResourceError, OSError) as exc:
                    cause = LineFailed(f"writing to the line failed: {exc!r}")
                    cause.__cause__ = exc
                    self.fail(cause)
                    return
                continue
            self._writer_idle = True
            if self._flushing:
                self.notify()
            wake = self.ep.get_send_timer()
            changed = self._changed
            if wake is None:
                await changed.wait()
            else:
                # Never closer than a millisecond: a wake time at or before
                # now with nothing released would otherwise spin.
                with trio.move_on_at(max(wake, self.now() + 1e-3)):
                    await changed.wait()

    async def _timer(self) -> None:
        while True:
            deadline = self.ep.get_timer()
            now = self.now()
            if deadline is not None and deadline <= now:
                self.ep.handle_timer(now)
                self.after_input()
                await trio.lowlevel.checkpoint()
                continue
            # Sleep until the deadline; notify() moves it earlier when needed.
            # A deadline that moved later just wakes this loop early: it
            # re-reads the timer and sleeps again.
            with trio.CancelScope(deadline=math.inf if deadline is None else deadline) as scope:
                self._timer_scope = scope
                try:
                    await trio.sleep_forever()
                finally:
                    self._timer_scope = None

    # -- teardown -----------------------------------------------------------------

    async def flush(self) -> None:
        """Give the writer a bounded moment to push out what is pending (shielded)."""
        with trio.CancelScope(shield=True):
            pending = self.ep.statistics().line_backlog
            self._flushing += 1
            try:
                with trio.move_on_after(_FLUSH_GRACE + pending):
                    self.notify()
                    await trio.lowlevel.checkpoint()
                    while (
                        not self._writer_idle and self.broken is None and not self._stopped.is_set()
                    ):
                        await self.changed()
                    if not self._writer_running and self.broken is None:
                        await self._write_last()
            finally:
                self._flushing -= 1

    async def _write_last(self) -> None:
        """The writer is gone -- cancelled with its nursery, as Ctrl-C on a
        command cancels the whole run -- while the endpoint has something to
        say, the E of an abort: write it here.  Without this a program
        interrupted mid-transfer left without telling the peer, who judged
        the link dead long after ("link dead after 26.4 s of silence")
        instead of reporting that the peer aborted.  Best effort: a port
        that fails now has nothing more to lose."""
        data = self.ep.data_to_send(self.now())
        if data:
            with contextlib.suppress(
                trio.BrokenResourceError, trio.ClosedResourceError, trio.BusyResourceError, OSError
            ):
                await self._put(data)

    async def _put(self, data: bytes) -> None:
        """Write what ``data_to_send`` returned, after the drop it may ask
        for (:meth:`Endpoint.take_discard`), and count it."""
        if self.ep.take_discard() and self._discard is not None:
            self._discard()
        await self.port.send_all(data)
        self.writes += 1
        self.bytes_out += len(data)

    async def stop(self) -> None:
        """Stop the tasks and close the port if it is ours (prompt; shielded)."""
        self._cancel.cancel()
        with trio.CancelScope(shield=True):
            if self.owns_port:
                await trio.aclose_forcefully(self.port)
