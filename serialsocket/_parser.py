"""Incremental Kermit packet parser (sans-I/O).

Strategy
--------
Feed any chunks with :meth:`PacketParser.receive_data`, then call
:meth:`PacketParser.next_event` until it returns ``None``.  The pull style lets
the layer above change the expected block check between two packets that came
in the same chunk (after the init exchange the check switches from type 1 to
CRC-16, and the very next packet may already be in the buffer).

The parser is built on one fact: the MARK (SOH) never occurs inside a packet.
LEN, SEQ, TYPE and CHECK are printable, and every Kermit encoder prefixes SOH
in data.  So:

* bytes before a MARK are inter-packet filler (CR, LF, NUL padding: silently
  skipped) or garbage (reported as one ``garbage`` rejection per run);
* a MARK inside a packet that is still arriving means the packet was cut short:
  it is rejected as ``truncated`` at once and parsing restarts at that MARK,
  without waiting for bytes that will never come;
* after any rejection the parser discards everything up to the next MARK, so
  one damaged packet costs one rejection event, not a cascade.

Every damaged input is a counted :class:`PacketRejected` event, never an
exception.  The buffer never holds more than one packet of ``max_length`` (or
``init_max_length`` for an init packet) plus the bytes of the last chunk that
follow it.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace

from ._checks import _CRC16_FUN, _CRC16_TABLE, BlockCheck, check_chars
from ._errors import LocalProtocolError
from ._fec import CORRECTED_TYPE, repair, trailer_length
from ._packet import _SET_DATA, _SET_SEQ, _SET_TYPE, Packet, _slot_setter, _trusted_packet
from ._wire import (
    DEFAULT_MAX_PACKET_LENGTH,
    EXTENDED_HEADER_LENGTH,
    MARK,
    MAX_PACKET_LENGTH,
    MIN_PACKET_LENGTH,
    NORMAL_HEADER_LENGTH,
    PacketType,
)

_new = object.__new__

__all__ = [
    "PacketParser",
    "PacketReceived",
    "PacketRejected",
    "ParserEvent",
    "ParserStatistics",
    "RejectReason",
]

_SAMPLE = 256
"""Rejected bytes kept in an event: enough to read a packet trace, bounded for floods."""

_FILLER = b"\r\n\x00"
"""Bytes silently skipped between packets: EOL, LF that some hosts add, NUL padding."""

_INIT_TYPES = frozenset({PacketType.SEND_INIT.value, PacketType.INIT.value})

_SPECIAL_TYPES = frozenset(
    ord(t) for t in (PacketType.SEND_INIT, PacketType.INIT, PacketType.NAK, PacketType.ERROR)
)
"""Type letters whose block check may differ from the one in force (``_checks_for``)."""

_CRC16 = BlockCheck.CRC16
"""(Enum member lookups cost a descriptor call each in Python 3.11.)"""

_CORRECTED_C = ord(CORRECTED_TYPE)

_FAST_TYPE = bytes(
    33 <= c <= 126 and c not in _SPECIAL_TYPES and c != _CORRECTED_C for c in range(256)
)
"""Type bytes the fast path takes: printable, checked with the check in force,
and not a corrected data packet (which may need its repair)."""

_KNOWN = {ord(t.value): t for t in PacketType}
_TYPES: tuple[str, ...] = tuple(_KNOWN.get(c, chr(c)) for c in range(256))
"""The ``Packet.type`` of each type byte: the :class:`PacketType` member, or the letter."""


class RejectReason(enum.StrEnum):
    """Why bytes were dropped; the strings appear in the packet inspector's output."""

    GARBAGE = "garbage"
    """Bytes outside any packet that are not EOL/LF/NUL filler."""
    BAD_LENGTH = "bad length"
    """LEN is not a printable 3..94 (or blank), or too small for the check."""
    BAD_HEADER = "bad header"
    """SEQ or TYPE is not printable, or the extended header check (HCHECK) failed."""
    TOO_LONG = "too long"
    """The packet announces more than ``max_length`` characters."""
    TRUNCATED = "truncated"
    """A new MARK arrived before the packet was complete."""
    BAD_CHECK = "bad check"
    """The block check does not match."""


@dataclass(frozen=True, slots=True, kw_only=True)
class PacketReceived:
    """A packet whose block check verified.

    Attributes:
        packet: the packet (data still prefix-encoded).
        extended: True for the extended (long) format.
        check: the block check that verified it.
        length: characters from MARK through CHECK.
    """

    packet: Packet
    extended: bool
    check: BlockCheck
    length: int


@dataclass(frozen=True, slots=True, kw_only=True)
class PacketRejected:
    """Bytes the parser dropped.

    Attributes:
        reason: why.
        raw: the dropped bytes, at most 256 of them.
        length: how many bytes were dropped in this event.
        seq: the sequence number the damaged packet claimed, if it got that
            far (untrustworthy by definition; for traces only).
        type: likewise, its type letter.
        damaged: with ``correction`` on, a packet whose check failed, whole
            (MARK through CHECK): a repair packet may still mend it
            (PROTOCOL.md 15.6); else None.
    """

    reason: RejectReason
    raw: bytes
    length: int
    seq: int | None = None
    type: str | None = None
    damaged: bytes | None = None


ParserEvent = PacketReceived | PacketRejected


def _received(packet: Packet, extended: bool, check: BlockCheck, length: int) -> PacketReceived:
    """``PacketReceived(...)`` for a packet the parser just verified, through
    the slot descriptors (once per packet on the hot path; the keyword
    ``__init__`` of a frozen dataclass costs twice as much)."""
    event = _new(PacketReceived)
    _SET_PACKET(event, packet)
    _SET_EXTENDED(event, extended)
    _SET_CHECK(event, check)
    _SET_LENGTH(event, length)
    return event


_SET_PACKET = _slot_setter(PacketReceived, "packet")
_SET_EXTENDED = _slot_setter(PacketReceived, "extended")
_SET_CHECK = _slot_setter(PacketReceived, "check")
_SET_LENGTH = _slot_setter(PacketReceived, "length")


@dataclass(frozen=True, slots=True, kw_only=True)
class ParserStatistics:
    """Counters since the parser was created.

    Attributes:
        packets: packets accepted.
        rejected: rejection events, by reason value.
        garbage_bytes: bytes dropped as garbage or as the tail of a rejected
            packet (filler excluded).
        filler_bytes: CR/LF/NUL skipped between packets.
        resyncs: times the parser had to hunt for a new MARK after damage.
        repaired: ``d`` packets whose check failed and that a repair of
            their damage made pass (PROTOCOL.md section 15).
    """

    packets: int
    rejected: dict[str, int]
    garbage_bytes: int
    filler_bytes: int
    resyncs: int
    repaired: int = 0


class PacketParser:
    """Turns a byte stream into :class:`PacketReceived` / :class:`PacketRejected` events.

    Args:
        max_length: the largest packet accepted, MARK through CHECK (the
            negotiated receive maximum).  Longer packets are rejected as
            ``too long`` and bound the buffer.
        check: the block check expected on ordinary packets.
        init_check: the block check of S and I packets: type 1 as Kermit
            requires, or CRC-16 when FORCE-3 ("5") was agreed.
        init_max_length: the largest S or I packet accepted, when larger than
            ``max_length`` (0, the default: ``max_length``): an init may carry
            early data before any length is negotiated (PROTOCOL.md section 13).
        error_fallback: also accept an E packet with a type-1 check while a
            stronger one is in force, as Kermit receivers do (a classic peer
            may send its error that way).  The price: a one-bit error that
            turns a ``D`` into an ``E`` passes the 6-bit checksum about once
            in 64, and a bogus error aborts the transfer.  Peers that always
            send E with the check in force (telelink endpoints, PROTOCOL.md
            section 2) turn it off.
        correction: read ``d`` packets as corrected data packets
            (PROTOCOL.md section 15): one whose check fails is repaired
            where its sums say (:func:`serialsocket._fec.repair`) and taken
            if the check then passes; either way it is delivered as the
            ``D`` packet it carries, its sums removed.  Off (the default, and
            until the init exchange agrees on it), a ``d`` is an unknown
            type letter like any other.

    ``check``, ``init_check``, ``max_length`` and ``correction`` may be
    changed between calls to :meth:`next_event`; the change applies to the
    next packet.
    """

    def __init__(
        self,
        *,
        max_length: int = DEFAULT_MAX_PACKET_LENGTH,
        check: BlockCheck = BlockCheck.CRC16,
        init_check: BlockCheck = BlockCheck.SUM6,
        init_max_length: int = 0,
        error_fallback: bool = True,
        correction: bool = False,
    ) -> None:
        self.max_length = max_length
        self.correction = correction
        self.init_max_length = init_max_length
        self.check = check
        self.init_check = init_check
        self.error_fallback = error_fallback
        # The unparsed bytes are _buf[_pos:]: parsing moves _pos and slices
        # packets straight out of an immutable buffer; receive_data drops the
        # consumed prefix when it appends.
        self._buf = b""
        self._pos = 0
        self._discarding = False
        self._packets = 0
        self._rejected: dict[str, int] = {}
        self._garbage = 0
        self._filler = 0
        self._resyncs = 0
        self._repaired = 0

    @property
    def max_length(self) -> int:
        """Largest packet accepted, MARK through CHECK."""
        return self._max_length

    @max_length.setter
    def max_length(self, value: int) -> None:
        if not MIN_PACKET_LENGTH <= value <= MAX_PACKET_LENGTH:
            raise LocalProtocolError(
                f"max_length {value} is outside {MIN_PACKET_LENGTH}..{MAX_PACKET_LENGTH}"
            )
        self._max_length = value

    @property
    def buffered(self) -> int:
        """Bytes held waiting for the rest of a packet."""
        return len(self._buf) - self._pos

    def receive_data(self, data: bytes | bytearray | memoryview) -> None:
        """Append bytes from the line.  Call :meth:`next_event` until it returns None."""
        if self._pos:
            self._buf = self._buf[self._pos :] + data
            self._pos = 0
        else:
            self._buf += data

    def next_event(self) -> ParserEvent | None:
        """The next packet or rejection, or None when more bytes are needed."""
        buf = self._buf
        n = len(buf)
        pos = self._pos
        if n - pos > 7 and self.check is _CRC16:
            fast = self._next_fast(buf, n, pos)
            if fast is not None:
                return fast
        while (pos := self._pos) < n:
            if buf[pos] != MARK:
                event = self._skip_to_mark()
                if event is not None:
                    return event
                continue
            self._discarding = False
            if n - pos < 2:
                return None
            ln = buf[pos + 1]
            if 35 <= ln <= 126:
                total: int | None = ln - 30
                if ln - 30 > self._max_length:
                    if n - pos < 4:
                        return None  # the type decides the limit: wait for it
                    if ln - 30 > self._limit(buf[pos + 3]):
                        return self._reject(RejectReason.TOO_LONG, 1)
            else:
                frame = self._extended_length()
                if isinstance(frame, PacketRejected):
                    return frame
                total = frame
            # A MARK inside the frame (or inside what has arrived of it) means
            # this packet was cut short on the line.
            stop = n if total is None else min(n, pos + total)
            cut = buf.find(MARK, pos + 1, stop)
            if cut > 0:
                return self._reject(RejectReason.TRUNCATED, cut - pos)
            if total is None or n - pos < total:
                return None
            return self._finish(total)
        return None

    def _next_fast(self, buf: bytes, n: int, pos: int) -> PacketReceived | None:
        """The common case in one straight run: [EOL] then a whole, valid packet
        under CRC-16 whose type takes the check in force.  Anything else
        (damage, a partial packet, S/I/N/E, other checks) returns None and
        :meth:`next_event` takes its general path from where this left off.
        """
        if buf[pos] != MARK:
            # The EOL after the previous packet, with a MARK right behind it.
            if buf[pos] not in _FILLER or buf[pos + 1] != MARK:
                return None
            self._filler += 1
            pos += 1
            self._pos = pos
        ln, seq_c, type_c = buf[pos + 1], buf[pos + 2], buf[pos + 3]
        if 35 <= ln <= 126:
            end = pos + ln - 30
            start = pos + NORMAL_HEADER_LENGTH
        elif ln == 32 and n - pos > EXTENDED_HEADER_LENGTH:
            lenx1, lenx2 = buf[pos + 4], buf[pos + 5]
            s = 32 + seq_c + type_c + lenx1 + lenx2
            if not (32 <= lenx1 <= 126 and 32 <= lenx2 <= 126) or (
                buf[pos + 6] != ((s + ((s & 0xC0) >> 6)) & 0x3F) + 32
            ):
                return None
            end = pos + EXTENDED_HEADER_LENGTH + (lenx1 - 32) * 95 + (lenx2 - 32)
            start = pos + EXTENDED_HEADER_LENGTH
        else:
            return None
        if (
            end > n
            or end - pos > self._max_length
            or end - start < 3
            or not 32 <= seq_c <= 95
            or not _FAST_TYPE[type_c]
            or buf.find(MARK, pos + 1, end) >= 0
        ):
            return None
        crc = _CRC16_FUN(buf[pos + 1 : end - 3], 0, _CRC16_TABLE)
        if (
            buf[end - 3] != (crc >> 12) + 32
            or buf[end - 2] != (crc >> 6 & 0x3F) + 32
            or buf[end - 1] != (crc & 0x3F) + 32
        ):
            return None
        self._pos = end
        self._discarding = False
        self._packets += 1
        # _received(_trusted_packet(...)) written out: this is once per packet.
        packet = _new(Packet)
        _SET_SEQ(packet, seq_c - 32)
        _SET_TYPE(packet, _TYPES[type_c])
        _SET_DATA(packet, buf[start : end - 3])
        event = _new(PacketReceived)
        _SET_PACKET(event, packet)
        _SET_EXTENDED(event, ln == 32)
        _SET_CHECK(event, _CRC16)
        _SET_LENGTH(event, end - pos)
        return event

    def statistics(self) -> ParserStatistics:
        """A snapshot of the counters."""
        return ParserStatistics(
            packets=self._packets,
            rejected=dict(self._rejected),
            garbage_bytes=self._garbage,
            filler_bytes=self._filler,
            resyncs=self._resyncs,
            repaired=self._repaired,
        )

    def reset(self) -> None:
        """Drop any partial packet (e.g. when a connection is torn down)."""
        self._buf = b""
        self._pos = 0
        self._discarding = False

    # -- internals ---------------------------------------------------------------

    def _skip_to_mark(self) -> PacketRejected | None:
        buf, pos = self._buf, self._pos
        i = buf.find(MARK, pos)
        end = len(buf) if i < 0 else i
        self._pos = end
        if end - pos == 1 and buf[pos] in _FILLER:
            # The EOL after each packet: the common case, kept cheap.
            self._filler += 1
            return None
        chunk = buf[pos:end]
        noise = chunk.translate(None, _FILLER)
        self._filler += end - pos - len(noise)
        if not noise:
            return None
        self._garbage += len(noise)
        if self._discarding:
            return None
        self._discarding = True
        self._resyncs += 1
        return self._event(RejectReason.GARBAGE, chunk[:_SAMPLE], len(chunk))

    def _extended_length(self) -> int | PacketRejected | None:
        """Total length MARK..CHECK announced by an extended header (or a bad
        LEN), a rejection, or None while the extended header is incomplete."""
        buf, pos = self._buf, self._pos
        if buf[pos + 1] != 32:
            return self._reject(RejectReason.BAD_LENGTH, 1)
        if len(buf) - pos < EXTENDED_HEADER_LENGTH:
            return None
        lenx1, lenx2 = buf[pos + 4], buf[pos + 5]
        s = 32 + buf[pos + 2] + buf[pos + 3] + lenx1 + lenx2
        # LENX1/LENX2 must be tochar(0..94): a 6-bit HCHECK alone lets one
        # damaged header in 64 through, and a control character there would
        # give a negative length.  HCHECK is type 1 over LEN..LENX2, inline.
        if not (32 <= lenx1 <= 126 and 32 <= lenx2 <= 126) or (
            buf[pos + 6] != ((s + ((s & 0xC0) >> 6)) & 0x3F) + 32
        ):
            return self._reject(RejectReason.BAD_HEADER, 1)
        total = EXTENDED_HEADER_LENGTH + (lenx1 - 32) * 95 + (lenx2 - 32)
        if total > self._limit(buf[pos + 3]):
            return self._reject(RejectReason.TOO_LONG, 1)
        return total

    def _limit(self, type_byte: int) -> int:
        """The longest packet of this type accepted."""
        if chr(type_byte) in _INIT_TYPES:
            return max(self._max_length, self.init_max_length)
        return self._max_length

    def _finish(self, total: int) -> ParserEvent:
        buf, pos = self._buf, self._pos
        end = pos + total
        extended = buf[pos + 1] == 32
        seq_c, type_c = buf[pos + 2], buf[pos + 3]
        start = pos + (EXTENDED_HEADER_LENGTH if extended else NORMAL_HEADER_LENGTH)
        if type_c == _CORRECTED_C and self.correction:
            # (Its SEQ is checked once repaired: the sums cover it.)
            return self._finish_corrected(total, extended, start)
        if not (32 <= seq_c <= 95 and 33 <= type_c <= 126):
            return self._reject(RejectReason.BAD_HEADER, total)
        ptype = _TYPES[type_c]
        check = self.check
        if check is _CRC16 and type_c not in _SPECIAL_TYPES and end - start >= 3:
            # The common case, inline: a data or ACK packet under CRC-16.
            crc = _CRC16_FUN(buf[pos + 1 : end - 3], 0, _CRC16_TABLE)
            if (
                buf[end - 3] == (crc >> 12) + 32
                and buf[end - 2] == (crc >> 6 & 0x3F) + 32
                and buf[end - 1] == (crc & 0x3F) + 32
            ):
                self._pos = end
                self._packets += 1
                return _received(
                    _trusted_packet(seq_c - 32, ptype, buf[start : end - 3]),
                    extended,
                    check,
                    total,
                )
            return self._reject(RejectReason.BAD_CHECK, total)
        candidates = self._checks_for(ptype, end - start, extended)
        if not candidates:
            return self._reject(RejectReason.BAD_LENGTH, total)
        for check in candidates:
            k = int(check)
            if check_chars(check, buf[pos + 1 : end - k]) == buf[end - k : end]:
                self._pos = end
                self._packets += 1
                return _received(
                    _trusted_packet(seq_c - 32, ptype, buf[start : end - k]),
                    extended,
                    check,
                    total,
                )
        return self._reject(RejectReason.BAD_CHECK, total)

    def _finish_corrected(self, total: int, extended: bool, start: int) -> ParserEvent:
        """A ``d`` packet (``correction`` on): as it came if its check passes,
        else repaired if a repair passes it; delivered as a ``D`` without its
        sums, or rejected as a bad check (or bad length: no room for sums)."""
        buf, pos = self._buf, self._pos
        end = pos + total
        check = self.check
        k = int(check)
        sums = trailer_length(total, k)
        if end - start < k + sums:
            return self._reject(RejectReason.BAD_LENGTH, total)
        raw = buf[pos:end]
        if check_chars(check, raw[1 : total - k]) != raw[total - k :]:
            # A repair is one more try of the check: only under a CRC.
            fixed = repair(raw, check) if k >= 3 else None
            if fixed is None:
                return self._reject(RejectReason.BAD_CHECK, total)
            if not 32 <= fixed[2] <= 95:
                return self._reject(RejectReason.BAD_HEADER, total)
            raw = fixed
            self._repaired += 1
        elif not 32 <= raw[2] <= 95:
            return self._reject(RejectReason.BAD_HEADER, total)
        self._pos = end
        self._packets += 1
        return _received(
            _trusted_packet(raw[2] - 32, PacketType.DATA, raw[start - pos : total - k - sums]),
            extended,
            check,
            total,
        )

    def _checks_for(self, ptype: str, field: int, extended: bool) -> list[BlockCheck]:
        """Block checks to try, in order, for a packet of this type and field size."""
        if ptype in _INIT_TYPES:
            first = self.init_check
        elif ptype == PacketType.NAK and not extended and 1 <= field <= 3:
            # A NAK has no data, so its check length is LEN - 2 (ckcfn2.c rpack):
            # this keeps NAKs readable while the two sides disagree on the check.
            first = BlockCheck(field)
        else:
            first = self.check
        order = [first]
        if self.error_fallback and ptype == PacketType.ERROR and first is not BlockCheck.SUM6:
            # Peers may send E with a type-1 check whatever is in force (ckcfn2.c).
            order.append(BlockCheck.SUM6)
        return [c for c in order if int(c) <= field]

    def _reject(self, reason: RejectReason, upto: int) -> PacketRejected:
        # Every rejection consumes at least the MARK, so the parser always progresses.
        upto = max(upto, 1)
        buf, pos = self._buf, self._pos
        raw = buf[pos : pos + upto]
        avail = len(buf) - pos
        seq = buf[pos + 2] - 32 if avail > 2 and 32 <= buf[pos + 2] <= 95 else None
        ptype = chr(buf[pos + 3]) if avail > 3 and 33 <= buf[pos + 3] <= 126 else None
        self._pos = pos + upto
        self._garbage += upto
        self._discarding = True
        self._resyncs += 1
        event = self._event(reason, raw[:_SAMPLE], upto, seq=seq, ptype=ptype)
        if reason is RejectReason.BAD_CHECK and self.correction:
            return replace(event, damaged=bytes(raw))
        return event

    def _event(
        self,
        reason: RejectReason,
        raw: bytes,
        length: int,
        *,
        seq: int | None = None,
        ptype: str | None = None,
    ) -> PacketRejected:
        self._rejected[reason.value] = self._rejected.get(reason.value, 0) + 1
        return PacketRejected(reason=reason, raw=raw, length=length, seq=seq, type=ptype)
