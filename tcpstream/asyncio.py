"""The controller client for asyncio: the same protocol, promises and options as the trio one.

For controller code that lives in asyncio (rclpy executors, MAVSDK, FastAPI
dashboards)::

    import tcpstream.asyncio as arm_asyncio

    async with arm_asyncio.connect_tcp("arm.example", key=key, identity="ctl") as arm:
        print((await arm.status()).feedback.joints)
        handle = await arm.submit(tcpstream.commands.move_joint(1, 0.2))
        result = await handle.completed()

Like aioquic's ``asyncio/`` beside its ``quic/`` core, this module is only an
adapter: the session is the sans-I/O :class:`~tcpstream.connection.ClientConnection`
(handshake, authentication, counters, heartbeats, the dead time) and the
exactly-once bookkeeping is the sans-I/O ``RequestBook`` the trio
:class:`~tcpstream.ArmClient` uses too (request ids, the failure barrier,
resume after a reconnect, ``OutcomeUnknown`` when the arm forgot us).  What is
here: the asyncio tasks that move bytes and time, futures for the callers, the
reconnect loop and an optional controller watchdog.  Nothing here calls trio.

Every wait is bounded or cancellable: ``asyncio.timeout`` around any call or
around the whole ``async with`` unwinds cleanly, and the BYE still goes out
(bounded, 1 s) so the arm halts outstanding work at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import secrets
import ssl as _ssl
from collections.abc import AsyncIterator, Awaitable, Callable
from types import TracebackType
from typing import Any, Protocol, Unpack, cast

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
from ._commands import Command, CommandResult, Feedback, validate_arguments
from ._errors import (
    AuthenticationFailed,
    LocalProtocolError,
    SessionClosed,
)
from ._events import (
    CloseReason,
    ControllerIdentity,
    Event,
    Granted,
    PacketRejected,
    RefusalReceived,
    Role,
    SessionEnded,
    SessionParameters,
    TelemetryReceived,
)
from ._options import ClientConfig, ClientOptions, client_config
from ._state import SessionState

__all__ = ["AsyncioArmClient", "AsyncioCommandHandle", "Opener", "connect_tcp"]

log = logging.getLogger("tcpstream.asyncio")

DEFAULT_PORT = 7010
"""The same default as :data:`tcpstream.DEFAULT_PORT`."""
RECEIVE_CHUNK = 16 * 216
"""Bytes asked of the stream per read: a burst of pipelined replies at once."""
TELEMETRY_BUFFER = 16
"""Samples buffered per subscriber; the newest is dropped (counted) beyond."""
GOODBYE_TIMEOUT = 1.0
"""Seconds the BYE gets to go out when the client is cancelled or fails."""
CLOSE_TIMEOUT = 5.0
"""Seconds a normal close waits for the arm to see the BYE."""

Opener = Callable[[], Awaitable[tuple[asyncio.StreamReader, asyncio.StreamWriter]]]
"""Opens a fresh byte stream to the arm (called again for every reconnection)."""


class AsyncioCommandHandle:
    """One submitted command: await :meth:`accepted`, then :meth:`completed`."""

    def __init__(self, request_id: int, command: Command) -> None:
        loop = asyncio.get_running_loop()
        self.request_id = request_id
        self.command = command
        self.position: int | None = None
        """Queue position reported by the arm's ACCEPTED (None until then)."""
        self._accepted: asyncio.Future[int] = loop.create_future()
        self._done: asyncio.Future[CommandResult] = loop.create_future()
        # A caller that never awaits a failed handle must not get "exception
        # was never retrieved" noise: the outcome is also in .done / .error.
        self._accepted.add_done_callback(_quiet)
        self._done.add_done_callback(_quiet)

    @property
    def done(self) -> bool:
        return self._done.done()

    async def accepted(self) -> int:
        """Wait until the arm queued the command; raises its failure if it failed first."""
        return await asyncio.shield(self._accepted)

    async def completed(self) -> CommandResult:
        """The outcome: the result, or :class:`CommandFailed` / :class:`OutcomeUnknown` /
        :class:`SessionClosed` raised."""
        return await asyncio.shield(self._done)

    def _settle(self, s: Settlement) -> None:
        if not s.final:
            assert s.position is not None
            self.position = s.position
            if not self._accepted.done():
                self._accepted.set_result(s.position)
            return
        if self._done.done():
            return
        if s.error is not None:
            if not self._accepted.done():
                self._accepted.set_exception(s.error)
            self._done.set_exception(s.error)
        else:
            assert s.result is not None
            if not self._accepted.done():
                self._accepted.set_result(self.position or 0)
            self._done.set_result(s.result)


def _quiet(future: asyncio.Future[Any]) -> None:
    if not future.cancelled():
        future.exception()


class AsyncioArmClient(CommandMethods):
    """A controller (or observer) connection to an arm, for asyncio.  Use ``async with``.

    Prefer :func:`connect_tcp`.  ``opener`` opens a fresh stream for the
    first connection and every reconnection.  The options are those of
    :class:`~tcpstream.ClientConfig` (or its fields as keywords).  ``watchdog``
    (seconds, optional): if the application makes no call into the client for
    that long (:meth:`kick` counts), the client says BYE at once, so the arm
    halts outstanding work instead of waiting for its deadman; later calls
    raise :class:`SessionClosed`.
    """

    def __init__(
        self,
        opener: Opener,
        config: ClientConfig | None = None,
        *,
        watchdog: float | None = None,
        **options: Unpack[ClientOptions],
    ) -> None:
        self._opener = opener
        self.config = settings = client_config(config, options)
        incarnation = settings.incarnation
        self.identity = ControllerIdentity(
            settings.identity, incarnation if incarnation is not None else secrets.randbits(64)
        )
        self.role = Role.OBSERVER if settings.observer else Role.CONTROLLER
        ClientConnection(self.identity, role=self.role, key=settings.key)  # checks now
        if watchdog is not None and not watchdog > 0:
            raise ValueError(f"watchdog must be > 0 seconds, or None; got {watchdog!r}")
        self.watchdog = watchdog
        self._book = RequestBook()
        self._pending: dict[int, AsyncioCommandHandle] = {}
        self._slots = asyncio.Semaphore(settings.max_in_flight)
        self._conn: ClientConnection | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._wake = asyncio.Event()  # output for the current session's writer
        self._lane_wake = asyncio.Event()  # an EMERGENCY_STOP for the expedited lane
        self._state: _SessionState | None = None
        # Set (and replaced) whenever the session is granted, ends or the client
        # closes: what submit() and __aenter__ wait on.
        self._changed = asyncio.Event()
        self._ready = False
        self._closed = False
        self._ending = False
        self._failure: Exception | None = None
        self._task: asyncio.Task[None] | None = None
        self._watch_task: asyncio.Task[None] | None = None
        self._session_done: asyncio.Event | None = None
        self._last_call = 0.0
        self._subscribers: set[asyncio.Queue[Feedback | None]] = set()
        self.parameters: SessionParameters | None = None
        self.latest_telemetry: Feedback | None = None
        self.reconnects = 0
        self.telemetry_dropped = 0
        self.bytes_sent = 0
        self.bytes_received = 0

    # --- lifetime -------------------------------------------------------------

    async def __aenter__(self) -> AsyncioArmClient:
        loop = asyncio.get_running_loop()
        self._last_call = loop.time()
        self._task = asyncio.create_task(self._connection_loop(), name="tcpstream-client")
        try:
            await self._wait_for(lambda: self._ready or self._closed)
            if not self._ready:
                raise self._failure or SessionClosed("the arm closed the connection")
        except BaseException:
            await self._stop_tasks()
            raise
        if self.watchdog is not None:
            self._watch_task = asyncio.create_task(self._watch(), name="tcpstream-watchdog")
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        try:
            if exc is None:
                await self.aclose()
            else:
                await self._goodbye(CloseReason.SHUTDOWN, _bye_text(exc))
        except BaseException as inner:
            # Cancelled (asyncio.timeout around the block) while closing: the
            # session still ends with a BYE, and the tasks still stop.
            await self._goodbye(CloseReason.SHUTDOWN, _bye_text(inner))
            raise
        finally:
            await self._stop_tasks()

    async def aclose(self, *, wait: bool = True) -> None:
        """Finish: wait for outstanding commands (``wait``), say BYE, close the stream."""
        if wait:
            for handle in list(self._pending.values()):
                with contextlib.suppress(Exception):
                    await handle.completed()
        self._close_now(CloseReason.NORMAL, "controller done")
        await self._wait_session_done(CLOSE_TIMEOUT)

    def kick(self) -> None:
        """Tell the watchdog the application is alive (any call does too)."""
        self._last_call = asyncio.get_running_loop().time()

    async def _goodbye(self, reason: CloseReason, message: str) -> None:
        if not self._ending:
            self._close_now(reason, message)
        # Shielded and bounded: the BYE goes out even inside a cancelled scope.
        with contextlib.suppress(asyncio.CancelledError, TimeoutError):
            await asyncio.shield(self._wait_session_done(GOODBYE_TIMEOUT))

    async def _wait_session_done(self, timeout: float) -> None:
        done = self._session_done
        if done is not None:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(timeout):
                    await done.wait()

    async def _stop_tasks(self) -> None:
        for task in (self._watch_task, self._task):
            if task is not None and not task.done():
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await asyncio.shield(task)
        self._closed = True
        self._settle_all(SessionClosed("the client closed the session"))

    def _close_now(self, reason: CloseReason, message: str) -> None:
        self._ending = True
        conn = self._conn
        if conn is not None and not conn.closed:
            conn.close(reason, asyncio.get_running_loop().time(), message)
            self._kick_io()
        self._settle_all(SessionClosed("the client closed the session", reason))
        self._notify()

    # --- the connection loop ----------------------------------------------------

    async def _connection_loop(self) -> None:
        cfg = self.config
        granted_once = False
        used = 0
        lost = "the session ended"
        try:
            try:
                streams = await self._opener()
            except (OSError, TimeoutError) as exc:
                self._failure = SessionClosed(f"cannot reach the arm: {describe_error(exc)}")
                return
            while True:
                granted, ended = await self._run_session(*streams)
                granted_once = granted_once or granted
                if granted:
                    used = 0
                lost = f"the link to the arm was lost ({ended.message})"
                if not granted_once or self._ending or ended.reason in FINAL_REASONS:
                    if self._failure is None and not granted_once:
                        self._failure = SessionClosed(f"no session: {ended.message}", ended.reason)
                    return
                next_streams = None
                last_error = ""
                while next_streams is None and used < cfg.reconnect_attempts:
                    await asyncio.sleep(cfg.reconnect_delay * 2**used)
                    used += 1
                    try:
                        next_streams = await self._opener()
                    except (OSError, TimeoutError) as exc:
                        last_error = describe_error(exc)
                        log.info("reconnect attempt %d failed: %s", used, last_error)
                if next_streams is None:
                    lost = gave_up(lost, cfg.reconnect_attempts, used, last_error)
                    return
                if self._closing():  # closed while we were reconnecting
                    next_streams[1].close()
                    return
                self.reconnects += 1
                streams = next_streams
        finally:
            self._closed = True
            self._settle_all(SessionClosed(f"{lost}; the session could not be resumed"))
            for queue in self._subscribers:
                _offer(queue, None)
            self._notify()

    async def _run_session(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> tuple[bool, SessionEnded]:
        loop = asyncio.get_running_loop()
        cfg = self.config
        conn = ClientConnection(
            self.identity,
            role=self.role,
            key=cfg.key,
            handshake_timeout=cfg.handshake_timeout,
            now=loop.time(),
            nonce_source=cfg.nonce_source,
        )
        self._conn, self._writer = conn, writer
        lane = _expedited_lane(writer)
        conn.expedited = lane is not None  # PROTOCOL.md section 15
        self._session_done = done = asyncio.Event()
        self._state = state = _SessionState()
        conn.connect(loop.time())
        self._wake.set()
        tasks = [
            asyncio.create_task(self._read(reader, conn, state)),
            asyncio.create_task(self._write(writer, conn, state)),
            asyncio.create_task(self._tick(conn, state)),
        ]
        if lane is not None:
            tasks.append(asyncio.create_task(self._lane_write(lane, conn)))
        try:
            await state.over.wait()
        finally:
            for task in tasks:
                task.cancel()
            for task in tasks:
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task
            # Push out what is left (a BYE), bounded, then close.
            with contextlib.suppress(Exception):
                data = conn.data_to_send()
                if data and not writer.is_closing():
                    writer.write(data)
                    async with asyncio.timeout(GOODBYE_TIMEOUT):
                        await writer.drain()
            writer.close()
            with contextlib.suppress(Exception):
                async with asyncio.timeout(GOODBYE_TIMEOUT):
                    await writer.wait_closed()
            self._ready = False
            done.set()
            self._notify()
        ended = state.ended or SessionEnded(CloseReason.PEER_EOF, "stream ended", True)
        if state.stream_error is not None:
            ended = SessionEnded(
                ended.reason, f"{ended.message}: {describe_error(state.stream_error)}", False
            )
        return state.granted, ended

    async def _read(
        self, reader: asyncio.StreamReader, conn: ClientConnection, state: _SessionState
    ) -> None:
        loop = asyncio.get_running_loop()
        while not conn.closed:
            try:
                data = await reader.read(RECEIVE_CHUNK)
            except (OSError, asyncio.IncompleteReadError) as exc:
                state.stream_error = state.stream_error or exc
                data = b""
            self.bytes_received += len(data)
            conn.receive_data(data, loop.time())
            self._drain_events(conn, state)
            if not data:
                break
        state.over.set()

    async def _write(
        self, writer: asyncio.StreamWriter, conn: ClientConnection, state: _SessionState
    ) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            data = conn.data_to_send()
            if data:
                try:
                    writer.write(data)
                    await writer.drain()
                except OSError as exc:
                    state.stream_error = state.stream_error or exc
                    state.over.set()
                    return
                self.bytes_sent += len(data)
            if conn.closed:
                state.over.set()
                return

    async def _lane_write(self, lane: _Lane, conn: ClientConnection) -> None:
        """Hands each EMERGENCY_STOP to the stream's expedited lane at once,
        never behind the writer, which may be waiting in ``drain``."""
        while not conn.closed:
            await self._lane_wake.wait()
            self._lane_wake.clear()
            for message in conn.expedited_to_send():
                try:
                    await lane.send_expedited(message)
                except (OSError, RuntimeError) as exc:
                    log.debug("expedited lane failed: %r", exc)  # the stream reports it too
                    return
                self.bytes_sent += len(message)

    async def _tick(self, conn: ClientConnection, state: _SessionState) -> None:
        loop = asyncio.get_running_loop()
        while not conn.closed:
            deadline = conn.get_timer()
            delay = 1.0 if deadline is None else max(0.0, deadline - loop.time())
            # Woken early by output (a send may move the heartbeat timer).
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(delay):
                    await state.timer_moved.wait()
            state.timer_moved.clear()
            conn.handle_timer(loop.time())
            self._drain_events(conn, state)
            self._wake.set()
        state.over.set()

    def _closing(self) -> bool:
        # A method, not the attribute: it changes across awaits.
        return self._ending

    def _kick_io(self) -> None:
        self._wake.set()
        if self._conn is not None and self._conn.expedited_pending:
            self._lane_wake.set()
        if self._state is not None:
            self._state.timer_moved.set()  # a state change may move the timer earlier

    # --- events -----------------------------------------------------------------

    def _drain_events(self, conn: ClientConnection, state: _SessionState) -> None:
        while (event := conn.next_event()) is not None:
            self._on_event(event, conn, state)
        if conn.closed:
            state.over.set()
        self._wake.set()
        if conn.expedited_pending:
            self._lane_wake.set()

    def _on_event(self, event: Event, conn: ClientConnection, state: _SessionState) -> None:
        if isinstance(event, Granted):
            state.granted = True
            self.parameters = event.parameters
            resend, unknown = self._book.on_grant(event)
            self._deliver(unknown)
            now = asyncio.get_running_loop().time()
            for rid, command, failures_seen in resend:
                conn.send_command(rid, command, now, failures_seen=failures_seen)
            self._ready = True
            self._notify()
        elif isinstance(event, TelemetryReceived):
            self.latest_telemetry = event.feedback
            for queue in self._subscribers:
                if not _offer(queue, event.feedback):
                    self.telemetry_dropped += 1
        elif isinstance(event, RefusalReceived):
            self._failure = refusal_error(event)
        elif isinstance(event, SessionEnded):
            self._ready = False
            state.ended = event
            if event.reason is CloseReason.AUTHENTICATION and not event.by_peer:
                self._failure = AuthenticationFailed(event.message)
            self._notify()
        elif isinstance(event, PacketRejected):
            log.info("dropped a packet from the arm: %s", event.message)
        else:
            self._deliver(self._book.on_event(event))

    def _deliver(self, settlements: list[Settlement]) -> None:
        for s in settlements:
            handle = self._pending.get(s.request_id)
            if handle is None:
                continue
            if s.final:
                del self._pending[s.request_id]
                if not is_emergency(handle.command):
                    self._slots.release()
            handle._settle(s)

    def _settle_all(self, why: SessionClosed) -> None:
        self._deliver(self._book.settle_all(why))

    def _notify(self) -> None:
        self._changed.set()
        self._changed = asyncio.Event()

    async def _wait_for(self, predicate: Callable[[], bool]) -> None:
        # Bounded by the connection loop: it ends in a grant or in _closed.
        while not predicate():
            await self._changed.wait()

    async def _watch(self) -> None:
        assert self.watchdog is not None
        loop = asyncio.get_running_loop()
        while True:
            idle = loop.time() - self._last_call
            if idle >= self.watchdog:
                log.warning("watchdog: no call for %.1f s; saying BYE", idle)
                self._failure = SessionClosed(
                    f"the controller watchdog expired ({self.watchdog:g} s without a call)"
                )
                self._close_now(CloseReason.SHUTDOWN, "controller watchdog expired")
                return
            await asyncio.sleep(self.watchdog - idle)

    # --- commands ---------------------------------------------------------------

    async def submit(self, command: Command) -> AsyncioCommandHandle:
        """Queue ``command`` at the arm without waiting for it to run (pipelining).

        Arguments are checked first (``CommandFailed`` BAD_ARGUMENT before
        anything crosses the link); waits for room when ``max_in_flight``
        commands are outstanding, and for the session during a reconnect.
        """
        self.kick()
        if self.role is not Role.CONTROLLER:
            raise LocalProtocolError("an observer cannot command the arm")
        validate_arguments(command)
        emergency = is_emergency(command)
        if not emergency:
            await self._slots.acquire()
        try:
            await self._wait_for(lambda: self._usable() or self._closed or self._ending)
            if not self._usable():
                raise (
                    self._failure
                    if isinstance(self._failure, SessionClosed)
                    else (SessionClosed("the session is closed; nothing was sent"))
                )
            rid, failures_seen = self._book.register(command)
        except BaseException:
            if not emergency:
                self._slots.release()
            raise
        handle = AsyncioCommandHandle(rid, command)
        self._pending[rid] = handle
        conn = self._conn
        assert conn is not None
        conn.send_command(
            rid, command, asyncio.get_running_loop().time(), failures_seen=failures_seen
        )
        self._kick_io()
        return handle

    def _usable(self) -> bool:
        conn = self._conn
        return (
            self._ready
            and not self._ending
            and conn is not None
            and conn.state is SessionState.OPEN
        )

    async def send(self, command: Command) -> CommandResult:
        """Run ``command`` and return its result; raises ``CommandFailed`` on failure."""
        handle = await self.submit(command)
        try:
            return await handle.completed()
        finally:
            self.kick()

    async def telemetry(self) -> AsyncIterator[Feedback]:
        """The arm's state as it arrives, until the session ends (newest dropped if slow)."""
        queue: asyncio.Queue[Feedback | None] = asyncio.Queue(TELEMETRY_BUFFER)
        self._subscribers.add(queue)
        try:
            while (item := await queue.get()) is not None:
                yield item
        finally:
            self._subscribers.discard(queue)

    @property
    def pending(self) -> int:
        """Commands sent and not yet settled."""
        return len(self._pending)

    @property
    def rejected_by_arm(self) -> int:
        return self._book.rejected_by_arm


class _Lane(Protocol):
    """A writer with an expedited lane (``serialsocket.asyncio``'s socket)."""

    @property
    def expedited(self) -> bool: ...

    async def send_expedited(self, message: bytes) -> None: ...


def _expedited_lane(writer: object) -> _Lane | None:
    """The expedited lane under ``writer``, if there is a working one
    (PROTOCOL.md section 15): the writer itself, or, for the (reader, writer)
    pair of ``serialsocket.asyncio.open_connection``, its extra "socket"."""
    candidates = [writer]
    get_extra_info = getattr(writer, "get_extra_info", None)
    if callable(get_extra_info):
        candidates.append(get_extra_info("socket"))
    for candidate in candidates:
        if getattr(candidate, "expedited", False) is True and callable(
            getattr(candidate, "send_expedited", None)
        ):
            return cast(_Lane, candidate)
    return None


class _SessionState:
    """One stream's worth of state shared by its three tasks."""

    def __init__(self) -> None:
        self.over = asyncio.Event()
        self.timer_moved = asyncio.Event()
        self.granted = False
        self.ended: SessionEnded | None = None
        self.stream_error: BaseException | None = None


def _bye_text(exc: BaseException) -> str:
    """What the BYE tells the arm: the kind of ending, never the exception's text."""
    if isinstance(exc, KeyboardInterrupt | asyncio.CancelledError | TimeoutError):
        return "controller interrupted"
    return f"controller error ({type(exc).__name__})"


def _offer(queue: asyncio.Queue[Feedback | None], item: Feedback | None) -> bool:
    try:
        queue.put_nowait(item)
    except asyncio.QueueFull:
        return False
    return True


def connect_tcp(
    host: str,
    port: int = DEFAULT_PORT,
    *,
    ssl: _ssl.SSLContext | None = None,
    server_hostname: str | None = None,
    config: ClientConfig | None = None,
    watchdog: float | None = None,
    **options: Unpack[ClientOptions],
) -> AsyncioArmClient:
    """``async with connect_tcp(host, port, key=..., identity=...) as arm:`` (asyncio).

    Reconnects and resumes like :func:`tcpstream.connect_tcp`.  With ``ssl``
    the stream is TLS (``server_hostname`` defaults to ``host``).
    """

    async def opener() -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        if ssl is None:
            return await asyncio.open_connection(host, port)
        return await asyncio.open_connection(
            host, port, ssl=ssl, server_hostname=server_hostname or host
        )

    return AsyncioArmClient(opener, client_config(config, options), watchdog=watchdog)
