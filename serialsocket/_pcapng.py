"""pcapng, sans-I/O: the blocks of a capture file, built and parsed as bytes.

Only what a capture of a serial line or a byte stream needs (the pcapng
specification, draft-ietf-opsawg-pcapng, sections 4.1, 4.2 and 4.3): a Section
Header Block, one Interface Description Block per port or connection, and an
Enhanced Packet Block per chunk of bytes seen, with its direction in the
``epb_flags`` option (inbound: the port received it; outbound: the port sent
it).  Blocks are written little-endian; the reader takes either byte order
and skips block types it does not know.

Link types are the "user" ones (LINKTYPE_USER0..15 are reserved for private
use): :data:`LINKTYPE_SERIAL` for the bytes of a serial line (Kermit
packets, modem commands, noise), :data:`LINKTYPE_TCPSTREAM` for the bytes of a
tcpstream session (216-byte command packets).  The Wireshark dissector in
``contrib/wireshark/telelink.lua`` registers for both.

Timestamps are seconds (a float, usually since the Unix epoch), stored in
microseconds (the default ``if_tsresol``).
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass

__all__ = [
    "LINKTYPE_SERIAL",
    "LINKTYPE_TCPSTREAM",
    "Capture",
    "CapturedPacket",
    "Direction",
    "Interface",
    "PcapngError",
    "PcapngWriter",
    "read_pcapng",
]

LINKTYPE_SERIAL = 147
"""LINKTYPE_USER0: the raw bytes of a serial line (telelink's Kermit packets)."""
LINKTYPE_TCPSTREAM = 148
"""LINKTYPE_USER1: the bytes of a tcpstream session (216-byte packets, any chunking)."""

_SHB = 0x0A0D0D0A
_IDB = 0x00000001
_EPB = 0x00000006
_BYTE_ORDER_MAGIC = 0x1A2B3C4D

_OPT_END = 0
_SHB_USERAPPL = 4
_IF_NAME = 2
_IF_DESCRIPTION = 3
_EPB_FLAGS = 2

_MAX_BLOCK = 16 * 1024 * 1024
"""Largest block the reader accepts: far above any chunk we write (a relay
read is at most 64 KiB); a corrupt length must not make it allocate gigabytes."""


class Direction(enum.IntEnum):
    """The direction bits of ``epb_flags`` (pcapng section 4.3.1, bits 0-1)."""

    UNKNOWN = 0
    INBOUND = 1
    """The interface received these bytes (``rx``)."""
    OUTBOUND = 2
    """The interface sent these bytes (``tx``)."""


class PcapngError(ValueError):
    """Bytes that are not a pcapng file this reader understands (says where)."""


@dataclass(frozen=True, slots=True)
class Interface:
    """One Interface Description Block: a port, a pty or a connection."""

    name: str
    linktype: int = LINKTYPE_SERIAL
    description: str = ""


@dataclass(frozen=True, slots=True)
class CapturedPacket:
    """One Enhanced Packet Block: bytes seen on an interface at a time, one way."""

    interface: int
    timestamp: float
    data: bytes
    direction: Direction = Direction.UNKNOWN


@dataclass(frozen=True, slots=True)
class Capture:
    """A parsed capture: the application that wrote it, its interfaces and packets."""

    application: str
    interfaces: tuple[Interface, ...]
    packets: tuple[CapturedPacket, ...]


def _pad(n: int) -> int:
    return -n % 4


def _option(code: int, value: bytes) -> bytes:
    return struct.pack("<HH", code, len(value)) + value + b"\0" * _pad(len(value))


def _options(items: list[tuple[int, bytes]]) -> bytes:
    if not items:
        return b""
    return b"".join(_option(code, value) for code, value in items) + _option(_OPT_END, b"")


def _block(block_type: int, body: bytes) -> bytes:
    total = 12 + len(body)  # type, length, body (already padded), length again
    return struct.pack("<II", block_type, total) + body + struct.pack("<I", total)


class PcapngWriter:
    """Builds the bytes of one pcapng section; the caller writes them somewhere.

    :meth:`header` first, then any mix of :meth:`add_interface` (an interface
    must be described before its first packet) and :meth:`packet`.  Nothing
    here touches a file or a clock: timestamps come in as arguments.
    """

    def __init__(self, application: str = "telelink") -> None:
        self.application = application
        self._interfaces: list[Interface] = []

    @property
    def interfaces(self) -> tuple[Interface, ...]:
        """The interfaces described so far, by id."""
        return tuple(self._interfaces)

    def header(self) -> bytes:
        """The Section Header Block (byte-order magic, version 1.0, length unknown)."""
        body = struct.pack("<IHHq", _BYTE_ORDER_MAGIC, 1, 0, -1)
        body += _options([(_SHB_USERAPPL, self.application.encode())])
        return _block(_SHB, body)

    def add_interface(self, interface: Interface) -> tuple[int, bytes]:
        """Describe an interface: its id (for :meth:`packet`) and the block to write."""
        self._interfaces.append(interface)
        body = struct.pack("<HHI", interface.linktype, 0, 0)  # snaplen 0: no limit
        opts = [(_IF_NAME, interface.name.encode())]
        if interface.description:
            opts.append((_IF_DESCRIPTION, interface.description.encode()))
        return len(self._interfaces) - 1, _block(_IDB, body + _options(opts))

    def packet(
        self,
        interface: int,
        data: bytes | bytearray | memoryview,
        timestamp: float,
        direction: Direction = Direction.UNKNOWN,
    ) -> bytes:
        """One Enhanced Packet Block: ``data`` seen on ``interface`` at ``timestamp`` s."""
        if not 0 <= interface < len(self._interfaces):
            raise ValueError(
                f"interface {interface} is not described (add_interface first; "
                f"{len(self._interfaces)} so far)"
            )
        if timestamp < 0:
            raise ValueError(f"timestamp {timestamp} is before 1970")
        raw = bytes(data)
        micros = round(timestamp * 1_000_000)
        body = struct.pack(
            "<IIIII", interface, micros >> 32, micros & 0xFFFFFFFF, len(raw), len(raw)
        )
        body += raw + b"\0" * _pad(len(raw))
        if direction != Direction.UNKNOWN:
            body += _options([(_EPB_FLAGS, struct.pack("<I", int(direction)))])
        return _block(_EPB, body)


def _parse_options(body: bytes, order: str, where: int) -> dict[int, bytes]:
    found: dict[int, bytes] = {}
    pos = 0
    while pos + 4 <= len(body):
        code, length = struct.unpack_from(order + "HH", body, pos)
        pos += 4
        if code == _OPT_END:
            break
        if pos + length > len(body):
            raise PcapngError(f"block at offset {where}: option {code} runs past the block")
        found.setdefault(code, body[pos : pos + length])
        pos += length + _pad(length)
    return found


def read_pcapng(data: bytes) -> Capture:
    """Parse a one-section pcapng file (what :class:`PcapngWriter` writes).

    Raises :class:`PcapngError` naming the offset of the first block that is
    not well formed.  Blocks of other types (statistics, comments) are skipped.
    """
    if len(data) < 28 or struct.unpack_from("<I", data)[0] != _SHB:
        raise PcapngError("not a pcapng file: no Section Header Block at offset 0")
    magic = data[8:12]
    if magic == struct.pack("<I", _BYTE_ORDER_MAGIC):
        order = "<"
    elif magic == struct.pack(">I", _BYTE_ORDER_MAGIC):
        order = ">"
    else:
        raise PcapngError("offset 8: bad byte-order magic")
    application = ""
    interfaces: list[Interface] = []
    packets: list[CapturedPacket] = []
    pos = 0
    while pos < len(data):
        if pos + 12 > len(data):
            raise PcapngError(f"offset {pos}: a truncated block header")
        block_type, total = struct.unpack_from(order + "II", data, pos)
        if total < 12 or total % 4 or total > _MAX_BLOCK or pos + total > len(data):
            raise PcapngError(f"offset {pos}: bad block length {total}")
        if struct.unpack_from(order + "I", data, pos + total - 4)[0] != total:
            raise PcapngError(f"offset {pos}: the trailing block length does not match")
        body = data[pos + 8 : pos + total - 4]
        if block_type == _SHB:
            if pos != 0:
                raise PcapngError(f"offset {pos}: a second section (not supported)")
            major, _minor = struct.unpack_from(order + "HH", body, 4)
            if major != 1:
                raise PcapngError(f"offset {pos}: pcapng major version {major}, not 1")
            opts = _parse_options(body[16:], order, pos)
            application = opts.get(_SHB_USERAPPL, b"").decode(errors="replace")
        elif block_type == _IDB:
            linktype = struct.unpack_from(order + "H", body)[0]
            opts = _parse_options(body[8:], order, pos)
            interfaces.append(
                Interface(
                    name=opts.get(_IF_NAME, b"").decode(errors="replace"),
                    linktype=linktype,
                    description=opts.get(_IF_DESCRIPTION, b"").decode(errors="replace"),
                )
            )
        elif block_type == _EPB:
            iface, high, low, caplen, _origlen = struct.unpack_from(order + "IIIII", body)
            if iface >= len(interfaces):
                raise PcapngError(f"offset {pos}: packet on undescribed interface {iface}")
            if 20 + caplen > len(body):
                raise PcapngError(f"offset {pos}: captured length {caplen} runs past the block")
            end = 20 + caplen + _pad(caplen)
            opts = _parse_options(body[end:], order, pos)
            flags = struct.unpack(order + "I", opts[_EPB_FLAGS])[0] if _EPB_FLAGS in opts else 0
            bits = flags & 3  # 3 is not a direction: read it as unknown
            packets.append(
                CapturedPacket(
                    interface=iface,
                    timestamp=((high << 32) | low) / 1_000_000,
                    data=body[20 : 20 + caplen],
                    direction=Direction(bits) if bits != 3 else Direction.UNKNOWN,
                )
            )
        pos += total
    return Capture(application, tuple(interfaces), tuple(packets))
