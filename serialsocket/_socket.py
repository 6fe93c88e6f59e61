"""SerialSocket: a trio ``HalfCloseableStream`` running the ARQ endpoint over a port.

Theory of operation
-------------------
A *driver* (:mod:`serialsocket._driver`) owns one port (any
``trio.abc.Stream``: a pty or serial device wrapped by ``open_port``, an
in-memory impaired link, a TCP stream) and one sans-I/O
:class:`~serialsocket.Endpoint`, and runs the reader, writer and timer tasks.

A :class:`SerialSocket` is a *session* on a driver.  A client's session owns
the port and closes it on ``aclose``.  A listener's sessions share the port:
when one closes, the endpoint resets and listens again (seed 003: "the
manipulator will reset and listen for further connection requests").

Failures reach the application as ``trio.BrokenResourceError`` whose
``__cause__`` says what happened: :class:`PeerAborted` (the peer sent an E
packet, with its reason), :class:`LinkDeadError` (silence; with the bytes
acknowledged, in flight and never sent) or :class:`LineFailed` (the port
itself failed or reached EOF).

A *deferred* socket (``connect(port, defer=True)``) is a client session whose
connection request has not gone out yet: the first ``send_all`` queues its
bytes and sends the request with the first of them inside (early data,
PROTOCOL.md section 13), as TCP Fast Open's connect-on-first-send does.
Until the connection is established the session raises the connect's own
failure (chained to ``BrokenResourceError``) from whichever call meets it.
"""

from __future__ import annotations

import logging
import operator
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from contextlib import asynccontextmanager, contextmanager

import trio

from ._config import EndpointConfig
from ._driver import _READ_SIZE, LineFailed, LinkBroken, LinkDeadError, PeerAborted, _Driver
from ._endpoint import Endpoint
from ._errors import LocalProtocolError
from ._outcome import SocketStatistics, ending
from ._port import port_statistics
from ._state import TERMINAL, State

__all__ = [
    "LineFailed",
    "LinkBroken",
    "LinkDeadError",
    "PeerAborted",
    "SerialListener",
    "SerialSocket",
    "SocketStatistics",
    "accept",
    "connect",
    "listen",
    "open_serial_socket",
    "serve",
]

log = logging.getLogger(__name__)

_REQUEST_GRACE = 0.05
"""Seconds a deferred socket's first receive waits for a first write before it
sends the connection request itself (empty).  Long enough for a sender started
beside the receiver (tcpstream's reader and writer start together) to be
scheduled on a loaded machine; short against any link where deferring pays
(a round trip of a tenth of a second or more)."""


class SerialSocket(trio.abc.HalfCloseableStream):
    """A connected serial socket: reliable, sequenced, full duplex.

    Obtain one from :func:`connect`, :func:`open_serial_socket` or
    :meth:`SerialListener.accept`.  Semantics follow ``trio.abc``:
    ``receive_some`` returns ``b""`` only at the peer's EOF; after
    ``send_eof`` the peer sees EOF once every byte before it arrived;
    ``aclose`` closes gracefully -- for as long as the close makes progress,
    giving up after ``close_timeout`` without any -- and, if cancelled, aborts.
    A socket from ``connect(..., defer=True)`` connects on its first write
    (see :func:`connect`).
    """

    def __init__(
        self, driver: _Driver, *, close_timeout: float | None, deferred: bool = False
    ) -> None:
        self._d = driver
        self._deferred = deferred
        """Made by ``connect(defer=True)``: until established, calls wait for
        the connection and raise its failure as :func:`connect` would."""
        self._unrequested = deferred
        """Deferred, and the connection request has not gone out yet."""
        self._request_by: float | None = None
        """When a waiting receive sends the deferred request itself (fixed by
        the first one to wait, so a retried receive does not postpone it)."""
        self._generation = driver.generation
        self._closed = False
        self._eof_sent = False
        self._sending = False
        self._receiving = False
        self.close_timeout = close_timeout
        """Seconds a close may go without progress before it is given up; None
        (unless ``EndpointConfig.dead_after`` is set): the endpoint's
        dead-link interval when the close starts, which follows the measured
        round trip (the hints' value gave a close 2 s without hints, and a
        1.3 s line aborted every close)."""
        self.close_error: str | None = None
        """After :meth:`aclose`: None if the connection ended delivered (every
        byte we were given acknowledged by the peer and the peer's EOF
        received), else what happened and how many bytes were acknowledged,
        in flight and never sent."""
        self._final: str | None = None  # how the connection ended, if it ended before aclose

    @property
    def endpoint(self) -> Endpoint:
        """The sans-I/O endpoint underneath (for inspection)."""
        return self._d.ep

    def statistics(self) -> SocketStatistics:
        """The ARQ statistics and the port counters."""
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

    @contextmanager
    def _send_guard(self) -> Iterator[None]:
        """One sending task at a time (trio's BusyResourceError contract)."""
        if self._sending:
            raise trio.BusyResourceError("another task is already sending on this socket")
        self._sending = True
        try:
            yield
        finally:
            self._sending = False

    def _check_open(self) -> None:
        if self._closed or self._generation != self._d.generation:
            raise trio.ClosedResourceError("this serial socket was closed")

    def _connecting(self) -> bool:
        """A deferred connection not yet established (requested or not)."""
        return self._deferred and self._d.ep.parameters is None

    def _request(self) -> None:
        """Send the deferred connection request now, carrying the head of the
        send queue as early data; nothing once it went."""
        if self._unrequested:
            self._unrequested = False
            d = self._d
            d.ep.connect(d.now())
            d.notify()

    def _raise_if_connect_failed(self) -> None:
        """A deferred connection that failed before it was established: raise
        what :func:`connect` raises, chained to BrokenResourceError."""
        if not self._connecting():
            return
        d = self._d
        if d.ep.state in TERMINAL or d.broken is not None or d.stopped:
            cause = _connect_failure(d)
            raise trio.BrokenResourceError(str(cause)) from cause

    async def _wait(self) -> None:
        """Wait for the next change.  An unrequested deferred socket waits at
        most until :data:`_REQUEST_GRACE` after the first such wait, then
        sends its connection request (without early data)."""
        if not self._unrequested:
            await self._d.changed()
            return
        if self._request_by is None:
            self._request_by = trio.current_time() + _REQUEST_GRACE
        with trio.move_on_at(self._request_by):
            await self._d.changed()
            return
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
            raise trio.BrokenResourceError(str(d.broken)) from d.broken
        if d.ep.state in (State.FAILED, State.DEAD):
            cause = LineFailed(f"the connection ended ({d.ep.state.value})")
            raise trio.BrokenResourceError(str(cause)) from cause

    # -- stream API ---------------------------------------------------------------

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        """Queue all of ``data`` for reliable delivery; returns once it is queued.

        On a deferred socket the first (non-empty) call sends the connection
        request, carrying the first of ``data`` as early data, and returns
        without waiting for the answer.

        Raises:
            trio.BusyResourceError: another task is already sending.
            trio.ClosedResourceError: this socket was closed or ``send_eof``
                was called.
            trio.BrokenResourceError: the connection failed (see the cause;
                for a deferred connection that was never established, what
                :func:`connect` raises).
        """
        with self._send_guard():
            self._check_open()
            if self._eof_sent:
                raise trio.ClosedResourceError("send_eof() was already called")
            await trio.lowlevel.checkpoint()
            view = memoryview(data).cast("B")
            while True:
                self._check_open()
                self._raise_if_broken()
                if view:
                    try:
                        taken = self._d.ep.send(view, self._d.now())
                    except LocalProtocolError as exc:
                        raise trio.BrokenResourceError(str(exc)) from exc
                    self._request()  # deferred: the request carries the head of them
                    if taken:
                        view = view[taken:]
                        self._d.notify()
                if not view:
                    return
                await self._d.changed()

    async def wait_send_all_might_not_block(self) -> None:
        """Wait until the send buffer has room (or the socket failed)."""
        with self._send_guard():
            await trio.lowlevel.checkpoint()
            while True:
                self._check_open()
                ep = self._d.ep
                if self._d.broken is not None or ep.state in TERMINAL or ep.send_buffer_free > 0:
                    return
                await self._d.changed()

    async def send_eof(self) -> None:
        """Half-close: the peer reads EOF after every byte sent so far.

        On a deferred socket not yet connecting, this sends the connection
        request (the EOF follows once connected)."""
        with self._send_guard():
            self._check_open()
            await trio.lowlevel.checkpoint()
            if self._eof_sent:
                return
            self._raise_if_broken()
            self._eof_sent = True
            self._d.ep.send_eof(self._d.now())
            self._request()
            self._d.notify()

    async def receive_some(self, max_bytes: int | None = None) -> bytes:
        """Bytes from the peer, in order, each exactly once; ``b""`` only at EOF.

        On a deferred socket this waits for the connection as well (see
        :func:`connect`); one that has not sent its request yet sends it a
        moment (50 ms) after the first receive began, if no write came first.

        Raises:
            trio.BusyResourceError: another task is already receiving.
            trio.ClosedResourceError: this socket was closed (also wakes a
                blocked receive).
            trio.BrokenResourceError: the connection failed (see the cause;
                for a deferred connection that was never established, what
                :func:`connect` raises); bytes delivered before the failure
                are returned first.
        """
        if max_bytes is not None:
            max_bytes = operator.index(max_bytes)  # TypeError for 1.5, as trio requires
            if max_bytes < 1:
                raise ValueError("max_bytes must be >= 1")
        if self._receiving:
            raise trio.BusyResourceError("another task is already receiving on this socket")
        self._receiving = True
        try:
            self._check_open()
            await trio.lowlevel.checkpoint()
            while True:
                self._check_open()
                ep = self._d.ep
                queued = ep.control_pending
                data = ep.read(max_bytes or _READ_SIZE, self._d.now())
                if data:
                    if ep.control_pending != queued:
                        self._d.notify()  # the read queued a window update: wake the writer
                    return data
                if self._d.ep.at_eof:
                    return b""
                self._raise_if_broken()
                await self._wait()
        finally:
            self._receiving = False

    # -- the expedited lane (PROTOCOL.md section 11) ------------------------------

    @property
    def expedited(self) -> bool:
        """Both ends agreed on the expedited lane: :meth:`send_expedited` and
        :meth:`receive_expedited` work (False with a classic or older peer).

        A deferred socket not yet connected says whether it asks for the lane
        (``EndpointConfig.expedited``): a stream user such as tcpstream
        decides at its start whether to use the lane, before the answer can
        be known, and :meth:`send_expedited` waits for the connection.  So a
        True here may still end without a lane (a classic peer); tcpstream
        sends on the lane only when its own peer says it reads it, and that
        peer's socket knows the agreed lanes."""
        if self._connecting() and self._d.ep.state not in TERMINAL:
            return self._d.ep.config.expedited
        return self._d.ep.expedited

    async def send_expedited(self, message: bytes | bytearray | memoryview) -> None:
        """Send one small urgent message ahead of every byte queued on the stream.

        Returns once it is queued (it is on the line at once, behind only what
        the UART holds); it is retransmitted until acknowledged and reaches
        the peer's :meth:`receive_expedited` whole and exactly once.  It is
        not ordered with the stream: it overtakes data sent before it.
        Waits (cancellably) while the lane already holds its limit of
        unacknowledged messages, and on a deferred socket for the connection
        (sending its request if it has not gone).

        Raises:
            trio.ClosedResourceError: this socket was closed.
            trio.BrokenResourceError: the connection failed, or has no lane
                (check :attr:`expedited`).
            ValueError: ``message`` is empty or too long for the lane (1024
                bytes at most, and 31 packets at the negotiated length).
        """
        await trio.lowlevel.checkpoint()
        self._check_open()
        await self._established()
        while True:
            self._check_open()
            self._raise_if_broken()
            try:
                queued = self._d.ep.offer_expedited(message, self._d.now())
            except LocalProtocolError as exc:  # no lane, or the connection ended
                raise trio.BrokenResourceError(str(exc)) from exc
            if queued:
                self._d.notify()
                return
            await self._d.changed()  # the lane is full: wait for an acknowledgement

    async def receive_expedited(self) -> bytes:
        """The peer's next expedited message, whole; waits (cancellably) for one.

        Raises:
            trio.ClosedResourceError: this socket was closed.
            trio.BrokenResourceError: the connection ended (messages that had
                arrived are returned first).
        """
        await trio.lowlevel.checkpoint()
        while True:
            self._check_open()
            message = self._d.ep.read_expedited()
            if message is not None:
                return message
            self._raise_if_broken()
            if (over := self._d.ep.expedited_over) is not None:
                raise trio.BrokenResourceError(over)
            await self._wait()

    # -- the latest-value lane (PROTOCOL.md section 12) ---------------------------

    @property
    def latest(self) -> bool:
        """Both ends agreed on the latest-value lane: :meth:`send_latest` and
        :meth:`receive_latest` work (False with a classic or older peer).

        False on a deferred socket until it is connected: :meth:`send_latest`
        never waits, so it cannot hold a value for a connection not yet made."""
        return self._d.ep.latest

    def send_latest(self, value: bytes | bytearray | memoryview) -> None:
        """Offer ``value`` as the newest of a series; never waits.

        It replaces a value not yet on the line, goes on the line when the
        stream's own packets leave room, and a newer value replaces it on
        the line instead of its resend: a lost value never holds up a newer
        one.  The peer's :meth:`receive_latest` gets values in order, each at
        most once, some skipped; the newest is resent until acknowledged.

        Raises:
            trio.ClosedResourceError: this socket was closed.
            trio.BrokenResourceError: the connection failed, is closing, or has
                no lane (check :attr:`latest`).
            ValueError: ``value`` is empty or does not fit one packet.
        """
        self._check_open()
        self._raise_if_broken()
        try:
            self._d.ep.send_latest(value, self._d.now())
        except LocalProtocolError as exc:  # no lane, or the connection ended
            raise trio.BrokenResourceError(str(exc)) from exc
        self._d.notify()

    @property
    def latest_waiting(self) -> bool:
        """A value given to :meth:`send_latest` is not yet on the line."""
        return self._d.ep.latest_waiting

    async def receive_latest(self) -> bytes:
        """The newest value from the peer not yet received; waits (cancellably)
        for one.  Values that arrived meanwhile and were overtaken are skipped.

        Raises:
            trio.ClosedResourceError: this socket was closed.
            trio.BrokenResourceError: the connection ended (a value that had
                arrived is returned first).
        """
        await trio.lowlevel.checkpoint()
        while True:
            self._check_open()
            value = self._d.ep.read_latest()
            if value is not None:
                return value
            self._raise_if_broken()
            if (over := self._d.ep.latest_over) is not None:
                raise trio.BrokenResourceError(over)
            await self._wait()

    async def aclose(self) -> None:
        """Close gracefully: all our data acknowledged, both EOFs exchanged.

        Waits as long as the close makes progress -- our data being
        acknowledged, the peer's EOF arriving -- however long a backlog on a
        slow line takes to drain.  The endpoint gives the close up (and tells
        the peer, with an E packet) only after ``close_timeout`` seconds in
        which nothing moved, or when the link is judged dead by silence:
        there is no fixed deadline counted from the call.

        Afterwards :attr:`close_error` is None exactly when every byte we were
        given was acknowledged by the peer and the peer's EOF arrived; else it
        says what happened and how many bytes were acknowledged, in flight
        and never sent.  ``aclose`` itself does not raise for it, as trio's
        streams do not; a program whose exit status means "delivered" checks
        it, as the netcat does.  If cancelled, the connection is aborted (and
        ``Cancelled`` propagates).  Idempotent.

        A deferred socket whose request has not gone out sends nothing: the
        port closes at once (:attr:`close_error` None: it was given nothing
        to deliver).  One whose request went out waits for the connection
        (bounded by the connect timeout) and then closes gracefully, so what
        was written is delivered as after :func:`connect`; if the connection
        fails, :attr:`close_error` says so.
        """
        if self._closed:
            await trio.lowlevel.checkpoint()
            return
        self._closed = True
        d = self._d
        if self._generation != d.generation:
            # The listener already reset the endpoint for a newer connection:
            # it is not ours to close.  How ours ended was recorded then.
            await trio.lowlevel.checkpoint()
            self.close_error = self._final
            return
        d.notify()  # wake our own blocked receive/send: they now raise Closed
        if self._unrequested:
            # Deferred and never requested: the peer knows nothing of us.
            try:
                await trio.lowlevel.checkpoint()
            finally:
                await d.stop()
            return
        try:
            await trio.lowlevel.checkpoint()
            # A deferred connection still being made ends (the endpoint's
            # connect deadline) or comes up; then it is closed like any other.
            while d.ep.state is State.CONNECTING and d.broken is None and not d.stopped:
                await d.changed()
            if d.ep.state is State.ESTABLISHED and d.broken is None:
                d.ep.close(d.now(), patience=self.close_timeout)
                d.notify()
                # Only the endpoint ends this wait: the close completes, the
                # peer aborts, the link is judged dead, or the close makes no
                # progress for close_timeout (its deadline re-arms on every
                # acknowledgement, inside the endpoint's timers).
                while d.ep.state is State.ESTABLISHED and d.broken is None and not d.stopped:
                    await d.changed()
        except trio.Cancelled:
            if d.ep.state not in TERMINAL:
                d.ep.abort("connection closed by the application", d.now())
                d.after_input()
            self.close_error = _ending(d, "the close was cancelled")
            raise
        finally:
            await d.flush()
            if d.owns_port:
                await d.stop()
            else:
                d.notify()
        failed = self._deferred and d.ep.parameters is None  # never connected
        self.close_error = _ending(
            d, f"connecting failed: {_connect_failure(d)}" if failed else None
        )


class SerialListener(trio.abc.Listener[SerialSocket]):
    """Accepts one connection at a time on a port; resets and listens after each."""

    def __init__(self, driver: _Driver, *, close_timeout: float | None) -> None:
        self._d = driver
        self._close_timeout = close_timeout
        self._session: SerialSocket | None = None
        self._closed = False

    @property
    def endpoint(self) -> Endpoint:
        """The sans-I/O endpoint underneath (for inspection)."""
        return self._d.ep

    async def accept(self) -> SerialSocket:
        """Wait for the next connection.

        While the current session's connection is live, this waits for it to
        end.  When a connection has ended (closed, aborted, dead), the
        endpoint resets and listens again; a session object from it that was
        not closed raises ClosedResourceError from then on.

        Raises:
            trio.ClosedResourceError: the listener was closed.
            trio.BrokenResourceError: the port itself failed.
        """
        await trio.lowlevel.checkpoint()
        d = self._d
        while True:
            if self._closed:
                raise trio.ClosedResourceError("listener closed")
            if isinstance(d.broken, LineFailed):
                raise trio.BrokenResourceError(str(d.broken)) from d.broken
            state = d.ep.state
            current = self._session is not None and self._session._generation == d.generation
            if state is State.ESTABLISHED and not current:
                self._session = SerialSocket(d, close_timeout=self._close_timeout)
                return self._session
            if state in TERMINAL:
                if self._session is not None and self._session._generation == d.generation:
                    # Record how it ended before the endpoint forgets it: a
                    # later aclose on that session reports it.
                    self._session._final = _ending(d)
                d.ep.reset()
                d.ep.listen()
                d.generation += 1
                d.broken = None
                d.ended_by_us = None
                d.notify()
                continue
            await d.changed()

    async def aclose(self) -> None:
        """Stop listening, end any session, and close the port."""
        if self._closed:
            await trio.lowlevel.checkpoint()
            return
        self._closed = True
        # A live session is aborted (close it first to close it gracefully);
        # one that completed its close (LINGER) is simply left: an E then
        # would tell a peer still waiting for our last ACK that it failed.
        state = self._d.ep.state
        if state not in TERMINAL and state not in (State.IDLE, State.LINGER):
            self._d.ep.abort("listener closed", self._d.now())
            await self._d.flush()
        self._d.owns_port = True
        await self._d.stop()


def _close_timeout(config: EndpointConfig) -> float | None:
    """How long a close may go without progress: the configured dead-link
    interval, else None -- the endpoint's own, measured when the close starts."""
    return config.dead_after


async def _start_driver(
    port: trio.abc.Stream, cfg: EndpointConfig, nursery: trio.Nursery | None
) -> _Driver:
    """A driver that owns ``port``, running in ``nursery`` or as a system task."""
    driver = _Driver(port, Endpoint(cfg), owns_port=True)
    if nursery is not None:
        await nursery.start(driver.run)
    else:
        trio.lowlevel.spawn_system_task(driver.run)
    return driver


async def connect(
    port: trio.abc.Stream,
    config: EndpointConfig | None = None,
    *,
    nursery: trio.Nursery | None = None,
    early_data: bytes | bytearray | memoryview = b"",
    defer: bool = False,
) -> SerialSocket:
    """Connect over ``port`` and return the socket (the port now belongs to it).

    The driver runs in ``nursery`` when given, else as a trio system task (it
    stops when the socket is closed).

    ``early_data``: bytes to send first, queued before the connection
    request goes out: the first of them (at most ``config.early_data``, and
    the init's own bound: serialsocket/PROTOCOL.md section 13) ride in it and
    reach a telelink listener one one-way delay after this call instead of
    after the handshake's round trip; the rest, or all of them if the
    listener does not take early data, follow as ordinary data.  Delivered
    exactly once and before anything sent later.

    ``defer=True`` connects on the first write instead (TCP Fast Open's
    connect-on-first-send), for a caller whose first bytes are not known
    until it has the socket -- a session layer such as tcpstream writing its
    HELLO.  The socket is returned at once, nothing sent; then:

    * the first non-empty ``send_all`` queues its bytes and sends the
      connection request with the first of them as early data (as
      ``early_data`` above), and returns once they are queued, as always;
      ``send_eof`` and ``send_expedited`` send the request too (the latter
      then waits for the connection: the lane needs it);
    * ``receive_some`` (and the lanes' receives) wait for the connection; one
      that began before any write sends the request itself, without early
      data, a moment (50 ms) later;
    * the connect timeout counts from the request.  If the connection fails,
      the next operation (or the one waiting) raises
      ``trio.BrokenResourceError`` whose ``__cause__`` is what this function
      raises without ``defer``: ``ConnectionRefusedError``,
      ``TimeoutError``, or the port's :class:`LineFailed`;
    * ``aclose`` before the request sends nothing and closes the port; after
      it, waits for the connection and closes gracefully;
    * every wait is cancellable, and a cancelled one leaves the socket as it
      was (a request sent stays sent; a cancelled ``aclose`` aborts);
    * :attr:`SerialSocket.expedited` says until then what this side asks for.

    Raises:
        ConnectionRefusedError: the peer refused, with its reason.
        TimeoutError: no answer within the connect timeout.
        trio.BrokenResourceError: the port failed while connecting.
        ValueError: ``early_data`` is larger than the send buffer, or given
            with ``defer`` (write the bytes instead).
    """
    cfg = (config or EndpointConfig()).for_line(port)  # 8N1 port: 8-bit profile
    cfg.check_early_data(early_data)
    if defer and early_data:
        raise ValueError("early_data with defer=True: send the bytes with send_all instead")
    driver = await _start_driver(port, cfg, nursery)
    if defer:
        return SerialSocket(driver, close_timeout=_close_timeout(cfg), deferred=True)
    driver.ep.send(early_data, driver.now())
    driver.ep.connect(driver.now())
    driver.notify()
    try:
        while True:
            state = driver.ep.state
            if state is State.ESTABLISHED:
                return SerialSocket(driver, close_timeout=_close_timeout(cfg))
            if state in TERMINAL:
                raise _connect_error(driver)
            if driver.broken is not None:
                raise trio.BrokenResourceError(str(driver.broken)) from driver.broken
            await driver.changed()
    except BaseException:
        await driver.flush()
        await driver.stop()
        raise


async def accept(
    port: trio.abc.Stream,
    config: EndpointConfig | None = None,
    *,
    nursery: trio.Nursery | None = None,
) -> SerialSocket:
    """Wait for one connection on ``port`` and return it (the port now belongs to it).

    For a server that accepts connection after connection on the same port,
    use :func:`listen` or :func:`serve` instead.

    Raises:
        trio.BrokenResourceError: the port failed while listening.
    """
    cfg = (config or EndpointConfig()).for_line(port)  # 8N1 port: 8-bit profile
    driver = await _start_driver(port, cfg, nursery)
    driver.ep.listen()
    try:
        while driver.ep.state is not State.ESTABLISHED:
            if driver.broken is not None:
                raise trio.BrokenResourceError(str(driver.broken)) from driver.broken
            await driver.changed()
        return SerialSocket(driver, close_timeout=_close_timeout(cfg))
    except BaseException:
        await driver.stop()
        raise


def _connect_failure(driver: _Driver) -> Exception:
    """Why a connection request failed: what :func:`connect` raises, or
    chains to the BrokenResourceError it raises."""
    if isinstance(driver.broken, LineFailed):
        return driver.broken
    if driver.stopped and driver.broken is None and driver.ep.state not in TERMINAL:
        return LineFailed("the serial socket stopped before it was connected")
    return _connect_error(driver)


def _connect_error(driver: _Driver) -> Exception:
    if isinstance(driver.broken, PeerAborted):
        return ConnectionRefusedError(f"connection refused: {driver.broken.reason}")
    return TimeoutError(
        f"no answer to connect within {driver.ep.config.derived_connect_timeout():.1f} s: "
        "is the other side listening, and are the line settings right?"
    )


@asynccontextmanager
async def open_serial_socket(
    port: trio.abc.Stream,
    config: EndpointConfig | None = None,
    *,
    early_data: bytes | bytearray | memoryview = b"",
    defer: bool = False,
) -> AsyncIterator[SerialSocket]:
    """``async with open_serial_socket(port) as sock:`` -- connect, use, close
    (``early_data`` and ``defer`` as for :func:`connect`)."""
    async with trio.open_nursery() as nursery:
        sock = await connect(port, config, nursery=nursery, early_data=early_data, defer=defer)
        try:
            yield sock
        finally:
            await sock.aclose()


@asynccontextmanager
async def listen(
    port: trio.abc.Stream, config: EndpointConfig | None = None
) -> AsyncIterator[SerialListener]:
    """``async with listen(port) as listener: sock = await listener.accept()``."""
    cfg = (config or EndpointConfig()).for_line(port)  # 8N1 port: 8-bit profile
    driver = _Driver(port, Endpoint(cfg), owns_port=False)
    async with trio.open_nursery() as nursery:
        await nursery.start(driver.run)
        driver.ep.listen()
        listener = SerialListener(driver, close_timeout=_close_timeout(cfg))
        try:
            yield listener
        finally:
            await listener.aclose()


async def serve(
    port: trio.abc.Stream,
    handler: Callable[[SerialSocket], Awaitable[object]],
    config: EndpointConfig | None = None,
    *,
    task_status: trio.TaskStatus[SerialListener] = trio.TASK_STATUS_IGNORED,
) -> None:
    """Serve connections on ``port`` one after another, forever (cancel to stop).

    Each connection is handed to ``handler`` and closed when it returns; then
    the endpoint resets and listens for the next.  An exception from the
    handler for one connection is logged and does not stop the server.
    """
    async with listen(port, config) as listener:
        task_status.started(listener)
        while True:
            sock = await listener.accept()
            try:
                await handler(sock)
            except (trio.BrokenResourceError, trio.ClosedResourceError, LinkBroken) as exc:
                log.info("connection ended: %s", exc)
            finally:
                await sock.aclose()


def _ending(d: _Driver, what: str | None = None) -> str | None:
    """None if the connection on ``d`` ended delivered, else what happened, with
    the counts (:func:`serialsocket._outcome.ending`)."""
    ep = d.ep
    if what is None:
        if d.broken is not None:
            what = str(d.broken)
        elif d.ended_by_us is not None:
            what = f"this side aborted the connection: {d.ended_by_us}"
        elif d.stopped:
            what = "the serial socket stopped before the close finished"
        else:
            what = f"the connection ended ({ep.state.value})"
    return ending(ep, what)
