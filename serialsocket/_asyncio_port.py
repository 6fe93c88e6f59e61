"""Layer 1 for asyncio: a serial device, a pty or a pyserial URL as an asyncio port.

The trio port (:mod:`serialsocket._port`) has an asyncio twin here, opened the
same way (:func:`serialsocket._pyserial.open_serial`: 8N1, raw, no flow
control unless asked, the pty DTR pitfall absorbed):

* a device or pty path has a file descriptor: a non-blocking duplicate is
  read and written with the event loop's ``add_reader`` / ``add_writer``, so
  no thread is involved;
* a pyserial URL (``loop://``, ``socket://``, ``spy://``) has no descriptor
  we may use: one reader thread hands chunks to the loop through a bounded
  queue, and writes run in the loop's default executor in bounded chunks.

Everything a port raises is an ``OSError``: the device's own (``EIO`` when
the other side of a pty closed), or ``EBADF`` once the port was closed (a
read or write waiting at that moment is woken with it).  No trio here.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import os
import queue
import threading
import tty
from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

from ._encoding import Encoding
from ._pyserial import (
    PTY_MASTER_CLOSE_GRACE,
    THREAD_READ_TIMEOUT,
    PortStatistics,
    check_line_settings,
    discard_unsent,
    holds_output,
    open_serial,
    plain_tcp_socket,
    port_encoding,
    read_blocks_for_one_byte,
    read_burst,
)

__all__ = ["AsyncPort", "AsyncioSerialPort", "open_port", "open_pty_pair", "port_statistics"]

READ_SIZE = 65536
"""Bytes asked of the device per read; a pty hands out at most ~4 KB anyway."""

_THREAD_WRITE_CHUNK = 4096
"""Bytes per executor write of a URL port: keeps each uncancellable wait short."""

_THREAD_QUEUE = 16
"""Chunks the reader thread of a URL port may hold before it stops reading
(back-pressure): 16 x 64 KB bounds the memory of a port whose reader is slow."""

_THREAD_BURST = 4096
"""Bytes the reader thread of a URL port gathers before it hands them to the
loop: a few packets, so a steady stream is delivered as it comes."""

_THREAD_JOIN = 1.0 + THREAD_READ_TIMEOUT
"""Seconds closing a URL port waits for its reader thread (it notices the stop
flag within one read timeout)."""


@runtime_checkable
class AsyncPort(Protocol):
    """What the asyncio serial socket needs of a line (any object with these three).

    ``read`` returns at least one byte, or ``b""`` when the line ended for
    good; failures are ``OSError``.
    """

    async def read(self, max_bytes: int) -> bytes: ...
    async def write(self, data: bytes) -> None: ...
    async def aclose(self) -> None: ...


class _Transport(Protocol):
    can_discard: bool

    def discard_output(self) -> None: ...
    async def read(self, max_bytes: int) -> bytes: ...
    async def write(self, data: bytes) -> None: ...
    async def aclose(self) -> None: ...


class AsyncioSerialPort:
    """An asyncio serial line with counters.  Use :func:`open_port` or :func:`open_pty_pair`.

    ``write`` returns once the bytes are in the device's output buffer.  One
    reader and one writer at a time (a second concurrent one is a
    ``RuntimeError``).

    Attributes:
        name: the path or URL this port was opened with.
        serial: the pyserial object (its settings), or None for a raw pty fd.
    """

    def __init__(
        self, transport: _Transport, name: str, serial_obj: Any = None, *, close_grace: float = 0.0
    ) -> None:
        self._t = transport
        self.name = name
        self.serial = serial_obj
        self._closed = False
        self._close_grace = close_grace
        self._reading = self._writing = False
        self._bytes_in = self._bytes_out = self._reads = self._writes = self._errors = 0

    @property
    def encoding(self) -> Encoding:
        """The prefix profile this line carries (see ``SerialPort.encoding``)."""
        return port_encoding(self.serial)

    def statistics(self) -> PortStatistics:
        """A snapshot of the counters."""
        return PortStatistics(
            name=self.name,
            bytes_in=self._bytes_in,
            bytes_out=self._bytes_out,
            reads=self._reads,
            writes=self._writes,
            errors=self._errors,
        )

    def _check_open(self) -> None:
        if self._closed:
            raise OSError(errno.EBADF, f"port {self.name} was closed")

    async def read(self, max_bytes: int = READ_SIZE) -> bytes:
        """Some bytes from the line (at least one), or ``b""`` at a URL transport's EOF.

        Raises:
            OSError: the device failed, or the port was closed.
            RuntimeError: another task is already reading.
        """
        if max_bytes < 1:
            raise ValueError("max_bytes must be >= 1")
        if self._reading:
            raise RuntimeError(f"another task is already reading from {self.name}")
        self._check_open()
        self._reading = True
        try:
            data = await self._t.read(max_bytes)
        except OSError:
            if not self._closed:
                self._errors += 1
            raise
        finally:
            self._reading = False
        if data:
            self._reads += 1
            self._bytes_in += len(data)
        return data

    async def write(self, data: bytes) -> None:
        """Write all of ``data``.

        Raises:
            OSError: the device failed, or the port was closed.
            RuntimeError: another task is already writing.
        """
        if self._writing:
            raise RuntimeError(f"another task is already writing to {self.name}")
        self._check_open()
        self._writing = True
        try:
            await self._t.write(data)
        except OSError:
            if not self._closed:
                self._errors += 1
            raise
        finally:
            self._writing = False
        self._writes += 1
        self._bytes_out += len(data)

    @property
    def can_discard_output(self) -> bool:
        """:meth:`discard_output` drops something: a serial device, not a
        pty or a URL (see ``SerialPort.can_discard_output``)."""
        return self._t.can_discard

    def discard_output(self) -> None:
        """Drop the bytes written and not yet sent (see
        ``SerialPort.discard_output``); call it between writes.

        Raises:
            OSError: the device failed, or the port was closed.
        """
        self._check_open()
        try:
            self._t.discard_output()
        except OSError:
            self._errors += 1
            raise

    async def aclose(self) -> None:
        """Close the port (idempotent; a waiting read or write gets ``EBADF``)."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._close_grace > 0:
                await asyncio.sleep(self._close_grace)  # see PTY_MASTER_CLOSE_GRACE
        finally:
            await self._t.aclose()


def port_statistics(port: object) -> PortStatistics | None:
    """``port.statistics()`` when it is a :class:`PortStatistics` record (else None)."""
    fn = getattr(port, "statistics", None)
    stats = fn() if callable(fn) else None
    return stats if isinstance(stats, PortStatistics) else None


# -- descriptor transport ----------------------------------------------------------


def _wake(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)


class _FdTransport:
    """Non-blocking reads and writes on a duplicate of a device's fd, woken by the loop."""

    def __init__(self, fd: int, owner: Any = None, *, can_discard: bool = False) -> None:
        self._fd = os.dup(fd)  # our own number: pyserial closes its fd, we close ours
        os.set_blocking(self._fd, False)
        self._owner = owner
        self._closed = False
        self._waiting: set[asyncio.Future[None]] = set()
        self.can_discard = can_discard

    def discard_output(self) -> None:
        self._check()
        if self.can_discard:
            discard_unsent(self._fd)

    async def _wait(
        self,
        add: Callable[..., object],
        remove: Callable[[int], object],
    ) -> None:
        future = asyncio.get_running_loop().create_future()
        add(self._fd, _wake, future)
        self._waiting.add(future)
        try:
            await future
        finally:
            self._waiting.discard(future)
            if not self._closed:
                remove(self._fd)

    def _check(self) -> None:
        if self._closed:
            raise OSError(errno.EBADF, "the port was closed")

    async def read(self, max_bytes: int) -> bytes:
        loop = asyncio.get_running_loop()
        while True:
            self._check()
            try:
                return os.read(self._fd, max_bytes)
            except BlockingIOError:
                pass
            await self._wait(loop.add_reader, loop.remove_reader)

    async def write(self, data: bytes) -> None:
        loop = asyncio.get_running_loop()
        view = memoryview(data).cast("B")
        while view:
            self._check()
            try:
                view = view[os.write(self._fd, view) :]
                continue
            except BlockingIOError:
                pass
            await self._wait(loop.add_writer, loop.remove_writer)

    async def aclose(self) -> None:
        self._closed = True
        with contextlib.suppress(RuntimeError):  # no running loop: nothing registered
            loop = asyncio.get_running_loop()
            loop.remove_reader(self._fd)
            loop.remove_writer(self._fd)
        for future in self._waiting:
            if not future.done():
                future.set_exception(OSError(errno.EBADF, "the port was closed"))
        os.close(self._fd)
        if self._owner is not None:
            with contextlib.suppress(OSError):
                self._owner.close()
        await asyncio.sleep(0)


# -- thread transport ----------------------------------------------------------------


class _ThreadTransport:
    """A pyserial object without a usable fd: one reader thread, executor writes.

    The reader thread reads with a read timeout and puts chunks in a queue of
    ``_THREAD_QUEUE`` (blocking while it is full: back-pressure), then wakes
    the loop.  Data read is never lost to a cancelled ``read``: it waits in
    the queue.  Writes run in the default executor in chunks, each bounded by
    the write timeout; a cancelled ``write`` leaves the chunk in progress to
    finish.
    """

    def __init__(self, ser: Any, loop: asyncio.AbstractEventLoop) -> None:
        self._ser = ser
        self._tcp = plain_tcp_socket(ser)
        self._loop = loop
        self.can_discard = False
        self._stop = threading.Event()
        self._chunks: queue.Queue[bytes | OSError] = queue.Queue(_THREAD_QUEUE)
        self._arrived = asyncio.Event()
        self._pending = b""
        self._thread = threading.Thread(
            target=self._read_loop, name=f"serialsocket-asyncio-port-{ser.port}", daemon=True
        )
        self._thread.start()

    def _read_loop(self) -> None:
        while not self._stop.is_set():
            try:
                item: bytes | OSError = self._read_available()
            except Exception as exc:  # pyserial raises several types; all end the port
                item = exc if isinstance(exc, OSError) else OSError(errno.EIO, str(exc))
            if item == b"":
                continue
            while not self._stop.is_set():
                try:
                    self._chunks.put(item, timeout=THREAD_READ_TIMEOUT)
                    break
                except queue.Full:
                    continue
            with contextlib.suppress(RuntimeError):  # the loop is closed: nobody listens
                self._loop.call_soon_threadsafe(self._arrived.set)
            if isinstance(item, OSError):
                return

    def _read_available(self) -> bytes:
        # Bounded by _THREAD_BURST: without the bound a steady stream would
        # be held back until it paused, ACKs with it.
        return read_burst(self._ser, self._tcp, _THREAD_BURST)

    def discard_output(self) -> None:
        # A URL has no UART queue of ours to drop: nothing to do.
        return

    async def read(self, max_bytes: int) -> bytes:
        while not self._pending:
            if self._stop.is_set():
                raise OSError(errno.EBADF, "the port was closed")
            try:
                item = self._chunks.get_nowait()
            except queue.Empty:
                self._arrived.clear()
                if self._chunks.empty():
                    await self._arrived.wait()
                continue
            if isinstance(item, OSError):
                raise item
            self._pending = item
        out, self._pending = self._pending[:max_bytes], self._pending[max_bytes:]
        return out

    async def write(self, data: bytes) -> None:
        loop = asyncio.get_running_loop()
        view = memoryview(data).cast("B")
        while view:
            chunk = bytes(view[:_THREAD_WRITE_CHUNK])
            written = await loop.run_in_executor(None, self._ser.write, chunk)
            if written is not None and written != len(chunk):
                raise OSError(errno.ETIMEDOUT, "write timed out: is the line flow-controlled off?")
            view = view[len(chunk) :]

    async def aclose(self) -> None:
        self._stop.set()
        self._arrived.set()  # a waiting read wakes and sees the port closed
        loop = asyncio.get_running_loop()
        # Bounded: the thread notices the flag within one read timeout.
        await loop.run_in_executor(None, self._thread.join, _THREAD_JOIN)
        await loop.run_in_executor(None, self._ser.close)


# -- opening -------------------------------------------------------------------------


async def open_port(
    path_or_url: str,
    baud: int = 9600,
    *,
    bytesize: int = 8,
    parity: str = "N",
    stopbits: float = 1,
    xonxoff: bool = False,
    rtscts: bool = False,
    exclusive: bool = False,
) -> AsyncioSerialPort:
    """Open a serial device, a pty path or a pyserial URL as an :class:`AsyncioSerialPort`.

    The arguments are those of :func:`serialsocket.open_port` (the trio one).

    Raises:
        OSError: the port could not be opened: check the path and its permissions.
        ValueError: a bad setting or an unknown URL scheme.
        TypeError: ``path_or_url`` is not a string.
    """
    check_line_settings(path_or_url, baud, bytesize, parity, stopbits)
    loop = asyncio.get_running_loop()
    thread_io = "://" in path_or_url
    ser = open_serial(
        path_or_url,
        baud=baud,
        bytesize=bytesize,
        parity=parity,
        stopbits=stopbits,
        xonxoff=xonxoff,
        rtscts=rtscts,
        thread_io=thread_io,
        exclusive=exclusive,
    )
    if thread_io:
        return AsyncioSerialPort(_ThreadTransport(ser, loop), path_or_url, ser)
    try:
        read_blocks_for_one_byte(ser.fd)
        transport = _FdTransport(ser.fd, ser, can_discard=holds_output(ser.fd))
    except BaseException:
        ser.close()
        raise
    return AsyncioSerialPort(transport, path_or_url, ser)


def open_pty_pair() -> tuple[AsyncioSerialPort, AsyncioSerialPort]:
    """Two connected ports: the master and the slave side of a new pty, both raw.

    Like :func:`serialsocket.open_pty_pair`: a null-modem cable with
    infinite speed, for examples, tests and benchmarks; close both.  The
    slave's ``name`` is its path (``/dev/pts/N``).
    """
    master, slave = os.openpty()
    try:
        tty.setraw(slave)
        tty.setraw(master)
        name = os.ttyname(slave)
        a = AsyncioSerialPort(
            _FdTransport(master), f"{name} (master)", close_grace=PTY_MASTER_CLOSE_GRACE
        )
        b = AsyncioSerialPort(_FdTransport(slave), name)
    finally:
        os.close(master)
        os.close(slave)
    return a, b
