"""A blocking serial socket for controller code that is not async.

:class:`BlockingSerialSocket` runs one trio event loop in a background thread
per socket and forwards each call to it with ``trio.from_thread.run``.  The
calling thread blocks until the call finishes, fails or times out; the serial
socket's tasks (reader, writer, timers: ACKs, retransmissions, keepalives)
keep running in the background thread between calls, so the link stays alive
while the controller computes.

::

    with BlockingSerialSocket.connect("/dev/ttyUSB0", baud=2400, dial="5551234") as sock:
        sock.sendall(b"MOVE 0.3 0.1 0.5\\n")
        reply = sock.recv(4096, timeout=10.0)

Errors are the serial socket's: ``trio.BrokenResourceError`` (``__cause__``
says why: dead link, peer abort, failed line), ``trio.ClosedResourceError``
after ``close``, the typed :class:`~serialsocket.DialError` family, and
``TimeoutError`` when a call's timeout expires.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Awaitable, Callable
from types import TracebackType
from typing import TypeVar

import trio

from ._config import EndpointConfig
from ._hayes import answer as answer_call
from ._hayes import dial as dial_call
from ._port import open_port
from ._socket import SerialSocket, SocketStatistics
from ._socket import accept as accept_socket
from ._socket import connect as connect_socket

__all__ = ["BlockingSerialSocket"]

T = TypeVar("T")

_START_TIMEOUT = 10.0
"""Seconds to wait for the background event loop to start (a thread start)."""

_STOP_TIMEOUT = 10.0
"""Seconds to wait for the background thread to end after close; its last
step (closing the port) is bounded by the port's own short timeouts."""


class BlockingSerialSocket:
    """A connected serial socket with a blocking, socket-like interface.

    Get one from :meth:`connect` (controller side) or :meth:`accept` (arm
    side).  One thread at a time may send and one may receive (as with the
    async socket); ``close`` may be called from any thread.

    Attributes:
        timeout: default timeout in seconds for ``sendall``/``recv`` (None:
            block until done).  A call's own ``timeout`` argument wins.
    """

    def __init__(self, *, timeout: float | None = None) -> None:
        """Start the background event loop (use :meth:`connect`/:meth:`accept`)."""
        self.timeout = timeout
        self._sock: SerialSocket | None = None
        self._closed = False
        self._started = threading.Event()
        self._token: trio.lowlevel.TrioToken | None = None
        self._nursery: trio.Nursery | None = None
        self._stop: trio.Event | None = None
        self._thread = threading.Thread(
            target=trio.run, args=(self._main,), name="serialsocket-blocking", daemon=True
        )
        self._thread.start()
        if not self._started.wait(_START_TIMEOUT):
            raise RuntimeError("the serial socket's event loop thread did not start")

    async def _main(self) -> None:
        self._stop = trio.Event()
        async with trio.open_nursery() as nursery:
            self._nursery = nursery
            self._token = trio.lowlevel.current_trio_token()
            self._started.set()
            await self._stop.wait()
            nursery.cancel_scope.cancel()

    # -- construction -------------------------------------------------------------

    @classmethod
    def connect(
        cls,
        port: str | trio.abc.Stream,
        config: EndpointConfig | None = None,
        *,
        baud: int = 9600,
        dial: str | None = None,
        timeout: float | None = None,
    ) -> BlockingSerialSocket:
        """Open ``port`` (a path, URL or ready stream), optionally dial, and connect.

        Args:
            port: device path, pyserial URL, or a trio stream (e.g. one side
                of :func:`~serialsocket.open_pty_pair`).
            config: endpoint configuration (tell it the line's delay and rate).
            baud: line rate when ``port`` is a path or URL.
            dial: a phone number: dial it through a Hayes modem first.
            timeout: the default timeout of later calls; connecting itself is
                bounded by the configuration's connect timeout (and the dial
                timeout).

        Raises:
            OSError: the port could not be opened.
            DialError: dialing failed (busy, no answer, ...).
            ConnectionRefusedError, TimeoutError: the peer refused or did not answer.
        """
        self = cls(timeout=timeout)

        async def start(nursery: trio.Nursery) -> SerialSocket:
            stream = await _open(port, baud)
            try:
                if dial is not None:
                    await dial_call(stream, dial)
            except BaseException:
                await trio.aclose_forcefully(stream)
                raise
            return await connect_socket(stream, config, nursery=nursery)

        self._start(start)
        return self

    @classmethod
    def accept(
        cls,
        port: str | trio.abc.Stream,
        config: EndpointConfig | None = None,
        *,
        baud: int = 9600,
        answer: bool = False,
        timeout: float | None = None,
    ) -> BlockingSerialSocket:
        """Open ``port``, optionally answer a modem call, and wait for one connection.

        Blocks until a peer connects (interrupt it by closing the port from
        elsewhere, or use ``timeout``, which here also bounds the wait).

        Raises:
            OSError: the port could not be opened.
            TimeoutError: nobody connected within ``timeout``.
            DialError: answering the call failed.
        """
        self = cls(timeout=timeout)

        async def start(nursery: trio.Nursery) -> SerialSocket:
            stream = await _open(port, baud)
            try:
                if answer:
                    await answer_call(stream)
            except BaseException:
                await trio.aclose_forcefully(stream)
                raise
            return await accept_socket(stream, config, nursery=nursery)

        self._start(start, timeout)
        return self

    def _start(
        self, start: Callable[[trio.Nursery], Awaitable[SerialSocket]], timeout: float | None = None
    ) -> None:
        async def run_start() -> SerialSocket:
            assert self._nursery is not None
            return await start(self._nursery)

        try:
            self._sock = self._call(run_start, timeout, "connecting")
        except BaseException:
            self._shutdown_loop()
            raise

    # -- calls into the loop ------------------------------------------------------

    def _call(self, fn: Callable[[], Awaitable[T]], timeout: float | None, what: str) -> T:
        async def bounded() -> T:
            if timeout is None:
                return await fn()
            try:
                with trio.fail_after(timeout):
                    return await fn()
            except trio.TooSlowError:
                raise TimeoutError(f"{what} timed out after {timeout} s") from None

        if self._token is None:
            raise RuntimeError("event loop not running")
        try:
            return trio.from_thread.run(bounded, trio_token=self._token)
        except trio.RunFinishedError:
            raise trio.ClosedResourceError("this serial socket was closed") from None

    def _socket(self) -> SerialSocket:
        if self._closed:
            raise trio.ClosedResourceError("this serial socket was closed")
        if self._sock is None:
            raise trio.ClosedResourceError(
                "not connected: make the socket with BlockingSerialSocket.connect() or .accept()"
            )
        return self._sock

    def _timeout(self, timeout: float | None) -> float | None:
        return self.timeout if timeout is None else timeout

    # -- socket API -----------------------------------------------------------------

    def sendall(self, data: bytes | bytearray | memoryview, timeout: float | None = None) -> None:
        """Queue all of ``data`` for reliable delivery (blocks while the send buffer is full).

        Raises:
            TimeoutError: not all of it was queued in time.  A prefix may have
                been queued and will be delivered; the stream stays usable,
                but how much was taken is unknown (trio's contract for a
                cancelled ``send_all``).
            trio.BrokenResourceError: the connection failed (see ``__cause__``).
            trio.ClosedResourceError: the socket was closed or ``shutdown`` called.
        """
        sock = self._socket()
        payload = bytes(data)  # the caller may reuse its buffer once we return

        async def send() -> None:
            await sock.send_all(payload)

        self._call(send, self._timeout(timeout), "sendall")

    def recv(self, bufsize: int, timeout: float | None = None) -> bytes:
        """Up to ``bufsize`` bytes, in order; ``b""`` once the peer sent EOF.

        Raises:
            TimeoutError: nothing arrived in time; nothing was lost, call again.
            trio.BrokenResourceError: the connection failed (see ``__cause__``).
            trio.ClosedResourceError: the socket was closed.
        """
        sock = self._socket()

        async def receive() -> bytes:
            return await sock.receive_some(bufsize)

        return self._call(receive, self._timeout(timeout), "recv")

    def shutdown(self) -> None:
        """Half-close: the peer reads EOF after everything sent so far; we can still recv."""
        sock = self._socket()
        self._call(sock.send_eof, self._timeout(None), "shutdown")

    def statistics(self) -> SocketStatistics:
        """The ARQ record plus the port counters."""
        sock = self._socket()

        async def stats() -> SocketStatistics:
            await trio.lowlevel.checkpoint()
            return sock.statistics()

        return self._call(stats, None, "statistics")

    def close(self) -> None:
        """Close gracefully (bounded by the socket's close timeout), then stop the loop.

        Idempotent.  If the peer does not finish closing in time, the
        connection is aborted.
        """
        if self._closed:
            return
        self._closed = True
        try:
            if self._sock is not None:
                self._call(self._sock.aclose, None, "close")
        finally:
            self._shutdown_loop()

    def _shutdown_loop(self) -> None:
        stop = self._stop
        if stop is not None and self._token is not None:
            with contextlib.suppress(trio.RunFinishedError):
                trio.from_thread.run_sync(stop.set, trio_token=self._token)
        self._thread.join(_STOP_TIMEOUT)

    def __enter__(self) -> BlockingSerialSocket:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


async def _open(port: str | trio.abc.Stream, baud: int) -> trio.abc.Stream:
    if isinstance(port, str):
        return await open_port(port, baud)
    return port
