"""The controller's async client: pipelined commands, telemetry, reconnect with resume.

::

    async with tcpstream.connect_tcp("arm.example", 7010, key=KEY, identity="ops-1") as arm:
        reply = await arm.move_joints([0, 0.5, -0.3, 0, 0.2, 0])
        first = await arm.submit(tcpstream.commands.open_fingers())  # pipelined
        second = await arm.submit(tcpstream.commands.close_fingers())
        await first.completed(); await second.completed()

Every command gets a request id (1, 2, 3, ... within this client's
incarnation).  If the link breaks, the client reconnects (when it was given a
way to: a stream factory) and re-sends every command whose outcome it has not
seen, under the *same* request id: the arm answers those from its memory or
attaches to the one still running, so nothing runs twice.  Waits are bounded
by the protocol itself: a dead link is detected within the arm's dead time,
and reconnection is attempted a bounded number of times; every wait is also
cancellable by the caller (``trio.move_on_after``).
"""

from __future__ import annotations

import logging
import secrets
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Unpack

import trio

from ._client_connection import ClientConnection
from ._client_core import (
    FINAL_REASONS,
    CommandMethods,
    RequestBook,
    Settlement,
    describe_error,
    gave_up,
    is_emergency,
    refusal_error,
)
from ._commands import (
    Command,
    CommandResult,
    Feedback,
    validate_arguments,
)
from ._connection import ConnectionStatistics
from ._errors import (
    AuthenticationFailed,
    LocalProtocolError,
    SessionClosed,
)
from ._events import (
    Accepted,
    CloseReason,
    Completed,
    ControllerIdentity,
    Event,
    Failed,
    Granted,
    PacketRejected,
    RefusalReceived,
    Role,
    SessionEnded,
    SessionParameters,
    TelemetryReceived,
)
from ._options import ClientConfig, ClientOptions, client_config
from ._pump import Pump
from ._state import SessionState

__all__ = ["ArmClient", "ClientStatistics", "CommandHandle", "StreamFactory"]

log = logging.getLogger(__name__)

StreamFactory = Callable[[], Awaitable[trio.abc.Stream]]

TELEMETRY_BUFFER = 16
"""Telemetry samples buffered per subscriber; a slower reader loses the newest
(counted) rather than making the connection wait."""


@dataclass(frozen=True, slots=True, kw_only=True)
class ClientStatistics:
    """What an operator reads about a controller's client (:meth:`ArmClient.statistics`)."""

    pending: int
    """Commands sent and not yet settled (COMPLETED or FAILED)."""
    reconnects: int
    """Times the session was resumed over a new stream."""
    telemetry_dropped: int
    """Samples a slow subscriber did not take in time (newest dropped)."""
    rejected_by_arm: int
    """FAILED replies matching no command: packets the arm could not use."""
    bytes_sent: int
    """On the current stream (0 between streams)."""
    bytes_received: int
    connection: ConnectionStatistics | None
    """The current session's packet counters (packets, bad packets, replays,
    heartbeats); None between streams."""


class CommandHandle:
    """One submitted command: await :meth:`accepted`, then :meth:`completed`."""

    def __init__(self, request_id: int, command: Command) -> None:
        self.request_id = request_id
        self.command = command
        self.position: int | None = None
        """Queue position reported by the arm's ACCEPTED (None until then)."""
        self.result: CommandResult | None = None
        self.error: Exception | None = None
        self.sent = False
        self.failures_seen = 0
        """The highest failed request id this client had seen when it sent the command."""
        self._accepted = trio.Event()
        self._done = trio.Event()

    @property
    def done(self) -> bool:
        return self._done.is_set()

    async def accepted(self) -> int:
        """Wait until the arm queued the command; its queue position.

        Raises the command's failure if it failed before being queued.  A
        command that completed although its ACCEPTED was never heard (both
        replies were lost with the link and the arm answered COMPLETED from
        memory on the resume) was queued: this returns 0, position unknown,
        as the asyncio client does.
        """
        await self._accepted.wait()
        if self.position is not None:
            return self.position
        if self.error is not None:
            raise self.error
        return 0

    async def completed(self) -> CommandResult:
        """Wait for the outcome; raises :class:`CommandFailed` or :class:`SessionClosed`."""
        await self._done.wait()
        if self.error is not None:
            raise self.error
        assert self.result is not None
        return self.result

    def _accept(self, position: int) -> None:
        self.position = position
        self._accepted.set()

    def _finish(self, result: CommandResult | None, error: Exception | None) -> None:
        if self._done.is_set():
            return
        self.result, self.error = result, error
        self._accepted.set()
        self._done.set()


class ArmClient(CommandMethods):
    """A controller (or observer) connection to an arm.  Use ``async with``.

    Prefer :func:`connect_tcp` / :func:`connect_stream` to building one.
    ``stream_factory`` opens a fresh stream; it is called for the first
    connection and for every reconnection (``reconnect_attempts`` in a row at
    most, ``reconnect_delay`` apart, doubling).  The options are a
    :class:`ClientConfig` and/or its fields as keywords (these win), checked
    here, in the caller's frame.
    """

    def __init__(
        self,
        stream_factory: StreamFactory,
        config: ClientConfig | None = None,
        **options: Unpack[ClientOptions],
    ) -> None:
        self._factory = stream_factory
        self.config = settings = client_config(config, options)
        incarnation = settings.incarnation
        self.identity = ControllerIdentity(
            settings.identity, incarnation if incarnation is not None else secrets.randbits(64)
        )
        role = Role.OBSERVER if settings.observer else Role.CONTROLLER
        # Check everything a connection would refuse now, in the caller's frame,
        # not later inside the background task.
        ClientConnection(self.identity, role=role, key=settings.key)
        self._key = settings.key
        self.role = role
        self._reconnect_attempts = settings.reconnect_attempts
        self._reconnect_delay = settings.reconnect_delay
        self._handshake_timeout = settings.handshake_timeout
        self._nonce_source = settings.nonce_source
        max_in_flight = settings.max_in_flight
        # In-flight commands, bounded like the arm's queue: submit() waits for room.
        self._slots = trio.Semaphore(max_in_flight)
        self._pending: dict[int, CommandHandle] = {}
        # Request ids, the failure barrier and the resume decision (sans-I/O,
        # shared with the asyncio client).
        self._book = RequestBook()
        self._pump: Pump | None = None
        self._conn: ClientConnection | None = None
        self._ready = trio.Event()
        self._closed = trio.Event()
        # Set (and replaced) whenever the session is granted, ends or the client
        # closes: what submit() waits on while the link is being re-established.
        self._changed = trio.Event()
        self._failure: Exception | None = None
        self._ending = False
        self._granted_now = False
        self._subscribers: set[trio.MemorySendChannel[Feedback]] = set()
        self.parameters: SessionParameters | None = None
        self.latest_telemetry: Feedback | None = None
        self.reconnects = 0
        self.telemetry_dropped = 0
        self._nursery: trio.Nursery | None = None
        self._loop_scope: trio.CancelScope | None = None
        self._stopping = False

    # --- lifetime -------------------------------------------------------------

    async def __aenter__(self) -> ArmClient:
        self._nursery_cm = trio.open_nursery()
        self._nursery = await self._nursery_cm.__aenter__()
        self._nursery.start_soon(self._connection_loop)
        try:
            # Granted, or the first session failed (refused, bad key, no answer).
            async with trio.open_nursery() as wait:
                wait.start_soon(_set_when, self._ready, wait.cancel_scope)
                wait.start_soon(_set_when, self._closed, wait.cancel_scope)
            if not self._ready.is_set():
                raise self._failure or SessionClosed("the arm closed the connection")
        except BaseException:
            # Stop the background task, then raise the failure itself (Refused,
            # AuthenticationFailed, a cancellation...), not wrapped in a group.
            await self._stop_tasks()
            raise
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        try:
            if exc is None:
                await self.aclose()
            else:
                # Tell the arm we are gone (it halts outstanding work at once
                # rather than waiting out the deadman).
                self._close_now(CloseReason.SHUTDOWN, _bye_text(exc))
                await self._flush_goodbye()
        except BaseException as inner:
            # Cancelled (a deadline around the block) or failed while closing:
            # the session still ends with a BYE, and the tasks still stop.
            if not self._ending:
                self._close_now(CloseReason.SHUTDOWN, _bye_text(inner))
            await self._flush_goodbye()
            raise
        finally:
            # Always leave the nursery entered in __aenter__, whatever happened
            # above: a cancel scope left open corrupts trio's scope stack.
            await self._stop_tasks()
        return None

    async def _flush_goodbye(self) -> None:
        """Let the BYE go out: bounded, and even inside a cancelled scope."""
        if self._pump is not None:
            with trio.move_on_after(1.0) as scope:
                scope.shield = True
                await self._pump.wait_done()

    async def _stop_tasks(self) -> None:
        assert self._nursery is not None
        self._stopping = True
        if self._loop_scope is not None:
            self._loop_scope.cancel()
        self._nursery.cancel_scope.cancel()
        # The background tasks end promptly by this cancel (their own waits are
        # bounded).  Always awaited, never skipped: a nursery left un-exited
        # corrupts trio's cancel scope stack.  The caller's own exception (if
        # any) then propagates as itself, not wrapped in an exception group.
        await self._nursery_cm.__aexit__(None, None, None)

    async def aclose(self, *, wait: bool = True) -> None:
        """Finish: wait for outstanding commands (``wait``), say BYE, close the stream."""
        if wait:
            for handle in list(self._pending.values()):
                await handle._done.wait()
        self._close_now(CloseReason.NORMAL, "controller done")
        pump = self._pump
        if pump is not None:
            with trio.move_on_after(5.0):
                await pump.wait_done()

    def _closing(self) -> bool:
        # A method, not the attribute: it changes across awaits.
        return self._ending

    def _notify(self) -> None:
        self._changed.set()
        self._changed = trio.Event()

    def _usable(self) -> bool:
        """A granted session is open right now: a command can be sent on it."""
        conn = self._conn
        return (
            self._ready.is_set()
            and not self._ending
            and conn is not None
            and conn.state is SessionState.OPEN
        )

    def _close_now(self, reason: CloseReason, message: str) -> None:
        self._ending = True
        self._notify()
        if self._pump is not None:
            self._pump.close(reason, message)
        self._fail_pending(SessionClosed("the client closed the session", reason))

    # --- the connection loop ----------------------------------------------------

    async def _connection_loop(self) -> None:
        # Shielded from the caller's cancel scopes: a deadline around ``async
        # with`` cancels the caller's waits, but the session must live on long
        # enough to carry the BYE (__aexit__ waits for it, bounded).  Only
        # _stop_tasks ends it.
        with trio.CancelScope(shield=True) as scope:
            self._loop_scope = scope
            if self._stopping:
                scope.cancel()
            await self._connect_and_resume()

    async def _connect_and_resume(self) -> None:
        granted_once = False
        try:
            stream = await self._factory()
        except (OSError, trio.BrokenResourceError) as exc:
            # Connection refused, no route, a TLS certificate the client does not trust...
            self._failure = SessionClosed(f"cannot reach the arm: {describe_error(exc)}")
            self._failure.__cause__ = exc
            self._closed.set()
            return
        # Reconnection attempts used in the current outage (reset by a grant): a
        # stream that opens but never gets a grant uses one just like a stream
        # that cannot be opened, so an arm that never answers is given up on.
        used = 0
        # Why the client ends, for every command it must settle: the session's
        # own end (with the stream's error) and the last reconnect failure.
        lost = "the session ended"
        try:
            while True:
                self._granted_now = False
                ended = await self._run_session(stream)
                lost = f"the link to the arm was lost ({ended.message})"
                granted_once = granted_once or self._granted_now
                if self._granted_now:
                    used = 0
                if not granted_once or self._ending or ended.reason in FINAL_REASONS:
                    if self._failure is None and not granted_once:
                        self._failure = SessionClosed(f"no session: {ended.message}", ended.reason)
                    break
                next_stream: trio.abc.Stream | None = None
                last_error = ""
                while next_stream is None and used < self._reconnect_attempts:
                    await trio.sleep(self._reconnect_delay * 2**used)
                    used += 1
                    try:
                        next_stream = await self._factory()
                    except (OSError, trio.BrokenResourceError) as exc:
                        last_error = describe_error(exc)
                        log.info("reconnect attempt %d failed: %s", used, last_error)
                if next_stream is None:
                    lost = gave_up(lost, self._reconnect_attempts, used, last_error)
                    break
                if self._closing():  # closed while we were reconnecting
                    await trio.aclose_forcefully(next_stream)
                    break
                self.reconnects += 1
                stream = next_stream
        finally:
            self._closed.set()
            self._notify()
            self._fail_pending(SessionClosed(f"{lost}; the session could not be resumed"))
            for ch in self._subscribers:
                ch.close()

    async def _run_session(self, stream: trio.abc.Stream) -> SessionEnded:
        now = trio.current_time()
        conn = ClientConnection(
            self.identity,
            role=self.role,
            key=self._key,
            handshake_timeout=self._handshake_timeout,
            now=now,
            nonce_source=self._nonce_source,
        )
        ended: list[SessionEnded] = []
        self._conn = conn
        pump = Pump(stream, conn, lambda ev: self._on_event(ev, ended))
        self._pump = pump
        conn.connect(now)
        pump.kick()
        await pump.run()
        self._ready = trio.Event()
        end = ended[0] if ended else SessionEnded(CloseReason.PEER_EOF, "stream ended", True)
        if pump.stream_error is not None:
            # "the stream ended without a BYE" says little; the stream's own
            # error says why (a dead serial link with its byte counts, a reset).
            why = f"{end.message}: {describe_error(pump.stream_error)}"
            end = SessionEnded(end.reason, why, end.by_peer)
        return end

    # --- events -----------------------------------------------------------------

    def _on_event(self, event: Event, ended: list[SessionEnded]) -> None:
        if isinstance(event, Completed | Accepted | Failed):
            self._deliver(self._book.on_event(event))
        elif isinstance(event, TelemetryReceived):
            self._telemetry(event.feedback)
        elif isinstance(event, Granted):
            self._granted(event)
        elif isinstance(event, RefusalReceived):
            self._failure = refusal_error(event)
        elif isinstance(event, SessionEnded):
            # Not ready from this moment, not from when the pump has finished
            # closing the stream (which can take a while): submit() must not
            # use a CLOSED connection in between.
            self._ready = trio.Event()
            self._notify()
            ended.append(event)
            if event.reason is CloseReason.AUTHENTICATION and not event.by_peer:
                self._failure = AuthenticationFailed(event.message)
        elif isinstance(event, PacketRejected):
            log.info("dropped a packet from the arm: %s", event.message)

    def _granted(self, event: Granted) -> None:
        self._granted_now = True
        self.parameters = event.parameters
        pump, conn = self._pump, self._conn
        assert pump is not None
        assert conn is not None
        now = trio.current_time()
        resend, unknown = self._book.on_grant(event)
        self._deliver(unknown)
        for rid, command, failures_seen in resend:
            conn.send_command(rid, command, now, failures_seen=failures_seen)
        pump.kick()
        self._ready.set()
        self._notify()

    def _deliver(self, settlements: list[Settlement]) -> None:
        """Hand what the book decided to the waiting handles."""
        for s in settlements:
            handle = self._pending.get(s.request_id)
            if handle is None:
                continue
            if not s.final:
                assert s.position is not None
                handle._accept(s.position)
                continue
            del self._pending[s.request_id]
            handle._finish(s.result, s.error)
            if not is_emergency(handle.command):
                self._slots.release()

    def _fail_pending(self, error: SessionClosed) -> None:
        """Settle every pending command: a command already sent may have run, so
        it ends :class:`OutcomeUnknown` (the book decides); none is left waiting."""
        self._deliver(self._book.settle_all(error))
        for rid in sorted(self._pending):  # never sent (none today: see submit)
            self._deliver([Settlement(rid, error=error)])

    @property
    def rejected_by_arm(self) -> int:
        """FAILED replies matching no command: packets the arm could not use."""
        return self._book.rejected_by_arm

    def _telemetry(self, feedback: Feedback) -> None:
        self.latest_telemetry = feedback
        for ch in self._subscribers:
            try:
                ch.send_nowait(feedback)
            except trio.WouldBlock:
                self.telemetry_dropped += 1

    # --- commands ---------------------------------------------------------------

    async def submit(self, command: Command) -> CommandHandle:
        """Queue ``command`` at the arm without waiting for it to run (pipelining).

        Checks the arguments first (raises :class:`CommandFailed` BAD_ARGUMENT
        before anything crosses the link); waits for room when
        ``max_in_flight`` commands are outstanding, and for the session during
        a reconnect.
        """
        if self.role is not Role.CONTROLLER:
            raise LocalProtocolError("an observer cannot command the arm")
        validate_arguments(command)
        if not is_emergency(command):
            await self._slots.acquire()
        try:
            # Bounded: the reconnect loop ends in a grant or in _closed.
            while not self._usable():
                if self._closed.is_set() or self._ending:
                    raise SessionClosed(
                        "the session is closed; nothing was sent (create a new client, "
                        "or reconnect with this one's identity to resume)"
                    )
                await self._changed.wait()
            rid, failures_seen = self._book.register(command)
        except BaseException:
            if not is_emergency(command):
                self._slots.release()
            raise
        handle = CommandHandle(rid, command)
        handle.failures_seen = failures_seen
        self._pending[rid] = handle
        pump, conn = self._pump, self._conn
        assert pump is not None
        assert conn is not None
        conn.send_command(rid, command, trio.current_time(), failures_seen=failures_seen)
        handle.sent = True
        pump.kick()
        return handle

    async def send(self, command: Command) -> CommandResult:
        """Run ``command`` and return its result; raises :class:`CommandFailed` on failure."""
        handle = await self.submit(command)
        return await handle.completed()

    async def telemetry(self) -> AsyncIterator[Feedback]:
        """The arm's state, as it arrives (every N-th control sample), until the session ends."""
        send, receive = trio.open_memory_channel[Feedback](TELEMETRY_BUFFER)
        self._subscribers.add(send)
        try:
            async with receive:
                async for feedback in receive:
                    yield feedback
        finally:
            self._subscribers.discard(send)

    def statistics(self) -> ClientStatistics:
        """A snapshot of the client's counters (see :class:`ClientStatistics`)."""
        pump = self._pump
        return ClientStatistics(
            pending=len(self._pending),
            reconnects=self.reconnects,
            telemetry_dropped=self.telemetry_dropped,
            rejected_by_arm=self.rejected_by_arm,
            bytes_sent=pump.bytes_out if pump is not None else 0,
            bytes_received=pump.bytes_in if pump is not None else 0,
            connection=pump.conn.statistics() if pump is not None else None,
        )


def _bye_text(exc: BaseException) -> str:
    """What the BYE tells the arm about why the controller left: the kind of
    ending, never the exception's text (it is local detail, not protocol)."""
    if isinstance(exc, KeyboardInterrupt | trio.Cancelled):
        return "controller interrupted"
    return f"controller error ({type(exc).__name__})"


async def _set_when(event: trio.Event, scope: trio.CancelScope) -> None:
    await event.wait()
    scope.cancel()
