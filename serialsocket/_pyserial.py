"""Opening a port with pyserial: what the trio and the asyncio ports share.

:func:`open_serial` checks the line settings, opens a device path, a pty
path or a pyserial URL (``loop://``, ``socket://``, ``spy://``) in raw mode,
absorbs the pty DTR pitfall and maps pyserial's errors to ``ValueError`` and
``OSError``; :func:`read_blocks_for_one_byte` sets the termios VMIN/VTIME
that non-blocking reads need.  :class:`PortStatistics` is the record both
kinds of port keep.  No trio and no asyncio here: the I/O is the caller's
(:mod:`serialsocket._port` for trio, :mod:`serialsocket._asyncio_port` for
asyncio).
"""

from __future__ import annotations

import contextlib
import errno
import os
import socket
import sys
import termios
from dataclasses import dataclass
from typing import Any

import serial

from ._config import line_encoding
from ._encoding import EIGHT_BIT_CLEAN, Encoding

__all__ = [
    "PTY_MASTER_CLOSE_GRACE",
    "THREAD_READ_TIMEOUT",
    "THREAD_WRITE_TIMEOUT",
    "PortStatistics",
    "check_line_settings",
    "open_serial",
    "plain_tcp_socket",
    "port_encoding",
    "read_blocks_for_one_byte",
    "read_burst",
]

PTY_MASTER_CLOSE_GRACE = 0.2
"""Seconds a pty master waits before it closes.  Linux hangs the slave up when
its master closes and discards what the slave has not read yet: a socket
that closes right after its last write (the ACK of the peer's EOF) could
take it with it, and the peer, never told its data arrived, reported an
unclean close (an example did, on a loaded machine).  A serial port's close
drains its output instead; only the pty master waits."""

THREAD_READ_TIMEOUT = 0.05
"""Seconds one blocking read in the reader thread waits before it looks at
the stop flag again: bounds how long closing a URL port takes."""

THREAD_WRITE_TIMEOUT = 5.0
"""Seconds one blocking write of a chunk may take before the port is declared
broken (a chunk is at most 4096 bytes: 0.4 s at 9600 bit/s, so only a
stalled device gets near this)."""

_DTR_ERRNOS = frozenset({errno.EINVAL, errno.ENOTTY})
"""What a modem-control ioctl returns on a pty (it has no DTR/RTS lines)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class PortStatistics:
    """What passed through a port.

    Attributes:
        name: the path or URL it was opened with.
        bytes_in: bytes read.
        bytes_out: bytes written.
        reads: reads that returned data.
        writes: ``send_all`` calls that completed.
        errors: OS errors seen (each broke the port).
    """

    name: str
    bytes_in: int
    bytes_out: int
    reads: int
    writes: int
    errors: int


_BYTESIZES = (5, 6, 7, 8)
_PARITIES = {"N": "none", "E": "even", "O": "odd", "M": "mark", "S": "space"}
_STOPBITS = (1, 1.5, 2)


def check_line_settings(
    path_or_url: object, baud: object, bytesize: object, parity: object, stopbits: object
) -> None:
    """Refuse at once, with a typed error, what pyserial would refuse later or
    misbehave on (an open ``serial.Serial`` passed as the path used to hang)."""
    if not isinstance(path_or_url, str):
        raise TypeError(
            f"open_port takes a device path or a pyserial URL string, not "
            f"{type(path_or_url).__name__}; pass the port's name (e.g. ser.port) instead"
        )
    if isinstance(baud, bool) or not isinstance(baud, int) or baud <= 0:
        raise ValueError(f"baud must be a positive integer (bit/s), got {baud!r}")
    if bytesize not in _BYTESIZES or isinstance(bytesize, bool):
        raise ValueError(f"bytesize must be one of {_BYTESIZES}, got {bytesize!r}")
    if parity not in _PARITIES:
        raise ValueError(f"parity must be one of {'/'.join(_PARITIES)}, got {parity!r}")
    if stopbits not in _STOPBITS or isinstance(stopbits, bool):
        raise ValueError(f"stopbits must be one of {_STOPBITS}, got {stopbits!r}")


def _open_raw(
    url: str,
    *,
    baud: int,
    bytesize: int,
    parity: str,
    stopbits: float,
    xonxoff: bool,
    rtscts: bool,
    thread_io: bool,
    exclusive: bool,
) -> Any:
    """An open pyserial object, raw, with the DTR pitfall on ptys absorbed."""
    ser = serial.serial_for_url(
        url,
        do_not_open=True,
        baudrate=baud,
        bytesize=bytesize,
        parity=parity,
        stopbits=stopbits,
        xonxoff=xonxoff,
        rtscts=rtscts,
        timeout=THREAD_READ_TIMEOUT if thread_io else 0,
        write_timeout=THREAD_WRITE_TIMEOUT if thread_io else None,
    )
    if exclusive and hasattr(ser, "exclusive"):
        ser.exclusive = True
    try:
        ser.open()
    except OSError as exc:
        if exc.errno in _DTR_ERRNOS and getattr(ser, "is_open", False):
            return ser  # only the modem-line ioctl failed: a pty, usable as is
        raise
    return ser


def plain_tcp_socket(ser: Any) -> socket.socket | None:
    """The TCP socket under a ``socket://`` port, or None for any other port
    (``rfc2217://`` has one too, but its bytes are Telnet-escaped and its own
    thread reads them: never that one)."""
    if type(ser).__module__ != "serial.urlhandler.protocol_socket":
        return None
    sock = getattr(ser, "_socket", None)
    return sock if isinstance(sock, socket.socket) else None


def read_burst(ser: Any, tcp: socket.socket | None, limit: int) -> bytes:
    """What a URL port's reader thread reads at once: one byte with the
    port's timeout (b"" when it expires), then what else is already there,
    up to ``limit`` bytes.

    ``tcp`` is :func:`plain_tcp_socket` of ``ser``.  pyserial reads
    ``socket://`` by ``recv(1)`` and says ``in_waiting`` is 0 or 1 whatever
    is queued, so asking it again and again took two system calls a byte: a
    receiving end over ``socket://`` read 0.08 MB/s (``linksim bench pty
    --port socket``; 26 MB/s at 4096-character packets with one ``recv`` of
    everything queued).  For other ports ``in_waiting`` is only a lower
    bound too, so keep asking until it says 0 or ``limit`` is reached: one
    hand-off per burst rather than per two bytes (issue 19).
    """
    data = bytearray(ser.read(1))
    if data and tcp is not None:
        with contextlib.suppress(BlockingIOError, InterruptedError):
            data += tcp.recv(limit - 1, socket.MSG_DONTWAIT)
        return bytes(data)
    while data and len(data) < limit:
        more = min(ser.in_waiting, limit - len(data))
        if more <= 0:
            break
        chunk = ser.read(more)
        if not chunk:
            break
        data += chunk
    return bytes(data)


def open_serial(
    path_or_url: str,
    *,
    baud: int,
    bytesize: int = 8,
    parity: str = "N",
    stopbits: float = 1,
    xonxoff: bool,
    rtscts: bool,
    thread_io: bool,
    exclusive: bool,
) -> Any:
    """Open ``path_or_url`` with pyserial (settings already checked).

    ``thread_io``: the port will be read and written by threads (a URL), so
    reads time out after :data:`THREAD_READ_TIMEOUT` and writes after
    :data:`THREAD_WRITE_TIMEOUT`; else reads never block (``timeout=0``).

    Raises:
        OSError: the port could not be opened (with the device's errno).
        ValueError: a bad option in a URL.
    """
    try:
        return _open_raw(
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
    except (KeyError, TypeError) as exc:
        # pyserial parses a URL's ?options while opening and lets a bad one
        # escape as KeyError ('loop://?logging=nope').
        raise ValueError(
            f"bad option in {path_or_url!r}: {exc}; see pyserial's URL handlers for what "
            "each scheme accepts"
        ) from exc
    except serial.SerialException as exc:
        # pyserial's text repeats the errno and the path; say each once.
        why = os.strerror(exc.errno) if exc.errno else str(exc)
        raise OSError(
            exc.errno, f"cannot open {path_or_url!r}: {why} (check the path and its permissions)"
        ) from exc


_PTY_MAJORS = range(128, 144)
"""Linux's device numbers of Unix98 pseudo-terminals (masters 128-135,
slaves 136-143)."""


def holds_output(fd: int) -> bool:
    """Whether ``fd`` is a line that keeps written bytes until they are sent,
    so that :func:`discard_unsent` can drop them: a serial device, not a
    pseudo-terminal (a pty hands each write to its other side at once, and
    ``TCOFLUSH`` drops nothing there)."""
    try:
        st = os.fstat(fd)
        name = os.ttyname(fd)
    except OSError:
        return False
    if name.startswith("/dev/pts/") or name == "/dev/ptmx":
        return False
    return not (sys.platform.startswith("linux") and os.major(st.st_rdev) in _PTY_MAJORS)


def discard_unsent(fd: int) -> None:
    """Drop what was written to ``fd`` and not yet sent (``tcflush(TCOFLUSH)``).

    Raises:
        OSError: the descriptor is not a terminal, or closed.
    """
    try:
        termios.tcflush(fd, termios.TCOFLUSH)
    except termios.error as exc:  # not an OSError subclass
        raise OSError(*exc.args) from exc


def read_blocks_for_one_byte(fd: int) -> None:
    """VMIN = 1, VTIME = 0: a read waits for at least one byte.

    pyserial leaves VMIN = VTIME = 0 (it times reads with select), and in
    that mode a tty read with no data returns 0 bytes -- even on a
    non-blocking fd, where EAGAIN is expected -- which an event loop would
    report as end of file.  With VMIN = 1 a non-blocking read says EAGAIN and
    the loop waits for the fd to become readable.
    """
    attrs = termios.tcgetattr(fd)
    cc = attrs[6]
    if cc[termios.VMIN] != 1 or cc[termios.VTIME] != 0:
        cc[termios.VMIN] = 1
        cc[termios.VTIME] = 0
        termios.tcsetattr(fd, termios.TCSANOW, attrs)


def port_encoding(serial_obj: Any) -> Encoding:
    """The prefix profile a port carries, from its character format
    (:func:`~serialsocket._config.line_encoding`: 8N1 is 8-bit clean, 7 data
    bits or parity printable).  A raw pty (no pyserial object) is 8-bit clean."""
    if serial_obj is None:
        return EIGHT_BIT_CLEAN
    return line_encoding(getattr(serial_obj, "bytesize", 8), getattr(serial_obj, "parity", "N"))
