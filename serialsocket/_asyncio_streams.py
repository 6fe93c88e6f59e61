"""asyncio's (reader, writer) pair over a serial socket: ``serialsocket.asyncio.open_connection``.

An ``asyncio.Transport`` whose protocol is asyncio's own
``StreamReaderProtocol``, so the streams are the standard library's and any
API written against them (:mod:`tcpstream.asyncio`'s ``Opener``) runs over a
serial line unchanged.  No trio here.
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import Protocol

from ._asyncio_port import READ_SIZE

__all__ = ["streams_over"]


class _Socket(Protocol):
    """What the transport uses of a ``serialsocket.asyncio.AsyncioSerialSocket``."""

    async def read(self, n: int = -1) -> bytes: ...
    def write(self, data: bytes | bytearray | memoryview) -> None: ...
    async def drain(self) -> None: ...
    def write_eof(self) -> None: ...
    def get_write_buffer_size(self) -> int: ...
    def is_closing(self) -> bool: ...
    def close(self) -> None: ...
    def abort(self, reason: str = ...) -> None: ...
    async def wait_closed(self) -> None: ...


def streams_over(sock: _Socket) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    loop = asyncio.get_running_loop()
    reader = asyncio.StreamReader(limit=READ_SIZE, loop=loop)
    protocol = asyncio.StreamReaderProtocol(reader, loop=loop)
    transport = _SocketTransport(sock, protocol)
    writer = asyncio.StreamWriter(transport, protocol, reader, loop)
    return reader, writer


class _SocketTransport(asyncio.Transport):
    """An ``asyncio.Transport`` over a serial socket (``open_connection``).

    One task pumps what the socket reads into the protocol, pausing while the
    protocol asks it to (``pause_reading``), so the endpoint's receive window
    closes when the application stops reading.  ``write`` is the socket's
    (its bounded buffer plus the outbox); the protocol is paused while the
    outbox holds more than :data:`READ_SIZE` bytes.
    """

    def __init__(self, sock: _Socket, protocol: asyncio.StreamReaderProtocol) -> None:
        super().__init__({"socket": sock, "peername": None})
        self._sock = sock
        self._protocol = protocol
        self._resume = asyncio.Event()
        self._resume.set()
        self._write_paused = False
        self._resumer: asyncio.Task[None] | None = None
        self._closing = False
        self._closed = asyncio.Event()  # close() or abort() was called
        protocol.connection_made(self)
        self._pump = asyncio.create_task(self._read_loop(), name="serialsocket-transport")

    async def _read_loop(self) -> None:
        exc: Exception | None = None
        try:
            while True:
                await self._resume.wait()
                data = await self._sock.read(READ_SIZE)
                if not data:
                    self._protocol.eof_received()
                    # Half-closed by the peer: writing goes on until close() or abort().
                    await self._closed.wait()
                    break
                self._protocol.data_received(data)
                self._check_write_pressure()
        except ConnectionError as error:
            exc = error
            if not self._sock.is_closing():
                self._sock.abort("the link failed")  # stops the driver, closes the port
        except RuntimeError:
            pass  # closed by close() or abort()
        await self._sock.wait_closed()
        self._protocol.connection_lost(exc)

    def _check_write_pressure(self) -> None:
        high = self._sock.get_write_buffer_size() > READ_SIZE
        if high and not self._write_paused:
            self._write_paused = True
            self._protocol.pause_writing()
            self._resumer = asyncio.create_task(self._resume_writing_later())

    async def _resume_writing_later(self) -> None:
        with contextlib.suppress(ConnectionError, RuntimeError):
            await self._sock.drain()
        self._write_paused = False
        self._protocol.resume_writing()

    def write(self, data: bytes | bytearray | memoryview) -> None:
        self._sock.write(data)
        self._check_write_pressure()

    def write_eof(self) -> None:
        self._sock.write_eof()

    def can_write_eof(self) -> bool:
        return True

    def get_write_buffer_size(self) -> int:
        return self._sock.get_write_buffer_size()

    def is_reading(self) -> bool:
        return self._resume.is_set()

    def pause_reading(self) -> None:
        self._resume.clear()

    def resume_reading(self) -> None:
        self._resume.set()

    def is_closing(self) -> bool:
        return self._closing

    def close(self) -> None:
        self._closing = True
        self._closed.set()
        self._resume.set()  # a paused pump wakes and sees the socket closed
        self._sock.close()

    def abort(self) -> None:
        self._closing = True
        self._closed.set()
        self._resume.set()
        self._sock.abort()
