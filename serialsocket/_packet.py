"""Kermit packets: the frozen record and its wire form.

Wire layout (reference/kermit.md section 1)::

    normal:    MARK LEN SEQ TYPE DATA... CHECK [EOL]                 LEN = tochar(3..94)
    extended:  MARK ' ' SEQ TYPE LENX1 LENX2 HCHECK DATA... CHECK [EOL]

A packet is built normal when ``len(DATA) + len(CHECK) + 2 <= 94`` and extended
otherwise, exactly as kermit.c, gkermit.c and ckcfn2.c decide (C-Kermit once
built LEN 95/96 as normal packets and produced unreadable LEN bytes; that
boundary is tested).  Packet *lengths* in this package count MARK through
CHECK; see :data:`~serialsocket._wire.DEFAULT_MAX_PACKET_LENGTH`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ._checks import _CRC16_FUN, _CRC16_TABLE, BlockCheck, check_chars
from ._errors import LocalProtocolError
from ._wire import (
    CR,
    EXTENDED_HEADER_LENGTH,
    MARK,
    MAX_EXTENDED_FIELD,
    MAX_NORMAL_LEN,
    MAX_PACKET_LENGTH,
    MIN_PACKET_LENGTH,
    NORMAL_HEADER_LENGTH,
    SEQ_MODULUS,
    PacketType,
)

__all__ = ["Packet", "build_packet", "data_capacity", "packet_length"]

_KNOWN_TYPES = {t.value: t for t in PacketType}
_CRC16 = BlockCheck.CRC16
"""(Enum member lookups cost a descriptor call each in Python 3.11.)"""


@dataclass(frozen=True, slots=True, kw_only=True, init=False)
class Packet:
    """One Kermit packet.

    Attributes:
        seq: sequence number, 0..63.
        type: the type letter.  Known letters are :class:`PacketType` members
            (a ``StrEnum``, so ``packet.type == "D"`` works); unknown printable
            letters from a peer are kept as plain one-character strings.
        data: the data field exactly as on the wire, i.e. prefix-encoded.  Use
            :class:`~serialsocket.packets.Encoding` to encode and decode it.

    Raises:
        LocalProtocolError: ``seq`` is out of range, ``type`` is not one
            printable character, or ``data`` contains the packet MARK (which
            would cut the packet in two on the line).
    """

    seq: int
    type: str
    data: bytes

    # Written out (not generated) so that the checks and the three stores cost
    # one call: a sender builds one Packet per data packet.
    def __init__(self, *, seq: int, type: str, data: bytes = b"") -> None:
        if not 0 <= seq < SEQ_MODULUS:
            raise LocalProtocolError(f"sequence number {seq} is outside 0..63")
        if type.__class__ is not PacketType:
            if len(type) != 1 or not 33 <= ord(type) <= 126:
                raise LocalProtocolError(f"packet type {type!r} is not one printable character")
            type = _KNOWN_TYPES.get(type, type)
        if MARK in data:
            raise LocalProtocolError(
                "a data field must not contain the MARK (SOH): encode it first"
            )
        _SET_SEQ(self, seq)
        _SET_TYPE(self, type)
        _SET_DATA(self, data)


_new = object.__new__


def _slot_setter(cls: type, name: str) -> Callable[[Any, Any], None]:
    """The ``__set__`` of a slot: sets a field of a frozen, slotted dataclass
    without the attribute lookup of ``object.__setattr__`` (hot paths only)."""
    setter: Callable[[Any, Any], None] = getattr(cls, name).__set__
    return setter


_SET_SEQ = _slot_setter(Packet, "seq")
_SET_TYPE = _slot_setter(Packet, "type")
_SET_DATA = _slot_setter(Packet, "data")


def _trusted_packet(seq: int, ptype: str, data: bytes) -> Packet:
    """A :class:`Packet` from values already validated by the parser (seq in
    0..63, ``ptype`` a printable letter or its :class:`PacketType`, no MARK in
    ``data``), skipping ``__post_init__`` and the keyword ``__init__``: once
    per packet on the receive path."""
    packet = _new(Packet)
    _SET_SEQ(packet, seq)
    _SET_TYPE(packet, ptype)
    _SET_DATA(packet, data)
    return packet


def packet_length(data_length: int, check: BlockCheck) -> int:
    """Length of a packet from MARK through CHECK for a data field of this size."""
    field = data_length + int(check)
    if field + 2 <= MAX_NORMAL_LEN:
        return NORMAL_HEADER_LENGTH + field
    return EXTENDED_HEADER_LENGTH + field


def data_capacity(max_length: int, check: BlockCheck) -> int:
    """Largest data field whose packet fits in ``max_length`` (MARK through CHECK).

    Raises:
        LocalProtocolError: ``max_length`` is outside
            ``MIN_PACKET_LENGTH..MAX_PACKET_LENGTH`` (12..9031).
    """
    if not MIN_PACKET_LENGTH <= max_length <= MAX_PACKET_LENGTH:
        raise LocalProtocolError(
            f"maximum packet length {max_length} is outside "
            f"{MIN_PACKET_LENGTH}..{MAX_PACKET_LENGTH} (MARK through CHECK)"
        )
    normal = min(max_length - NORMAL_HEADER_LENGTH, MAX_NORMAL_LEN - 2) - int(check)
    extended = max_length - EXTENDED_HEADER_LENGTH - int(check)
    return max(normal, extended)


def build_packet(
    packet: Packet,
    check: BlockCheck = BlockCheck.CRC16,
    *,
    eol: int | None = CR,
    padding: bytes = b"",
) -> bytes:
    """Serialise a packet to wire bytes.

    Args:
        packet: the packet; its data field must already be encoded.
        check: the block check to append (the negotiated one; type 1 for the
            Send-Init exchange unless FORCE-3 was agreed).
        eol: the end-of-line byte appended after the check, or None.
        padding: bytes sent before the MARK when the peer asked for padding.

    Returns:
        ``padding + MARK ... CHECK + EOL``.

    Raises:
        LocalProtocolError: the data field is larger than an extended packet
            can carry (9024 data+check characters).
    """
    data = packet.data
    if check is _CRC16:
        if eol == CR and not padding:
            return _crc16_packet(packet.seq, ord(packet.type), data)
        # The header (MARK through HCHECK) and its CRC depend only on SEQ,
        # TYPE and the field's length, so they are cached; the CRC then
        # continues over the data alone.
        marked, head_crc = _crc16_head(packet.seq, ord(packet.type), len(data))
        crc = _CRC16_FUN(data, head_crc, _CRC16_TABLE)
        c1, c2, c3 = (crc >> 12) + 32, (crc >> 6 & 0x3F) + 32, (crc & 0x3F) + 32
        tail = bytes((c1, c2, c3)) if eol is None else bytes((c1, c2, c3, eol))
        return b"".join((padding, marked, data, tail))
    marked, _ = _header(packet.seq, ord(packet.type), len(data), int(check))
    covered = marked[1:] + data
    tail = check_chars(check, covered)
    if eol is not None:
        tail += bytes((eol,))
    return b"".join((padding, marked, data, tail))


_HEADS: dict[int, tuple[bytes, int]] = {}
_HEADS_BOUND = 4096
"""Cached CRC-16 headers: 64 sequence numbers times the few (type, length)
pairs a sender uses -- a few hundred in practice; cleared when full."""


def _crc16_head(seq: int, type_c: int, data_length: int) -> tuple[bytes, int]:
    """MARK through HCHECK of a CRC-16 packet and the CRC of LEN..HCHECK, cached.

    Raises:
        LocalProtocolError: the field is larger than an extended packet carries.
    """
    key = data_length << 14 | type_c << 6 | seq
    head = _HEADS.get(key)
    if head is None:
        head = _header(seq, type_c, data_length, 3)
        if len(_HEADS) >= _HEADS_BOUND:
            _HEADS.clear()
        _HEADS[key] = head
    return head


def _crc16_packet(seq: int, type_c: int, data: bytes) -> bytes:
    """``build_packet(Packet(seq=seq, type=chr(type_c), data=data))``: CRC-16,
    CR after it, no padding -- for fields the caller has made valid (``seq``
    in 0..63, ``type_c`` printable, no MARK in ``data``: an encoder's output).
    Once per packet on the send path, without the :class:`Packet`.

    Raises:
        LocalProtocolError: the field is larger than an extended packet carries.
    """
    head = _HEADS.get(len(data) << 14 | type_c << 6 | seq)  # (_crc16_head's key, inline)
    if head is None:
        head = _crc16_head(seq, type_c, len(data))
    marked, head_crc = head
    crc = _CRC16_FUN(data, head_crc, _CRC16_TABLE)
    return b"".join((marked, data, _CHECK_HIGH[crc >> 6], _CHECK_LOW_CR[crc & 0x3F]))


_CHECK_HIGH = tuple(bytes(((h >> 6) + 32, (h & 0x3F) + 32)) for h in range(1 << 10))
"""The first two CRC-16 check characters, by the CRC's top ten bits."""
_CHECK_LOW_CR = tuple(bytes((low + 32, CR)) for low in range(64))
"""The third check character and the CR, by the CRC's low six bits."""


def _header(seq: int, type_c: int, data_length: int, check_length: int) -> tuple[bytes, int]:
    """MARK through HCHECK for this packet, and the CRC-16 of its LEN..HCHECK.

    Raises:
        LocalProtocolError: the field is larger than an extended packet carries.
    """
    field = data_length + check_length
    seq_c = seq + 32
    if field + 2 <= MAX_NORMAL_LEN:
        head = bytes((field + 34, seq_c, type_c))
    elif field <= MAX_EXTENDED_FIELD:
        lenx1, lenx2 = field // 95, field % 95
        s = 32 + seq_c + type_c + lenx1 + lenx2 + 64
        hcheck = ((s + ((s & 0xC0) >> 6)) & 0x3F) + 32  # type 1 over LEN..LENX2
        head = bytes((32, seq_c, type_c, lenx1 + 32, lenx2 + 32, hcheck))
    else:
        raise LocalProtocolError(
            f"data field of {data_length} characters exceeds the Kermit maximum packet"
        )
    return b"\x01" + head, _CRC16_FUN(head, 0, _CRC16_TABLE)
