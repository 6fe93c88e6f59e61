"""The asyncio driver under a serial socket: one port, one sans-I/O endpoint.

The asyncio twin of :mod:`serialsocket._driver`, with the same shape:

* a reader task feeds everything read from the port into the endpoint;
* a writer task first hands the endpoint whatever the application wrote that
  did not fit its bounded send buffer (the *outbox*), then sends whatever the
  endpoint releases, waking on any change or on the endpoint's pacing timer
  (``get_send_timer``);
* the endpoint's timer is a ``loop.call_at`` handle, moved whenever
  ``get_timer()`` moves.

After any of these, waiters are woken through one "something changed" event
and each re-checks its own condition (no lost wake-ups: the loop is
single-threaded, and a waiter takes the event before it awaits it).  How a
connection ends is read from the endpoint's events by the shared
:class:`~serialsocket._outcome.LinkOutcome`.  No trio here.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import Callable

from ._asyncio_port import READ_SIZE, AsyncPort
from ._endpoint import Endpoint
from ._outcome import LineFailed, LinkBroken, LinkOutcome
from ._state import WRITABLE

__all__ = ["FLUSH_GRACE", "AsyncioDriver"]

log = logging.getLogger(__name__)

FLUSH_GRACE = 0.5
"""Seconds (plus the line time of what is pending) allowed to push out a last
E or ACK when a session is torn down; a local I/O bound, not a protocol timer."""

_STOP_GRACE = 1.0 + 0.05
"""Seconds closing the port may take (a URL port joins its reader thread)."""


class AsyncioDriver:
    """One port, one endpoint, two tasks and a timer (see the module docstring)."""

    def __init__(self, port: AsyncPort, endpoint: Endpoint, *, owns_port: bool) -> None:
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
        self.outcome = LinkOutcome()
        self.outbox = bytearray()
        """Bytes the application wrote that the endpoint's send buffer has not
        taken yet (asyncio's ``write`` never blocks; ``drain`` waits for this)."""
        self.eof_requested = False
        """``write_eof`` was called: the endpoint gets it once the outbox is empty."""
        self._loop = asyncio.get_running_loop()
        self._changed = asyncio.Event()
        self._tasks: list[asyncio.Task[None]] = []
        self._timer: asyncio.TimerHandle | None = None
        self._timer_at = math.inf
        self._stopped = False
        self._writer_idle = True
        self._dirty = True  # something changed since the writer last asked for output
        self._flushing = 0  # flush() calls waiting for the writer to go idle
        self.reads = self.writes = self.bytes_in = self.bytes_out = 0

    # -- change notification ----------------------------------------------------

    def now(self) -> float:
        return self._loop.time()

    def notify(self) -> None:
        """Wake every waiter (each re-checks its own condition) and re-arm the timer."""
        self._dirty = True
        self._wake()
        self._arm_timer()

    def _wake(self) -> None:
        self._changed.set()
        self._changed = asyncio.Event()

    async def changed(self) -> None:
        """Wait for the next :meth:`notify`."""
        await self._changed.wait()

    def after_input(self) -> None:
        """Collect endpoint events that end the connection, then wake waiters."""
        self.outcome.take_events(self.ep)
        self.notify()

    def fail(self, cause: LinkBroken) -> None:
        self.outcome.fail(cause)
        self.notify()

    @property
    def broken(self) -> LinkBroken | None:
        return self.outcome.broken

    @property
    def stopped(self) -> bool:
        """The tasks have ended (:meth:`stop`)."""
        return self._stopped

    # -- timer -------------------------------------------------------------------

    def _arm_timer(self) -> None:
        if self._stopped:
            return
        deadline = self.ep.get_timer()
        at = math.inf if deadline is None else deadline
        if at == self._timer_at:
            return
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._timer_at = at
        if deadline is not None:
            self._timer = self._loop.call_at(deadline, self._on_timer)

    def _on_timer(self) -> None:
        self._timer = None
        self._timer_at = math.inf
        now = self.now()
        deadline = self.ep.get_timer()
        if deadline is not None and deadline <= now:
            self.ep.handle_timer(now)
            self.after_input()  # re-arms
        else:
            # Woken a clock resolution early, or the deadline moved later.
            self._arm_timer()

    # -- tasks ------------------------------------------------------------------

    def start(self) -> None:
        """Start the reader and writer tasks and the timer."""
        self._tasks = [
            asyncio.create_task(self._reader(), name="serialsocket-reader"),
            asyncio.create_task(self._writer(), name="serialsocket-writer"),
        ]
        self._arm_timer()

    async def _reader(self) -> None:
        while True:
            try:
                data = await self.port.read(READ_SIZE)
            except OSError as exc:
                cause = LineFailed(f"reading the line failed: {exc!r}")
                cause.__cause__ = exc
                self.fail(cause)
                return
            if not data:
                self.fail(LineFailed("the line reached EOF: the other end of the port closed"))
                return
            self.reads += 1
            self.bytes_in += len(data)
            self.ep.receive_data(data, self.now())
            self.after_input()

    def feed(self) -> bool:
        """Move outbox bytes into the endpoint's send buffer (and a requested EOF
        once the outbox is empty); True if anything moved."""
        moved = False
        if self.ep.state not in WRITABLE:
            return False  # the connection ended: what is left is reported, never sent
        if self.outbox and self.ep.send_buffer_free > 0:
            taken = self.ep.send(self.outbox, self.now())
            if taken:
                del self.outbox[:taken]
                moved = True
        if self.eof_requested and not self.outbox:
            self.eof_requested = False
            self.ep.send_eof(self.now())
            moved = True
        return moved

    async def _writer(self) -> None:
        while True:
            self._dirty = False
            if self.feed():
                self._wake()  # drain() waiters: the outbox shrank
            data = self.ep.data_to_send(self.now())
            if data:
                self._writer_idle = False
                try:
                    if self.ep.take_discard() and self._discard is not None:
                        self._discard()
                    await self.port.write(data)
                except OSError as exc:
                    cause = LineFailed(f"writing to the line failed: {exc!r}")
                    cause.__cause__ = exc
                    self.fail(cause)
                    return
                self.writes += 1
                self.bytes_out += len(data)
                continue
            self._writer_idle = True
            if self._flushing:
                self._wake()  # flush() waiters: the writer is idle
            wake = self.ep.get_send_timer()
            changed = self._changed
            if wake is None:
                await changed.wait()
            else:
                # Never closer than a millisecond: a wake time at or before
                # now with nothing released would otherwise spin.
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout_at(max(wake, self.now() + 1e-3)):
                        await changed.wait()

    # -- teardown -----------------------------------------------------------------

    @property
    def output_settled(self) -> bool:
        """The writer has sent everything the endpoint released since the last change."""
        return self._writer_idle and not self._dirty

    async def flush(self) -> None:
        """Give the writer a bounded moment to push out what is pending."""
        pending = self.ep.statistics().line_backlog
        self._flushing += 1
        try:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(FLUSH_GRACE + pending):
                    self.notify()
                    while not self.output_settled and self.broken is None and not self._stopped:
                        await self.changed()
        finally:
            self._flushing -= 1

    async def stop(self) -> None:
        """Stop the tasks and the timer, and close the port if it is ours (bounded)."""
        if self._stopped:
            return
        self._stopped = True
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self.notify()
        if self.owns_port:
            with contextlib.suppress(OSError, TimeoutError):
                async with asyncio.timeout(_STOP_GRACE):
                    await self.port.aclose()
