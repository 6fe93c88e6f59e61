"""Layer 1, port I/O: a serial device, a pty or a pyserial URL as a trio stream.

:func:`open_port` opens what it is given with pyserial -- 8 data bits, no
parity, one stop bit unless told otherwise, raw mode, no flow control unless
asked -- and returns a
:class:`SerialPort`, a ``trio.abc.Stream`` that counts what passes through it.

* A device path (``/dev/ttyUSB0``, ``/dev/pts/5``) has a file descriptor:
  pyserial configures it (termios) and a ``trio.lowlevel.FdStream`` over a
  duplicate of the descriptor does the I/O, so reads and writes wait in trio's
  I/O manager, not in threads.
* A pyserial URL (``loop://``, ``socket://host:port``, ``spy://PATH``,
  ``rfc2217://...``) has no descriptor we may use (``spy://`` has one, but
  reading it directly would bypass the spy): one reader thread and short,
  bounded writes in worker threads move the bytes (:class:`_ThreadTransport`).

Errors at the stream boundary are trio's: an ``OSError`` (pyserial's
``SerialException`` is one) becomes ``trio.BrokenResourceError`` with the
``OSError`` chained as ``__cause__``; any use after ``aclose`` raises
``trio.ClosedResourceError``.

pty pitfalls handled here: pyserial's DTR/RTS ioctls fail on a pty with
``EINVAL`` or ``ENOTTY`` (a pty has no modem lines); pyserial >= 3.5 ignores
that while opening, and :func:`serialsocket._pyserial.open_serial` (shared with
the asyncio port) ignores exactly those two errnos around the whole open for
older releases and for the ``dsrdtr`` path.  A pty
master reads ``EIO`` once the slave side is closed (the "device went away"
case); that surfaces as ``BrokenResourceError`` like any other line failure.
"""

from __future__ import annotations

import contextlib
import errno
import os
import threading
import tty
from typing import Any, Protocol

import trio

from ._encoding import Encoding
from ._pyserial import (
    PTY_MASTER_CLOSE_GRACE,
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
from ._pyserial import THREAD_READ_TIMEOUT as _THREAD_READ_TIMEOUT

__all__ = ["PortStatistics", "SerialPort", "open_port", "open_pty_pair", "port_statistics"]

_READ_SIZE = 65536
"""Bytes asked of the device per read; a pty hands out at most ~4 KB anyway."""

_THREAD_WRITE_CHUNK = 4096
"""Bytes per worker-thread write: keeps each uncancellable wait short."""

_THREAD_QUEUE = 16
"""Chunks the reader thread may hold before it stops reading (back-pressure):
16 x 64 KB bounds the memory of a port whose reader is slow."""


class _Transport(Protocol):
    can_discard: bool

    def discard_output(self) -> None: ...
    async def send_all(self, data: bytes | bytearray | memoryview) -> None: ...
    async def wait_send_all_might_not_block(self) -> None: ...
    async def receive_some(self, max_bytes: int) -> bytes: ...
    async def aclose(self) -> None: ...


class SerialPort(trio.abc.Stream):
    """A trio stream over a serial line, with counters.

    Use :func:`open_port` or :func:`open_pty_pair` to get one.  ``send_all``
    returns once the bytes are in the device's output buffer (the UART may
    still be clocking them out).  ``receive_some`` returns ``b""`` only when
    the other end is gone for good (a URL transport's EOF); a pty whose other
    side closed raises ``BrokenResourceError`` instead, as the kernel says EIO.

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
        # trio's contract: one sender and one receiver at a time (the thread
        # transport would otherwise interleave two writers' chunks).
        self._sending = self._receiving = False
        self._bytes_in = self._bytes_out = self._reads = self._writes = self._errors = 0

    @property
    def encoding(self) -> Encoding:
        """The prefix profile this line carries (its character format: 8N1,
        a raw pty or a URL is 8-bit clean; 7 data bits or parity printable).
        ``connect``/``accept``/``listen`` use it when the configuration
        leaves ``encoding`` to the line (PROTOCOL.md section 8)."""
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
            raise trio.ClosedResourceError(f"port {self.name} was closed")

    def _broken(self, exc: OSError) -> trio.BrokenResourceError:
        self._errors += 1
        return trio.BrokenResourceError(
            f"port {self.name} failed: {exc} (unplugged, or the other end of the pty closed?)"
        )

    def _map(self, exc: trio.BrokenResourceError | trio.ClosedResourceError | OSError) -> Exception:
        """One error mapping for both transports (closed, broken, or a raw OSError)."""
        if self._closed or isinstance(exc, trio.ClosedResourceError):
            return trio.ClosedResourceError(f"port {self.name} was closed")
        if isinstance(exc, OSError):
            return self._broken(exc)
        cause = exc.__cause__
        if isinstance(cause, OSError):
            return self._broken(cause)
        self._errors += 1
        return exc

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        """Write all of ``data``.

        Raises:
            trio.ClosedResourceError: the port was closed.
            trio.BrokenResourceError: the device failed (``__cause__`` is the OSError).
            trio.BusyResourceError: another task is already sending.
        """
        if self._sending:
            raise trio.BusyResourceError(f"another task is already sending on {self.name}")
        self._check_open()
        self._sending = True
        try:
            await self._t.send_all(data)
        except (trio.BrokenResourceError, trio.ClosedResourceError, OSError) as exc:
            raise self._map(exc) from _cause_of(exc)
        finally:
            self._sending = False
        self._writes += 1
        self._bytes_out += len(data)

    @property
    def can_discard_output(self) -> bool:
        """:meth:`discard_output` drops something: a serial device, not a
        pty (which hands every write to its other side at once) or a URL."""
        return self._t.can_discard

    def discard_output(self) -> None:
        """Drop the bytes written and not yet sent (``tcflush(TCOFLUSH)``):
        what a serial socket does before an expedited message so that it
        waits behind none of them (PROTOCOL.md 11).  Call it between writes,
        not during one.  A UART's hardware FIFO (16 bytes on a 16550) may
        still go out.  Without :attr:`can_discard_output` there is nothing
        of ours to drop and nothing happens.

        Raises:
            trio.ClosedResourceError: the port was closed.
            trio.BrokenResourceError: the device failed (``__cause__`` is the OSError).
        """
        self._check_open()
        try:
            self._t.discard_output()
        except OSError as exc:
            raise self._map(exc) from exc

    async def wait_send_all_might_not_block(self) -> None:
        """Wait until a write would not block (or the port failed)."""
        self._check_open()
        try:
            await self._t.wait_send_all_might_not_block()
        except (trio.BrokenResourceError, trio.ClosedResourceError, OSError) as exc:
            raise self._map(exc) from _cause_of(exc)

    async def receive_some(self, max_bytes: int | None = None) -> bytes:
        """Some bytes from the line (at least one), or ``b""`` at a transport's EOF.

        Raises:
            trio.ClosedResourceError: the port was closed (also wakes a blocked read).
            trio.BrokenResourceError: the device failed (``__cause__`` is the OSError).
            trio.BusyResourceError: another task is already receiving.
        """
        if max_bytes is not None and max_bytes < 1:
            raise ValueError("max_bytes must be >= 1")
        if self._receiving:
            raise trio.BusyResourceError(f"another task is already receiving on {self.name}")
        self._check_open()
        self._receiving = True
        try:
            data = await self._t.receive_some(max_bytes or _READ_SIZE)
        except (trio.BrokenResourceError, trio.ClosedResourceError, OSError) as exc:
            raise self._map(exc) from _cause_of(exc)
        finally:
            self._receiving = False
        if data:
            self._reads += 1
            self._bytes_in += len(data)
        return data

    async def aclose(self) -> None:
        """Close the port (idempotent; wakes blocked readers with ClosedResourceError)."""
        if self._closed:
            await trio.lowlevel.checkpoint()
            return
        self._closed = True
        try:
            if self._close_grace > 0:
                await trio.sleep(self._close_grace)  # see PTY_MASTER_CLOSE_GRACE
        finally:
            await self._t.aclose()


def port_statistics(port: object) -> PortStatistics | None:
    """``port.statistics()`` when it is a :class:`PortStatistics` record (else None).

    Duck-typed so that wrappers (the packet trace) pass their port's record on.
    """
    fn = getattr(port, "statistics", None)
    stats = fn() if callable(fn) else None
    return stats if isinstance(stats, PortStatistics) else None


def _cause_of(exc: BaseException) -> BaseException | None:
    """The OSError behind ``exc`` (itself, or trio's chained cause), for chaining."""
    if isinstance(exc, OSError):
        return exc
    return exc.__cause__


# -- descriptor transport ----------------------------------------------------------


class _FdTransport:
    """``FdStream`` over a duplicate of a device's fd; the pyserial object is closed last."""

    def __init__(self, fd: int, owner: Any = None, *, can_discard: bool = False) -> None:
        # FdStream takes ownership of the fd it is given and sets O_NONBLOCK on
        # the open file description; it gets its own duplicate so that pyserial
        # (which keeps the termios settings and closes its fd) and trio never
        # close the same number twice.
        self._stream = trio.lowlevel.FdStream(os.dup(fd))
        self._owner = owner
        self.can_discard = can_discard

    def discard_output(self) -> None:
        if not self.can_discard:
            return
        fd = self._stream.fileno()
        if fd < 0:
            raise trio.ClosedResourceError("file was already closed")
        discard_unsent(fd)

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        await self._stream.send_all(data)

    async def wait_send_all_might_not_block(self) -> None:
        await self._stream.wait_send_all_might_not_block()

    async def receive_some(self, max_bytes: int) -> bytes:
        # Wait until the fd is readable, then read: one trip through the
        # scheduler per read (a checkpoint).  FdStream.receive_some
        # checkpoints, reads, and on EAGAIN -- the usual case for a reader
        # that keeps up -- waits and reads again: two trips and a failed
        # read per call.  Its errors are kept: EBADF (closed) and the rest.
        stream = self._stream
        while True:
            fd = stream.fileno()  # -1 once closed
            if fd < 0:
                raise trio.ClosedResourceError("file was already closed")
            await trio.lowlevel.wait_readable(fd)  # ClosedResourceError if closed meanwhile
            try:
                return os.read(fd, max_bytes)
            except BlockingIOError:
                continue  # another reader of the device took the bytes
            except OSError as exc:
                if exc.errno == errno.EBADF:
                    raise trio.ClosedResourceError("file was already closed") from None
                raise trio.BrokenResourceError from exc

    async def aclose(self) -> None:
        self._stream.close()  # notifies any task blocked on the fd
        if self._owner is not None:
            # The owner's fd is the original; a failing close leaves nothing to release.
            with contextlib.suppress(OSError):
                self._owner.close()
        await trio.lowlevel.checkpoint()


# -- thread transport ----------------------------------------------------------------


class _ThreadTransport:
    """A pyserial object without a usable fd: one reader thread, worker-thread writes.

    The reader thread reads with a ``_THREAD_READ_TIMEOUT`` timeout and hands
    chunks to trio through a memory channel of ``_THREAD_QUEUE`` chunks; while
    the channel is full it blocks (back-pressure).  Data read is never lost to
    a cancelled ``receive_some``: it waits in the channel.  Writes run in a
    worker thread in chunks, each bounded by the write timeout; a cancelled
    ``send_all`` returns after the chunk in progress (trio's contract: the
    stream is then in an unknown state for sending).
    """

    def __init__(self, ser: Any) -> None:
        self._ser = ser
        self._tcp = plain_tcp_socket(ser)
        self.can_discard = False
        self._stop = threading.Event()
        send, self._receive = trio.open_memory_channel[bytes | BaseException](_THREAD_QUEUE)
        self._token = trio.lowlevel.current_trio_token()
        self._pending = b""
        self._thread = threading.Thread(
            target=self._read_loop, args=(send,), name=f"serialsocket-port-{ser.port}", daemon=True
        )
        self._thread.start()

    def _read_loop(self, send: trio.MemorySendChannel[bytes | BaseException]) -> None:
        try:
            while not self._stop.is_set():
                try:
                    data = self._read_available()
                except Exception as exc:  # pyserial raises several types; all end the port
                    item: bytes | BaseException = (
                        exc if isinstance(exc, OSError) else OSError(errno.EIO, str(exc))
                    )
                    trio.from_thread.run(send.send, item, trio_token=self._token)
                    return
                if data:
                    trio.from_thread.run(send.send, bytes(data), trio_token=self._token)
        except (trio.RunFinishedError, trio.BrokenResourceError, trio.ClosedResourceError):
            return  # trio is gone or the port was closed: nobody wants the data
        finally:
            with contextlib.suppress(trio.RunFinishedError):
                trio.from_thread.run_sync(send.close, trio_token=self._token)

    def _read_available(self) -> bytes:
        return read_burst(self._ser, self._tcp, _READ_SIZE)

    def discard_output(self) -> None:
        # A URL has no UART queue of ours to drop (socket:// hands bytes to
        # TCP, loop:// has delivered them already): nothing to do.
        return

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        view = memoryview(data).cast("B")
        await trio.lowlevel.checkpoint()
        while view:
            chunk = bytes(view[:_THREAD_WRITE_CHUNK])
            written = await trio.to_thread.run_sync(self._ser.write, chunk)
            if written is not None and written != len(chunk):
                raise OSError(errno.ETIMEDOUT, "write timed out: is the line flow-controlled off?")
            view = view[len(chunk) :]

    async def wait_send_all_might_not_block(self) -> None:
        await trio.lowlevel.checkpoint()

    async def receive_some(self, max_bytes: int) -> bytes:
        if not self._pending:
            try:
                item = await self._receive.receive()
            except trio.EndOfChannel:
                return b""
            if isinstance(item, BaseException):
                raise item
            self._pending = item
        else:
            await trio.lowlevel.checkpoint()
        out, self._pending = self._pending[:max_bytes], self._pending[max_bytes:]
        return out

    async def aclose(self) -> None:
        self._stop.set()
        self._receive.close()  # a reader thread blocked on a full channel is released
        with trio.CancelScope(shield=True):
            # Bounded: the thread notices the flag within one read timeout.
            await trio.to_thread.run_sync(self._thread.join, 1.0 + _THREAD_READ_TIMEOUT)
            await trio.to_thread.run_sync(self._ser.close)


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
) -> SerialPort:
    """Open a serial device, a pty path or a pyserial URL as a :class:`SerialPort`.

    Args:
        path_or_url: ``/dev/ttyS0``, ``/dev/pts/7``, or a pyserial URL such as
            ``loop://``, ``socket://host:port``, ``spy:///dev/ttyS0``.
        baud: line rate in bit/s, > 0 (ignored by ptys and sockets, which are
            as fast as the machine).
        bytesize, parity, stopbits: the character format, 8N1 by default.
            It chooses the profile (``port.encoding``): 8N1 is 8-bit clean;
            a 7-bit line (``bytesize=7, parity="E"``: 7E1, classic Kermit
            territory) or any parity carries the printable profile.
        xonxoff: software flow control (off by default: the printable Kermit
            profile never sends XON/XOFF, but binary data over an 8-bit-clean
            profile would trip it; with it on, tell the endpoint
            ``EndpointConfig(xon_xoff=True)`` so the escape code escapes them).
        rtscts: hardware flow control.
        exclusive: take an advisory lock so a second program cannot open it.

    Returns:
        The port; close it with ``aclose`` (a :class:`SerialSocket` made over
        it closes it for you).

    Raises:
        OSError: the port could not be opened (pyserial's SerialException,
            with the device's errno): check the path and its permissions.
        ValueError: a bad setting or an unknown URL scheme.
        TypeError: ``path_or_url`` is not a string (an open ``serial.Serial``).
    """
    check_line_settings(path_or_url, baud, bytesize, parity, stopbits)
    await trio.lowlevel.checkpoint()
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
        return SerialPort(_ThreadTransport(ser), path_or_url, ser)
    try:
        read_blocks_for_one_byte(ser.fd)
        transport = _FdTransport(ser.fd, ser, can_discard=holds_output(ser.fd))
    except BaseException:
        ser.close()
        raise
    return SerialPort(transport, path_or_url, ser)


def open_pty_pair() -> tuple[SerialPort, SerialPort]:
    """Two connected ports: the master and the slave side of a new pty, both raw.

    What one writes the other reads, like a null-modem cable with infinite
    speed (the kernel's pty buffers, about 4 KB each way, are the only
    limit).  For demos, tests and benchmarks; close both.  The slave's
    ``name`` is its path (``/dev/pts/N``): another program may open it too,
    but then both readers compete for the bytes.
    """
    master, slave = os.openpty()
    try:
        tty.setraw(slave)
        # Raw mode on the master matters too: its termios echo flags are
        # ignored by Linux, but other kernels honour some of them.
        tty.setraw(master)
        name = os.ttyname(slave)
        a = SerialPort(_FdTransport(master), f"{name} (master)", close_grace=PTY_MASTER_CLOSE_GRACE)
        b = SerialPort(_FdTransport(slave), name)
    finally:
        # Each transport holds its own duplicate.
        os.close(master)
        os.close(slave)
    return a, b
