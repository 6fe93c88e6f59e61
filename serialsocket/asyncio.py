"""The serial socket for asyncio: the same endpoint, protocol and promises as the trio one.

For code that lives in asyncio (rclpy executors, MAVSDK, FastAPI dashboards)::

    import serialsocket.asyncio as serial_asyncio

    async with serial_asyncio.open_serial_socket("/dev/ttyUSB0", baud=9600) as sock:
        sock.write(b"hello")
        await sock.drain()
        print(await sock.read(100))

and on the other side ``async with serial_asyncio.listen(port) as listener:
sock = await listener.accept()``.  A socket reads like an
``asyncio.StreamReader`` (``read``, ``readexactly``) and writes like an
``asyncio.StreamWriter`` (``write``, ``drain``, ``write_eof``, ``close``,
``wait_closed``); plus ``abort``, ``statistics`` and ``close_error``.  For
APIs that want a reader/writer pair -- :mod:`tcpstream.asyncio`'s ``Opener``
-- :func:`open_connection` gives exactly that.

Like aioquic's ``asyncio/`` beside its ``quic/`` core, this module is only an
adapter: the protocol is the sans-I/O :class:`~serialsocket.Endpoint` the
trio :class:`~serialsocket.SerialSocket` runs, the failure causes and the
ending report are shared with it (:class:`~serialsocket.PeerAborted`,
:class:`~serialsocket.LinkDeadError`, :class:`~serialsocket.LineFailed`,
:class:`~serialsocket.SocketStatistics`), and the port is opened by the same
code.  What is here: the tasks that move bytes and time, and the stream
object.  Importing or using it never imports trio.

Errors follow asyncio's habits: a failed link is a ``ConnectionError``
whose ``__cause__`` says what happened (as ``trio.BrokenResourceError``'s
does); using a closed socket, or reading from two tasks at once, is a
``RuntimeError``; a refused connect is ``ConnectionRefusedError``, an
unanswered one ``TimeoutError``.  Every wait is cancellable: a cancelled
read or drain leaves the socket usable, and a socket closed by an exception
(``asyncio.timeout`` around the ``async with``) is aborted, its E packet
pushed out within a bounded time.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from types import TracebackType

from ._asyncio_driver import AsyncioDriver
from ._asyncio_port import (
    READ_SIZE,
    AsyncioSerialPort,
    AsyncPort,
    open_port,
    open_pty_pair,
    port_statistics,
)
from ._asyncio_streams import streams_over
from ._config import EndpointConfig
from ._endpoint import Endpoint
from ._errors import LocalProtocolError
from ._outcome import LineFailed, PeerAborted, SocketStatistics, ending
from ._state import LIVE, TERMINAL, State

__all__ = [
    "AsyncPort",
    "AsyncioSerialListener",
    "AsyncioSerialPort",
    "AsyncioSerialSocket",
    "accept",
    "connect",
    "listen",
    "open_connection",
    "open_port",
    "open_pty_pair",
    "open_serial_socket",
    "serve",
]

log = logging.getLogger(__name__)

PortLike = AsyncPort | str
"""A port object, or a device path / pyserial URL to open (at ``baud``)."""

_REQUEST_GRACE = 0.05
"""Seconds a deferred socket's first read waits for a first write before it
sends the connection request itself (as the trio socket's)."""


class AsyncioSerialSocket:
    """A connected serial socket for asyncio: reliable, sequenced, full duplex.

    Obtain one from :func:`connect`, :func:`open_serial_socket` or
    :meth:`AsyncioSerialListener.accept`.  ``read`` returns ``b""`` only at
    the peer's EOF; after ``write_eof`` the peer sees EOF once every byte
    before it arrived; ``close`` closes gracefully -- for as long as the close
    makes progress, giving up after ``close_timeout`` without any -- and a
    cancelled ``wait_closed``/``aclose`` aborts.  A socket from
    ``connect(..., defer=True)`` connects on its first write (see
    :func:`connect`).
    """

    def __init__(
        self, driver: AsyncioDriver, *, close_timeout: float | None, deferred: bool = False
    ) -> None:
        self._d = driver
        self._deferred = deferred
        """Made by ``connect(defer=True)``: until established, calls wait for
        the connection and raise its failure as :func:`connect` would."""
        self._unrequested = deferred
        """Deferred, and the connection request has not gone out yet."""
        self._request_by: float | None = None
        """When a waiting read sends the deferred request itself."""
        self._generation = driver.generation
        self._reading = False
        self._eof_written = False
        self._closing: asyncio.Task[None] | None = None
        self.close_timeout = close_timeout
        """Seconds a close may go without progress before it is given up; None:
        the endpoint's dead-link interval, which follows the measured round trip."""
        self.close_error: str | None = None
        """After the close: None if the connection ended delivered (every byte
        we were given acknowledged by the peer and the peer's EOF received),
        else what happened and how many bytes were acknowledged, in flight and
        never sent."""
        self._final: str | None = None  # how it ended, if a listener reset it first

    @property
    def endpoint(self) -> Endpoint:
        """The sans-I/O endpoint underneath (for inspection)."""
        return self._d.ep

    def statistics(self) -> SocketStatistics:
        """The ARQ statistics and the port counters (the trio socket's record)."""
        d = self._d
        return SocketStatistics(
            link=d.ep.statistics(),
            port_reads=d.reads,
            port_writes=d.writes,
            port_bytes_in=d.bytes_in,
            port_bytes_out=d.bytes_out,
            port=port_statistics(d.port),
        )

    # -- checks -----------------------------------------------------------------

    def _current(self) -> bool:
        return self._generation == self._d.generation

    def _check_open(self) -> None:
        if self._closing is not None or not self._current():
            raise RuntimeError("this serial socket was closed")

    def _connecting(self) -> bool:
        """A deferred connection not yet established (requested or not)."""
        return self._deferred and self._d.ep.parameters is None

    def _request(self) -> None:
        """Send the deferred connection request now, carrying the head of what
        was written as early data; nothing once it went."""
        if self._unrequested:
            self._unrequested = False
            d = self._d
            d.feed()  # the bytes written so far go into the endpoint: the init takes its head
            d.ep.connect(d.now())
            d.notify()

    def _raise_if_connect_failed(self) -> None:
        """A deferred connection that failed before it was established: raise
        what :func:`connect` raises, chained to ConnectionError."""
        d = self._d
        if self._connecting() and (d.ep.state in TERMINAL or d.broken is not None or d.stopped):
            cause = _connect_failure(d)
            raise ConnectionError(str(cause)) from cause

    async def _wait(self) -> None:
        """Wait for the next change.  An unrequested deferred socket waits at
        most until ``_REQUEST_GRACE`` after the first such wait, then sends
        its connection request (without early data)."""
        d = self._d
        if not self._unrequested:
            await d.changed()
            return
        if self._request_by is None:
            self._request_by = d.now() + _REQUEST_GRACE
        try:
            async with asyncio.timeout_at(self._request_by):
                await d.changed()
                return
        except TimeoutError:
            self._request()

    async def _established(self) -> None:
        """Send a deferred request if it has not gone, and wait for the
        connection (bounded by the connect timeout); raise its failure."""
        self._request()
        while self._connecting():
            self._check_open()
            self._raise_if_connect_failed()
            await self._d.changed()

    def _raise_if_broken(self) -> None:
        self._raise_if_connect_failed()
        d = self._d
        if d.broken is not None:
            raise ConnectionError(str(d.broken)) from d.broken
        if d.ep.state in (State.FAILED, State.DEAD):
            cause = LineFailed(f"the connection ended ({d.ep.state.value})")
            raise ConnectionError(str(cause)) from cause

    # -- reading ------------------------------------------------------------------

    async def read(self, n: int = -1) -> bytes:
        """Up to ``n`` bytes from the peer, in order, each exactly once; ``b""`` only at EOF.

        ``n = -1`` reads until EOF (as ``asyncio.StreamReader.read``).  On a
        deferred socket this waits for the connection as well (see
        :func:`connect`).

        Raises:
            ConnectionError: the connection failed (see ``__cause__``; for a
                deferred connection that was never established, what
                :func:`connect` raises); bytes delivered before the failure
                are returned first.
            RuntimeError: the socket was closed (also wakes a blocked read),
                or another task is already reading.
        """
        if n == 0:
            return b""
        if n < 0:
            chunks = []
            while chunk := await self.read(READ_SIZE):
                chunks.append(chunk)
            return b"".join(chunks)
        if self._reading:
            raise RuntimeError("another task is already reading from this socket")
        self._reading = True
        try:
            while True:
                self._check_open()
                d = self._d
                queued = d.ep.control_pending
                data = d.ep.read(n, d.now())
                if data:
                    if d.ep.control_pending != queued:
                        d.notify()  # the read queued a window update: wake the writer
                    return data
                if d.ep.at_eof:
                    return b""
                self._raise_if_broken()
                await self._wait()
        finally:
            self._reading = False

    async def readexactly(self, n: int) -> bytes:
        """Exactly ``n`` bytes; ``asyncio.IncompleteReadError`` if EOF comes first."""
        if n < 0:
            raise ValueError("readexactly size can not be less than zero")
        got = bytearray()
        while len(got) < n:
            chunk = await self.read(n - len(got))
            if not chunk:
                raise asyncio.IncompleteReadError(bytes(got), n)
            got += chunk
        return bytes(got)

    def at_eof(self) -> bool:
        """The peer's EOF arrived and every byte before it was read."""
        return self._d.ep.at_eof

    # -- writing ------------------------------------------------------------------

    def write(self, data: bytes | bytearray | memoryview) -> None:
        """Queue ``data`` for reliable delivery (never blocks; ``drain`` waits for room).

        On a deferred socket the first (non-empty) write sends the connection
        request, carrying the first of ``data`` as early data.

        Raises:
            ConnectionError: the connection already failed.
            RuntimeError: the socket was closed, or ``write_eof`` was called.
        """
        self._check_open()
        if self._eof_written:
            raise RuntimeError("cannot write after write_eof()")
        self._raise_if_broken()
        if data:
            self._d.outbox += data
            self._request()
            self._d.notify()

    def get_write_buffer_size(self) -> int:
        """Bytes written that the endpoint's send buffer has not taken yet."""
        return len(self._d.outbox)

    def writelines(self, data: list[bytes]) -> None:
        """``write`` each of ``data``."""
        for chunk in data:
            self.write(chunk)

    async def drain(self) -> None:
        """Wait until everything written is in the endpoint's (bounded) send buffer.

        Raises:
            ConnectionError: the connection failed (see ``__cause__``).
            RuntimeError: the socket was closed.
        """
        while True:
            self._check_open()
            self._raise_if_broken()
            if not self._d.outbox:
                await asyncio.sleep(0)
                return
            await self._d.changed()

    # -- the expedited lane (PROTOCOL.md section 11) ---------------------------

    @property
    def expedited(self) -> bool:
        """Both ends agreed on the expedited lane (False with a classic or older peer).

        A deferred socket not yet connected says whether it asks for the lane,
        as ``SerialSocket.expedited`` does (:meth:`send_expedited` waits for
        the connection)."""
        if self._connecting() and self._d.ep.state not in TERMINAL:
            return self._d.ep.config.expedited
        return self._d.ep.expedited

    async def send_expedited(self, message: bytes | bytearray | memoryview) -> None:
        """Send one small urgent message ahead of every byte queued on the stream
        (see ``SerialSocket.send_expedited``); waits while the lane is full, and
        on a deferred socket for the connection.

        Raises:
            ConnectionError: the connection failed or has no lane.
            RuntimeError: the socket was closed.
            ValueError: ``message`` is empty or too long for the lane.
        """
        self._check_open()
        await self._established()
        while True:
            self._check_open()
            self._raise_if_broken()
            try:
                queued = self._d.ep.offer_expedited(message, self._d.now())
            except LocalProtocolError as exc:  # no lane, or the connection ended
                raise ConnectionError(str(exc)) from exc
            if queued:
                self._d.notify()
                return
            await self._d.changed()  # the lane is full: wait for an acknowledgement

    async def receive_expedited(self) -> bytes:
        """The peer's next expedited message, whole; waits for one.

        Raises:
            ConnectionError: the connection ended (messages that had arrived
                are returned first).
            RuntimeError: the socket was closed.
        """
        while True:
            self._check_open()
            message = self._d.ep.read_expedited()
            if message is not None:
                return message
            self._raise_if_broken()
            if (over := self._d.ep.expedited_over) is not None:
                raise ConnectionError(over)
            await self._wait()

    # -- the latest-value lane (PROTOCOL.md section 12) ------------------------

    @property
    def latest(self) -> bool:
        """Both ends agreed on the latest-value lane (False with a classic or older
        peer, and on a deferred socket until it is connected)."""
        return self._d.ep.latest

    def send_latest(self, value: bytes | bytearray | memoryview) -> None:
        """Offer ``value`` as the newest of a series; never waits (see
        ``SerialSocket.send_latest``).

        Raises:
            ConnectionError: the connection failed, is closing, or has no lane.
            RuntimeError: the socket was closed.
            ValueError: ``value`` is empty or does not fit one packet.
        """
        self._check_open()
        self._raise_if_broken()
        try:
            self._d.ep.send_latest(value, self._d.now())
        except LocalProtocolError as exc:  # no lane, or the connection ended
            raise ConnectionError(str(exc)) from exc
        self._d.notify()

    async def receive_latest(self) -> bytes:
        """The newest value from the peer not yet received; waits for one.

        Raises:
            ConnectionError: the connection ended (a value that had arrived is
                returned first).
            RuntimeError: the socket was closed.
        """
        while True:
            self._check_open()
            value = self._d.ep.read_latest()
            if value is not None:
                return value
            self._raise_if_broken()
            if (over := self._d.ep.latest_over) is not None:
                raise ConnectionError(over)
            await self._wait()

    def can_write_eof(self) -> bool:
        return True

    def write_eof(self) -> None:
        """Half-close: the peer reads EOF after every byte written so far; reading goes on."""
        self._check_open()
        if self._eof_written:
            return
        self._raise_if_broken()
        self._eof_written = True
        self._d.eof_requested = True
        self._request()
        self._d.notify()

    async def wait_acknowledged(self) -> None:
        """Wait until every byte written so far is acknowledged by the peer."""
        d = self._d
        while True:
            self._check_open()
            self._raise_if_broken()
            if not d.outbox and not d.eof_requested and d.ep.all_acknowledged:
                return
            await d.changed()

    # -- closing ------------------------------------------------------------------

    def is_closing(self) -> bool:
        return self._closing is not None

    def close(self) -> None:
        """Start a graceful close (see :meth:`aclose`); ``wait_closed`` waits for it."""
        if self._closing is None:
            self._closing = asyncio.create_task(self._close(graceful=True))
            self._d.notify()  # wake our own blocked read/drain: they now raise

    def abort(self, reason: str = "connection aborted by the application") -> None:
        """End the connection at once, telling the peer why (an E packet)."""
        if self._closing is None:
            self._closing = asyncio.create_task(self._close(graceful=False, reason=reason))
            self._d.notify()

    async def wait_closed(self) -> None:
        """Wait for the close (or abort) to finish; if cancelled, abort (bounded)."""
        task = self._closing
        if task is None:
            raise RuntimeError("wait_closed() before close() or abort()")
        try:
            await asyncio.shield(task)
        except asyncio.CancelledError:
            self._abort_now("the close was cancelled")
            with contextlib.suppress(Exception):
                await asyncio.shield(task)  # bounded: the E and the port's close
            raise

    async def aclose(self) -> None:
        """Close gracefully: all our data acknowledged, both EOFs exchanged.

        Waits as long as the close makes progress -- our data being
        acknowledged, the peer's EOF arriving -- however long a backlog on a
        slow line takes; the endpoint gives it up (an E packet to the peer)
        only after ``close_timeout`` seconds in which nothing moved, or when
        the link is judged dead.  Afterwards :attr:`close_error` is None
        exactly when every byte was delivered both ways; ``aclose`` does not
        raise for it.  If cancelled, the connection is aborted.  Idempotent.

        A deferred socket whose request has not gone out sends nothing (its
        port closes at once, :attr:`close_error` None); one whose request
        went out waits for the connection (bounded by the connect timeout),
        then closes gracefully.
        """
        self.close()
        await self.wait_closed()

    async def __aenter__(self) -> AsyncioSerialSocket:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc is None:
            await self.aclose()
        else:
            self.abort(_abort_text(exc))
            await self.wait_closed()

    def _abort_now(self, reason: str) -> None:
        d = self._d
        if self._current() and d.ep.state in LIVE:
            d.ep.abort(reason, d.now())
            d.after_input()

    async def _close(self, *, graceful: bool, reason: str = "") -> None:
        d = self._d
        await asyncio.sleep(0)
        if not self._current():
            # The listener already reset the endpoint for a newer connection:
            # it is not ours to close.  How ours ended was recorded then.
            self.close_error = self._final
            return
        if self._unrequested:
            # Deferred and never requested: the peer knows nothing of us.
            await d.stop()
            return
        try:
            if not graceful:
                self._abort_now(reason)
            # A deferred connection still being made ends (the endpoint's
            # connect deadline) or comes up; then it is closed like any other.
            while d.ep.state is State.CONNECTING and d.broken is None and not d.stopped:
                await d.changed()
            if d.ep.state is State.ESTABLISHED and d.broken is None:
                await self._hand_over_outbox()
                if d.ep.state is State.ESTABLISHED and d.broken is None:
                    d.ep.close(d.now(), patience=self.close_timeout)
                    d.notify()
                # Only the endpoint ends this wait: the close completes, the
                # peer aborts, the link is judged dead, or the close makes no
                # progress for close_timeout (its deadline re-arms inside the
                # endpoint's timers on every acknowledgement).
                while d.ep.state is State.ESTABLISHED and d.broken is None and not d.stopped:
                    await d.changed()
        finally:
            await d.flush()
            if d.owns_port:
                await d.stop()
            else:
                d.notify()
        if self._deferred and d.ep.parameters is None:  # never connected
            self.close_error = ending(d.ep, f"connecting failed: {_connect_failure(d)}")
        else:
            self.close_error = ending(d.ep, d.outcome.describe(d.ep, stopped=d.stopped))

    async def _hand_over_outbox(self) -> None:
        """Before the endpoint's close: get what ``write`` buffered into the endpoint,
        giving up (abort) after ``close_timeout`` without progress."""
        d = self._d
        while d.outbox and d.ep.state is State.ESTABLISHED and d.broken is None:
            # None: the endpoint's dead-link interval, which follows the
            # measured round trip -- read at every step, not once: a close
            # begun at the first answer knows only the init's round trip.
            patience = d.ep.dead_after if self.close_timeout is None else self.close_timeout
            before = len(d.outbox)
            try:
                async with asyncio.timeout(patience):
                    while len(d.outbox) == before and d.broken is None:
                        await d.changed()
            except TimeoutError:
                self._abort_now(f"close made no progress for {patience:.1f} s")
                return


def _abort_text(exc: BaseException) -> str:
    """What the E packet tells the peer: the kind of ending, never the exception's text."""
    if isinstance(exc, KeyboardInterrupt | asyncio.CancelledError | TimeoutError):
        return "connection interrupted"
    return f"application error ({type(exc).__name__})"


class AsyncioSerialListener:
    """Accepts one connection at a time on a port; resets and listens after each."""

    def __init__(self, driver: AsyncioDriver, *, close_timeout: float | None) -> None:
        self._d = driver
        self._close_timeout = close_timeout
        self._session: AsyncioSerialSocket | None = None
        self._closed = False

    @property
    def endpoint(self) -> Endpoint:
        """The sans-I/O endpoint underneath (for inspection)."""
        return self._d.ep

    async def accept(self) -> AsyncioSerialSocket:
        """Wait for the next connection.

        While the current session's connection is live, this waits for it to
        end.  When a connection has ended, the endpoint resets and listens
        again; a session from it that was not closed raises ``RuntimeError``
        from then on.

        Raises:
            RuntimeError: the listener was closed.
            ConnectionError: the port itself failed (see ``__cause__``).
        """
        await asyncio.sleep(0)
        d = self._d
        while True:
            if self._closed:
                raise RuntimeError("listener closed")
            if isinstance(d.broken, LineFailed):
                raise ConnectionError(str(d.broken)) from d.broken
            state = d.ep.state
            session = self._session
            current = session is not None and session._generation == d.generation
            if state is State.ESTABLISHED and not current:
                self._session = AsyncioSerialSocket(d, close_timeout=self._close_timeout)
                return self._session
            if state in TERMINAL:
                if session is not None and current:
                    # Record how it ended before the endpoint forgets it.
                    session._final = ending(d.ep, d.outcome.describe(d.ep, stopped=d.stopped))
                d.ep.reset()
                d.ep.listen()
                d.generation += 1
                d.outcome.clear()
                d.outbox.clear()
                d.eof_requested = False
                d.notify()
                continue
            await d.changed()

    async def aclose(self) -> None:
        """Stop listening, end any session (aborting a live one), and close the port."""
        if self._closed:
            return
        self._closed = True
        d = self._d
        state = d.ep.state
        if state not in TERMINAL and state not in (State.IDLE, State.LINGER):
            d.ep.abort("listener closed", d.now())
            d.after_input()
            await d.flush()
        d.owns_port = True
        await d.stop()

    async def __aenter__(self) -> AsyncioSerialListener:
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.aclose()


def _close_timeout(config: EndpointConfig) -> float | None:
    """How long a close may go without progress: the configured dead-link
    interval, else None -- the endpoint's own, measured when the close starts
    (as :class:`serialsocket.SerialSocket` does)."""
    return config.dead_after


async def _port(port: PortLike, baud: int) -> tuple[AsyncPort, bool]:
    """The port, and whether we opened it (then it is ours to close on failure)."""
    if isinstance(port, str):
        return await open_port(port, baud), True
    return port, False


def _connect_failure(d: AsyncioDriver) -> Exception:
    """Why a connection request failed: what :func:`connect` raises, or
    chains to the ConnectionError it raises."""
    if isinstance(d.broken, LineFailed):
        return d.broken
    if d.stopped and d.broken is None and d.ep.state not in TERMINAL:
        return LineFailed("the serial socket stopped before it was connected")
    return _connect_error(d)


def _connect_error(d: AsyncioDriver) -> Exception:
    if isinstance(d.broken, PeerAborted):
        return ConnectionRefusedError(f"connection refused: {d.broken.reason}")
    return TimeoutError(
        f"no answer to connect within {d.ep.config.derived_connect_timeout():.1f} s: "
        "is the other side listening, and are the line settings right?"
    )


async def connect(
    port: PortLike,
    config: EndpointConfig | None = None,
    *,
    baud: int = 9600,
    early_data: bytes | bytearray | memoryview = b"",
    defer: bool = False,
) -> AsyncioSerialSocket:
    """Connect over ``port`` and return the socket (the port now belongs to it).

    ``port``: an :class:`AsyncioSerialPort` (or any :class:`AsyncPort`), or a
    device path / pyserial URL opened at ``baud``.

    ``early_data``: bytes to send first, queued before the connection
    request goes out: the first of them (at most ``config.early_data``, and
    the init's own bound: serialsocket/PROTOCOL.md section 13) ride in it and
    reach a telelink listener one one-way delay after this call instead of
    after the handshake's round trip; the rest, or all of them if the
    listener does not take early data, follow as ordinary data.  Delivered
    exactly once and before anything sent later.

    ``defer=True`` connects on the first write instead, as the trio
    ``serialsocket.connect`` does (its docstring has the whole contract): the
    socket is returned at once, nothing sent; the first non-empty ``write``
    sends the connection request with the first bytes inside; ``read``
    waits for the connection (one that began before any write sends the
    request itself a moment, 50 ms, later); a failed connection raises
    ``ConnectionError`` whose ``__cause__`` is what this function raises
    without ``defer``, from the next call or the one waiting; closing before
    the request sends nothing; every wait is cancellable and leaves the
    socket usable.

    Raises:
        ConnectionRefusedError: the peer refused, with its reason.
        TimeoutError: no answer within the connect timeout.
        ConnectionError: the port failed while connecting.
        OSError: a path or URL could not be opened.
        ValueError: ``early_data`` is larger than the send buffer, or given
            with ``defer`` (write the bytes instead).
    """
    (config or EndpointConfig()).check_early_data(early_data)
    if defer and early_data:
        raise ValueError("early_data with defer=True: write the bytes instead")
    line, _ = await _port(port, baud)
    cfg = (config or EndpointConfig()).for_line(line)  # 8N1 port: 8-bit profile
    d = AsyncioDriver(line, Endpoint(cfg), owns_port=True)
    try:
        d.start()
        if defer:
            return AsyncioSerialSocket(d, close_timeout=_close_timeout(cfg), deferred=True)
        d.ep.send(early_data, d.now())
        d.ep.connect(d.now())
        d.notify()
        while True:
            state = d.ep.state
            if state is State.ESTABLISHED:
                return AsyncioSerialSocket(d, close_timeout=_close_timeout(cfg))
            if state in TERMINAL:
                raise _connect_error(d)
            if d.broken is not None:
                raise ConnectionError(str(d.broken)) from d.broken
            await d.changed()
    except BaseException:
        if d.ep.state in LIVE:
            d.ep.abort("connect cancelled", d.now())
            d.after_input()
        await asyncio.shield(_teardown(d))
        raise


async def _teardown(d: AsyncioDriver) -> None:
    await d.flush()
    await d.stop()


async def accept(
    port: PortLike, config: EndpointConfig | None = None, *, baud: int = 9600
) -> AsyncioSerialSocket:
    """Wait for one connection on ``port`` and return it (the port now belongs to it).

    For a server that accepts connection after connection on the same port,
    use :func:`listen` or :func:`serve` instead.

    Raises:
        ConnectionError: the port failed while listening.
    """
    line, _ = await _port(port, baud)
    cfg = (config or EndpointConfig()).for_line(line)  # 8N1 port: 8-bit profile
    d = AsyncioDriver(line, Endpoint(cfg), owns_port=True)
    try:
        d.start()
        d.ep.listen()
        while d.ep.state is not State.ESTABLISHED:
            if d.broken is not None:
                raise ConnectionError(str(d.broken)) from d.broken
            await d.changed()
        return AsyncioSerialSocket(d, close_timeout=_close_timeout(cfg))
    except BaseException:
        await asyncio.shield(d.stop())
        raise


@asynccontextmanager
async def open_serial_socket(
    port: PortLike, config: EndpointConfig | None = None, *, baud: int = 9600, defer: bool = False
) -> AsyncIterator[AsyncioSerialSocket]:
    """``async with open_serial_socket(port) as sock:`` -- connect, use, close
    (``defer`` as for :func:`connect`).

    Closed gracefully when the block ends normally, aborted (with a bounded
    wait for the E packet) when it ends with an exception or a cancellation.
    """
    sock = await connect(port, config, baud=baud, defer=defer)
    async with sock:
        yield sock


@asynccontextmanager
async def listen(
    port: PortLike, config: EndpointConfig | None = None, *, baud: int = 9600
) -> AsyncIterator[AsyncioSerialListener]:
    """``async with listen(port) as listener: sock = await listener.accept()``.

    The listener's port is closed when the block ends.
    """
    line, _ = await _port(port, baud)
    cfg = (config or EndpointConfig()).for_line(line)  # 8N1 port: 8-bit profile
    d = AsyncioDriver(line, Endpoint(cfg), owns_port=False)
    d.start()
    d.ep.listen()
    listener = AsyncioSerialListener(d, close_timeout=_close_timeout(cfg))
    try:
        yield listener
    finally:
        await asyncio.shield(listener.aclose())


async def serve(
    port: PortLike,
    handler: Callable[[AsyncioSerialSocket], Awaitable[object]],
    config: EndpointConfig | None = None,
    *,
    baud: int = 9600,
    started: Callable[[AsyncioSerialListener], object] | None = None,
) -> None:
    """Serve connections on ``port`` one after another, forever (cancel to stop).

    Each connection is handed to ``handler`` and closed when it returns; then
    the endpoint resets and listens for the next.  A ``ConnectionError`` from
    the handler ends that connection only.  ``started`` is called with the
    listener once it listens.
    """
    async with listen(port, config, baud=baud) as listener:
        if started is not None:
            started(listener)
        while True:
            sock = await listener.accept()
            async with contextlib.AsyncExitStack() as stack:
                stack.push_async_callback(sock.aclose)
                try:
                    await handler(sock)
                except (ConnectionError, LocalProtocolError) as exc:
                    log.info("connection ended: %s", exc)


async def open_connection(
    port: PortLike, config: EndpointConfig | None = None, *, baud: int = 9600, defer: bool = False
) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    """Connect and return an ``asyncio`` (reader, writer) pair over the serial socket.

    For APIs written against asyncio's streams, such as the ``Opener`` of
    :class:`tcpstream.asyncio.AsyncioArmClient`.  ``writer.close()`` closes
    the serial socket gracefully, ``writer.write_eof()`` half-closes and
    ``writer.transport.abort()`` aborts; ``writer.get_extra_info("socket")``
    is the :class:`AsyncioSerialSocket` (its statistics, its close_error).
    ``defer=True`` (see :func:`connect`) lets the first bytes written -- a
    tcpstream HELLO -- ride in the connection request.
    """
    sock = await connect(port, config, baud=baud, defer=defer)
    return streams_over(sock)
