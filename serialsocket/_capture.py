"""Capture to a pcapng file: the file, and a stream wrapper that records both ways.

:class:`CaptureFile` owns the file and a :class:`~serialsocket.capture.PcapngWriter`;
every :meth:`CaptureFile.record` is one Enhanced Packet Block, flushed at once
so that a capture of a running program can be opened while it runs, and so
that nothing is lost when the program is killed.  :class:`CapturingStream`
wraps a port (or any ``trio.abc.Stream``) and records what is sent as
outbound and what is received as inbound on one interface.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from types import TracebackType
from typing import BinaryIO

import trio

from ._pcapng import LINKTYPE_SERIAL, Direction, Interface, PcapngWriter
from ._port import PortStatistics, port_statistics

__all__ = ["CaptureFile", "CapturingStream"]


class CaptureFile:
    """A pcapng file being written (``path`` is created or truncated).

    ``clock`` gives the timestamp of a record that brings none (default
    ``time.time``: seconds since the epoch, what Wireshark shows as dates).
    Closing it (or leaving its ``with`` block) closes the file; records after
    that are ignored, so a late byte on the way out cannot crash a run.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        clock: Callable[[], float] = time.time,
        application: str = "telelink",
    ) -> None:
        self.path = os.fspath(path)
        self.clock = clock
        self._writer = PcapngWriter(application)
        self._file: BinaryIO | None = open(self.path, "wb")  # noqa: SIM115 (closed in close())
        self.records = 0
        """Enhanced Packet Blocks written so far."""
        self._write(self._writer.header())

    def _write(self, block: bytes) -> None:
        if self._file is not None:
            self._file.write(block)
            self._file.flush()

    def add_interface(
        self, name: str, *, linktype: int = LINKTYPE_SERIAL, description: str = ""
    ) -> int:
        """Describe one more port or connection; returns its id for :meth:`record`."""
        interface, block = self._writer.add_interface(Interface(name, linktype, description))
        self._write(block)
        return interface

    def record(
        self,
        interface: int,
        data: bytes | bytearray | memoryview,
        direction: Direction,
        timestamp: float | None = None,
    ) -> None:
        """``data`` seen on ``interface`` going ``direction`` (now, unless ``timestamp``)."""
        if self._file is None or not data:
            return
        when = self.clock() if timestamp is None else timestamp
        self._write(self._writer.packet(interface, data, when, direction))
        self.records += 1

    def close(self) -> None:
        """Close the file (idempotent)."""
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> CaptureFile:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class CapturingStream(trio.abc.Stream):
    """A transparent wrapper around ``inner`` that records its bytes in ``capture``.

    What :meth:`send_all` sends is recorded outbound once the inner stream took
    it, what :meth:`receive_some` returns inbound, both on ``interface`` (see
    :meth:`CaptureFile.add_interface`).  Closing the wrapper closes ``inner``,
    not the capture: one capture may outlive many streams.
    """

    def __init__(self, inner: trio.abc.Stream, capture: CaptureFile, interface: int) -> None:
        self.inner = inner
        self.capture = capture
        self.interface = interface

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        await self.inner.send_all(data)
        self.capture.record(self.interface, data, Direction.OUTBOUND)

    async def wait_send_all_might_not_block(self) -> None:
        await self.inner.wait_send_all_might_not_block()

    async def receive_some(self, max_bytes: int | None = None) -> bytes | bytearray:
        data = await self.inner.receive_some(max_bytes)
        self.capture.record(self.interface, data, Direction.INBOUND)
        return data

    async def aclose(self) -> None:
        await self.inner.aclose()

    def statistics(self) -> PortStatistics | None:
        """The inner port's counters when it is a :class:`~serialsocket.SerialPort` (else None)."""
        return port_statistics(self.inner)
