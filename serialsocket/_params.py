"""The init exchange: each side's parameters and their negotiation.

The init packet (``I``, seq 0) and its acceptance (``Y``, seq 0) carry the same
Kermit Send-Init layout (reference/kermit.md section 4), so a Kermit tracer
reads them; telelink adds its own fields after SYSID.  Every field says what
*I* want *you* to do when sending to me:

====  =========  ==========================================================
 #    field      telelink's value
====  =========  ==========================================================
 1    MAXL       tochar(min(94, max_packet_length - 2)): longest normal LEN
 2    TIME       tochar(timeout hint in s, clamped to 0..94)
 3    NPAD       tochar(0)
 4    PADC       ctl(NUL) = ``@``
 5    EOL        tochar(CR) = ``-``
 6    QCTL       ``#``
 7    QBIN       ``&`` (printable profile: I want 8th-bit prefixing) or ``Y``
 8    CHKT       ``5`` for CRC-16 on every packet (FORCE-3), else ``1``/``2``
 9    REPT       ``~`` or space (no repeat counts)
 10   CAPAS      tochar(2 | 4): long packets, sliding windows
 11   WINDO      tochar(window)
 12   MAXLX1/2   tochar(n // 95), tochar(n % 95), n = max_packet_length - 7
 14   CHKPNT     ``0``
 15   CHKINT     ``___``
 18   WHATAMI    tochar(32): field valid, no flags
 19   SYSID      ``"TL`` (length 2, "TL" = telelink)
 20   WHATAMI2   tochar(32)
 21   VERSION    tochar(protocol version)
 22   TIMEOUT    three base-95 chars: the initial timeout hint in milliseconds
 23   XCAPAS     tochar(extensions offered): 1 = long sequence numbers,
                 2 = dense escape code (8-bit line), 4 = dense radix-91
                 packing (printable line), 8 = CRC-32, 16 = expedited
                 lane, 32 = escape XON/XOFF too
 24   XWINDO     three chars, tochar of 6 bits each, most significant first:
                 the window offered with long sequence numbers (with XCAPAS 1)
 25   XLANES     tochar(further lanes offered): 1 = the latest-value lane,
                 2 = early data, 4 = a first flight, 8 = corrected data
                 packets (with XCAPAS 16, after XWINDO when that is
                 present)
 26   XEARLY     only in an ``I`` with XLANES bit 2: two chars, tochar of 6
                 bits each, most significant first: the number ``n`` of
                 characters that follow, then ``n`` characters: the first
                 bytes of the stream, prefix-encoded as the classic
                 printable profile (``#``, ``&``, no repeat counts)
 27   XFLIGHT    only in an ``I`` with XLANES bit 4 (PROTOCOL.md 14): five
                 chars: tochar(k), the most packets of the first flight;
                 two chars (6 bits each) of its longest packet; two chars
                 (6 bits each) of the request's 12-bit nonce
====  =========  ==========================================================

MAXLX counts DATA+CHECK characters, as in C-Kermit; our lengths count MARK
through CHECK, so n = length - 7 exactly, with no hidden safety margin.

XCAPAS and XWINDO (PROTOCOL.md sections 9 and 10) extend protocol version 1
compatibly: an endpoint that stops reading after TIMEOUT sees no extension
offered, and an extension is used only when both sides offer it.  A
listener's answer carries XCAPAS only when the request did (:meth:`answer`),
so a peer that sends none gets exactly the classic 26-character answer.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

from ._checks import BlockCheck
from ._dense import XON_XOFF, EscapeEncoding, Radix91Encoding
from ._encoding import Encoding
from ._errors import RemoteProtocolError
from ._wire import MAX_PACKET_LENGTH, MIN_PACKET_LENGTH, ctl, tochar, unchar

__all__ = [
    "DENSE_FEATURES",
    "EARLY_ENCODING",
    "EARLY_INIT_LIMIT",
    "FEATURE_CRC32",
    "FEATURE_ESCAPE",
    "FEATURE_EXPEDITED",
    "FEATURE_RADIX91",
    "FEATURE_XON_XOFF",
    "LANE_CORRECTION",
    "LANE_EARLY",
    "LANE_FLIGHT",
    "LANE_LATEST",
    "LONG_SEQ_MODULUS",
    "MAX_FLIGHT_LENGTH",
    "MAX_FLIGHT_PACKETS",
    "MAX_LONG_WINDOW",
    "PROTOCOL_VERSION",
    "RESIDUAL_ERROR_TARGET",
    "DataCodec",
    "Flight",
    "InitParameters",
    "Negotiated",
    "crc32_wanted",
    "decode18",
    "encode18",
    "flight_format",
    "negotiate",
    "self_agreement",
]

PROTOCOL_VERSION = 1
"""Bumped on any incompatible change to the wire protocol in PROTOCOL.md."""

LONG_SEQ_MODULUS = 64**3
"""Sequence numbers are mod 262144 (18 bits) when both sides offer long ones:
the packet's SEQ character carries the low 6 bits, two characters at the head
of the data field the rest (PROTOCOL.md section 9)."""

MAX_LONG_WINDOW = LONG_SEQ_MODULUS // 2 - 1
"""Largest window with long sequence numbers: less than half the space, so a
receiver tells the current window from the previous one (131071 packets)."""

_CAP_MORE, _CAP_LONG, _CAP_WINDOWS = 1, 2, 4
_XCAP_LONG_SEQ = 1

FEATURE_ESCAPE = 2
"""XCAPAS bit: I decode the dense escape code (serialsocket/DENSE.md section 1)."""
FEATURE_RADIX91 = 4
"""XCAPAS bit: I decode the radix-91 packing (serialsocket/DENSE.md section 2)."""
FEATURE_CRC32 = 8
"""XCAPAS bit: I want CRC-32 on every packet after the init exchange (when
CRC-16 misses the residual-error target, PROTOCOL.md 10.5).  Every endpoint
that sets any of bits 2, 4, 8 decodes CRC-32, so the wish of either side is
granted when both set one of them."""
FEATURE_EXPEDITED = 16
"""XCAPAS bit: I speak the expedited lane (PROTOCOL.md section 11); agreed when
both set it."""
FEATURE_XON_XOFF = 32
"""XCAPAS bit: my line uses software flow control: the escape code must
escape XON/XOFF (:data:`~serialsocket._dense.XON_XOFF`) too."""
LANE_LATEST = 1
"""XLANES bit (the field after XCAPAS and XWINDO, sent with XCAPAS bit 16): I
speak the latest-value lane (PROTOCOL.md section 12); agreed when both set it."""
LANE_EARLY = 2
"""XLANES bit, early data (PROTOCOL.md section 13).  In an ``I``: the first
bytes of my stream follow in the XEARLY field.  In a listener's own
parameters: I take early data.  In a ``Y``: your early data was delivered, all
of it (nothing was delivered when the bit is clear)."""
LANE_FLIGHT = 4
"""XLANES bit, the first flight (PROTOCOL.md section 14).  In an ``I``: data
packets follow it before any answer, cut as if the listener agreed to my
offer (:func:`self_agreement`); the XFLIGHT field bounds them.  In a ``Y``:
your first flight was taken: every packet of it is data of this connection
(clear: none is, and your data starts again at sequence number k + 1).
Nowhere else."""
LANE_CORRECTION = 8
"""XLANES bit, corrected data packets (PROTOCOL.md section 15): I read ``d``
packets (a ``D`` whose data is followed by sums that repair one damaged
character per block); agreed when both set it, and then either side may send
them."""
MAX_FLIGHT_PACKETS = 31
"""The most packets a first flight may declare: within any window a telelink
endpoint offers, and within half the short sequence space."""
MAX_FLIGHT_LENGTH = 64 * 64 - 1
"""The longest first-flight packet XFLIGHT can announce (12 bits)."""
EARLY_INIT_LIMIT = 1024
"""The longest ``I`` a listener accepts whatever its own maximum packet length
(MARK through CHECK): room for early data before any length is negotiated."""
EARLY_ENCODING = Encoding(rept=None)
"""Early data's encoding: the classic printable profile, fixed (nothing is
negotiated yet), without repeat counts (so a byte count never splits a run)."""
_EARLY_FIELD_MAX = 64 * 64 - 1
DENSE_FEATURES = FEATURE_ESCAPE | FEATURE_RADIX91
"""What a telelink endpoint of this version decodes: offered with
``EndpointConfig(dense=True)``."""
_KNOWN_FEATURES = DENSE_FEATURES | FEATURE_CRC32 | FEATURE_XON_XOFF | FEATURE_EXPEDITED

DataCodec = Encoding | EscapeEncoding | Radix91Encoding
"""A data-field encoding: ``encode_fields`` on the sending side,
``decode_fields`` on the receiving side (the same interface on all three)."""
_SYSID = b"TL"


RESIDUAL_ERROR_TARGET = 1e-12
"""At most one undetected damaged byte per 10^12 delivered (PROTOCOL.md 10.3)."""

DESIGN_BYTE_ERROR_RATE = 1e-5
"""The byte damage rate the CRC-32 rule assumes when nothing is measured: the
worst rate at which a 128-character packet still gets through 99.9 % of the
time (PROTOCOL.md 10.3)."""

CRC16_HD4_LIMIT = 4093
"""Longest covered length (bytes) for which CRC-16/KERMIT catches every two-bit
error (Hamming distance 4); beyond it two flips 32 767 bits apart pass."""


def crc32_wanted(max_packet_length: int, byte_error_rate: float = DESIGN_BYTE_ERROR_RATE) -> bool:
    """Whether CRC-16 misses :data:`RESIDUAL_ERROR_TARGET` at this packet length.

    Undetected errors per delivered byte with an ``r``-bit CRC are about
    ``N q^2 / 2^(r+1)`` for ``N`` wire characters per packet and byte damage
    rate ``q`` (PROTOCOL.md 10.3), so CRC-16 suffices while
    ``N q^2 <= 2^17 x target``, and never past its HD-4 length.
    """
    n = max_packet_length + 1
    return (
        max_packet_length > CRC16_HD4_LIMIT
        or n * byte_error_rate**2 > 2**17 * RESIDUAL_ERROR_TARGET
    )


def encode18(n: int) -> bytes:
    """Three printable characters for an 18-bit number, most significant first."""
    return bytes((tochar(n >> 12 & 63), tochar(n >> 6 & 63), tochar(n & 63)))


def decode18(chars: bytes | bytearray | memoryview) -> int | None:
    """The number three :func:`encode18` characters carry, or None if any is not one."""
    if len(chars) != 3:
        return None
    a, b, c = (unchar(x) for x in chars)
    if not (0 <= a < 64 and 0 <= b < 64 and 0 <= c < 64):
        return None
    return a << 12 | b << 6 | c


_TIMEOUT_MS_MAX = 95**3 - 1
TIMEOUT_HINT_MAX = _TIMEOUT_MS_MAX / 1000
"""The longest initial timeout the TIMEOUT field carries (857.374 s): a
sender whose own is longer says this."""


@dataclass(frozen=True, slots=True, kw_only=True)
class InitParameters:
    """One side's init fields, decoded.

    Attributes:
        max_packet_length: longest packet I receive, MARK through CHECK.
        window: window slots I offer, 1..31.
        check: block check I ask for (CHKT ``5`` decodes as CRC16 + force).
        force_check: True when CHKT was ``5`` (CRC on the init packets too).
        qbin: ``&``-style prefix I want, ``Y`` (I agree if you want one) or ``N``.
        rept: repeat prefix I propose, or None.
        qctl: the control prefix I will use.
        timeout_hint: my initial timeout in seconds (telelink field; None from
            other Kermits).
        version: telelink protocol version, or None for a non-telelink peer.
        long_window: the window I offer with long sequence numbers
            (1..:data:`MAX_LONG_WINDOW`), or None: I do not offer them.
        features: the other XCAPAS bits (:data:`FEATURE_ESCAPE` ...), or
            None when the init carries no XCAPAS at all (a classic or older
            peer; then nothing of PROTOCOL.md section 10 is used).  Bits this
            version does not know are kept as received and never agreed.
        lanes: the XLANES bits (:data:`LANE_LATEST`, :data:`LANE_EARLY`), or
            None when the init carries no XLANES (it needs XCAPAS bit 16: an
            older telelink sends none, and reads past what it does not know).
        early: the early data an ``I`` carries (XEARLY, with
            :data:`LANE_EARLY`), or None.
        flight: the first flight an ``I`` announces (XFLIGHT, with
            :data:`LANE_FLIGHT`), or None.
    """

    max_packet_length: int
    window: int
    check: BlockCheck
    force_check: bool
    qbin: int
    rept: int | None
    qctl: int = ord("#")
    timeout_hint: float | None = None
    version: int | None = PROTOCOL_VERSION
    long_window: int | None = None
    features: int | None = None
    lanes: int | None = None
    early: bytes | None = None
    flight: Flight | None = None

    @classmethod
    def mine(
        cls,
        *,
        max_packet_length: int,
        window: int,
        check: BlockCheck,
        encoding: Encoding | None,
        timeout_hint: float,
        long_window: int | None = None,
        features: int | None = None,
        lanes: int | None = None,
    ) -> InitParameters:
        """The parameters an endpoint with this configuration offers.

        ``features`` are the XCAPAS bits offered besides long sequence
        numbers (None, the default: no XCAPAS, the classic init;
        ``EndpointConfig.init_features()`` gives an endpoint's).  An
        ``encoding`` of None (left to the line) offers the printable profile.  CRC-32 is added when
        ``check`` is :data:`BlockCheck.CRC32` or :func:`crc32_wanted` says the
        packet length needs it; the classic fields then still ask for CRC-16
        (CHKT ``5``), which is what a peer that does not agree uses.
        """
        if encoding is None:
            encoding = Encoding()  # left to a line nobody looked at: printable
        if (
            features is not None
            and features & DENSE_FEATURES
            and (check is BlockCheck.CRC32 or crc32_wanted(max_packet_length))
        ):
            features |= FEATURE_CRC32
        return cls(
            max_packet_length=max_packet_length,
            window=window,
            check=BlockCheck.CRC16 if check is BlockCheck.CRC32 else check,
            force_check=check in (BlockCheck.CRC16, BlockCheck.CRC32),
            qbin=encoding.qbin if encoding.qbin is not None else ord("Y"),
            rept=encoding.rept,
            qctl=encoding.qctl,
            timeout_hint=timeout_hint,
            long_window=long_window,
            features=features,
            lanes=lanes if features is not None and features & FEATURE_EXPEDITED else None,
        )

    def answer(self, theirs: InitParameters, long_window: int | None) -> InitParameters:
        """What a listener with these parameters answers to ``theirs``.

        XCAPAS is echoed only if the request carried one (a peer that sends
        none gets the classic answer) and this side offers features at all
        (``features`` not None), with the features both sides know --
        so the answer never claims an encoding the requester did not offer --
        plus CRC-32 when either side asks for it.  Long sequence numbers:
        ``long_window`` when the requester offered them.  XLANES: the lanes
        both speak, when both sent the field and the expedited lane is agreed.
        """
        features = None
        lanes = None
        if theirs.features is not None and self.features is not None:
            # Encodings: what both decode.  CRC-32 and XON/XOFF: wishes and
            # declarations, mine and (CRC-32) the requester's echoed.
            # CRC-32 only from a side that decodes it (one that sets 2, 4 or 8).
            speaks = self.features & (DENSE_FEATURES | FEATURE_CRC32)
            features = (
                (self.features & theirs.features & (DENSE_FEATURES | FEATURE_EXPEDITED))
                | ((self.features | theirs.features) & FEATURE_CRC32 if speaks else 0)
                | (self.features & FEATURE_XON_XOFF)
            )
            if features & FEATURE_EXPEDITED and None not in (self.lanes, theirs.lanes):
                lanes = (self.lanes or 0) & (theirs.lanes or 0)
        return dataclasses.replace(
            self,
            features=features,
            lanes=lanes,
            early=None,
            flight=None,
            long_window=long_window if theirs.long_window is not None else None,
        )

    def with_early(self, data: bytes) -> InitParameters:
        """These parameters as an ``I`` that carries ``data`` as early data
        (none, when ``data`` is empty or no XLANES field goes out)."""
        if self.lanes is None:
            return self
        if not data:
            return dataclasses.replace(self, lanes=self.lanes & ~LANE_EARLY, early=None)
        return dataclasses.replace(self, lanes=self.lanes | LANE_EARLY, early=bytes(data))

    @property
    def timeout_at_least(self) -> bool:
        """The TIMEOUT field is at its largest value: the sender's initial
        timeout is that or longer (the field cannot say more)."""
        return (self.timeout_hint or 0.0) >= TIMEOUT_HINT_MAX

    def with_flight(self, flight: Flight | None) -> InitParameters:
        """These parameters as an ``I`` that announces ``flight`` (none: the
        bit clear), or, with ``flight`` None, as an answer that says the
        requester's first flight was not taken."""
        if self.lanes is None:
            return self
        if flight is None:
            return dataclasses.replace(self, lanes=self.lanes & ~LANE_FLIGHT, flight=None)
        return dataclasses.replace(self, lanes=self.lanes | LANE_FLIGHT, flight=flight)

    def without_early(self) -> InitParameters:
        """These parameters with no early data and the bit clear: the answer
        of a side that does not deliver the other's early data."""
        return self.with_early(b"")

    def encode(self) -> bytes:
        """The init data field (all printable, no prefixing needed)."""
        n = self.max_packet_length - 7
        ms = min(max(round((self.timeout_hint or 0.0) * 1000), 0), _TIMEOUT_MS_MAX)
        fields = [
            tochar(min(94, self.max_packet_length - 2)),
            tochar(min(94, max(0, round(self.timeout_hint or 0)))),
            tochar(0),
            ctl(0),
            tochar(13),
            self.qctl,
            self.qbin,
            ord("5") if self.force_check else ord(str(int(self.check))),
            self.rept if self.rept is not None else 32,
            tochar(_CAP_LONG | _CAP_WINDOWS),
            tochar(self.window),
            tochar(n // 95),
            tochar(n % 95),
            ord("0"),
            *b"___",
            tochar(32),
            tochar(len(_SYSID)),
            *_SYSID,
            tochar(32),
            tochar(self.version or 0),
            tochar(ms // 9025),
            tochar(ms // 95 % 95),
            tochar(ms % 95),
        ]
        # Without an offer the init stays 26 characters (the classic init).
        if self.long_window is not None or self.features is not None:
            xcaps = (self.features or 0) & ~_XCAP_LONG_SEQ
            if self.long_window is not None:
                xcaps |= _XCAP_LONG_SEQ
            fields.append(tochar(xcaps))
            if self.long_window is not None:
                fields += encode18(self.long_window)
            if xcaps & FEATURE_EXPEDITED and self.lanes is not None:
                fields.append(tochar(self.lanes))
                if self.lanes & LANE_EARLY and self.early is not None:
                    encoded = EARLY_ENCODING.encode(self.early)
                    if len(encoded) > _EARLY_FIELD_MAX:
                        raise ValueError(f"early data encodes to {len(encoded)} characters")
                    fields += (tochar(len(encoded) >> 6), tochar(len(encoded) & 63))
                    fields += encoded
                if self.lanes & LANE_FLIGHT and self.flight is not None:
                    fields += self.flight.encode()
        return bytes(fields)

    @classmethod
    def decode(cls, data: bytes) -> InitParameters:
        """Parse a peer's init field; missing trailing fields take Kermit defaults.

        Raises:
            RemoteProtocolError: a field is out of its legal range.
        """

        def at(i: int, default: int) -> int:
            return data[i] if i < len(data) else default

        def bad(what: str) -> RemoteProtocolError:
            return RemoteProtocolError(
                f"init packet: bad {what} in {data!r}", error_hint=f"Bad init field: {what}"
            )

        maxl = unchar(at(0, tochar(80)))
        if maxl < 10:
            maxl = 80  # Kermit treats MAXL < 10 as the default (ckcfns.c spar).
        if maxl > 94:
            raise bad("MAXL")
        qctl = at(5, ord("#"))
        qbin = at(6, ord("N"))
        chkt = at(7, ord("1"))
        if chkt not in b"1235":
            raise bad("CHKT")
        rept_c = at(8, 32)
        rept = rept_c if (33 <= rept_c <= 62 or 96 <= rept_c <= 126) else None
        i = 9
        caps = 0
        shift = 0
        while i < len(data):
            c = unchar(data[i])
            if not 0 <= c <= 94:
                raise bad("CAPAS")
            if shift == 0:
                caps = c
            i += 1
            shift += 1
            if not c & _CAP_MORE:
                break
        window = unchar(at(i, tochar(1))) if caps & _CAP_WINDOWS else 1
        if not 1 <= window <= 32:
            raise bad("WINDO")
        window = min(window, 31)
        max_len = maxl + 2
        if caps & _CAP_LONG and i + 2 < len(data):
            n = unchar(data[i + 1]) * 95 + unchar(data[i + 2])
            if n < 0:
                raise bad("MAXLX")
            max_len = min(max(n + 7, MIN_PACKET_LENGTH), MAX_PACKET_LENGTH)
        j = i + 3 + 1 + 3 + 1  # CHKPNT, CHKINT, WHATAMI
        version = None
        timeout_hint = None
        long_window = None
        features = None
        lanes = None
        early = None
        flight = None
        if j < len(data):
            sysid_len = unchar(data[j])
            sysid = data[j + 1 : j + 1 + sysid_len]
            k = j + 1 + max(sysid_len, 0) + 1  # skip WHATAMI2
            if sysid == _SYSID and k + 3 < len(data):
                version = unchar(data[k])
                a, b, c = (unchar(x) for x in data[k + 1 : k + 4])
                if min(a, b, c) < 0 or max(a, b, c) > 94:
                    raise bad("TIMEOUT")
                timeout_hint = (a * 9025 + b * 95 + c) / 1000
                if k + 4 < len(data):
                    xcaps = unchar(data[k + 4])
                    if not 0 <= xcaps <= 94:
                        raise bad("XCAPAS")
                    features = xcaps & ~_XCAP_LONG_SEQ
                    if xcaps & _XCAP_LONG_SEQ:
                        long_window = decode18(data[k + 5 : k + 8])
                        if long_window is None or not 1 <= long_window <= MAX_LONG_WINDOW:
                            raise bad("XWINDO")
                    at_lanes = k + (8 if xcaps & _XCAP_LONG_SEQ else 5)
                    if xcaps & FEATURE_EXPEDITED and at_lanes < len(data):
                        lanes = unchar(data[at_lanes])
                        if not 0 <= lanes <= 94:
                            raise bad("XLANES")
                        rest = data[at_lanes + 1 :]
                        if lanes & LANE_EARLY and rest:
                            early, rest = _decode_early(rest, bad)
                            if rest and not lanes & LANE_FLIGHT:
                                raise bad("XEARLY")  # the count must match
                        if lanes & LANE_FLIGHT and rest:
                            # (Characters after it: a later version's fields.)
                            flight = Flight.decode(rest, bad)
        return cls(
            max_packet_length=max(max_len, MIN_PACKET_LENGTH),
            window=window,
            check=BlockCheck(3 if chkt == ord("5") else chkt - ord("0")),
            force_check=chkt == ord("5"),
            qbin=qbin,
            rept=rept,
            qctl=qctl,
            timeout_hint=timeout_hint,
            version=version,
            long_window=long_window,
            features=features,
            lanes=lanes,
            early=early,
            flight=flight,
        )


def _decode_early(field: bytes, bad: Callable[[str], RemoteProtocolError]) -> tuple[bytes, bytes]:
    """The XEARLY field: two count characters, then exactly that many
    characters of printable-profile encoding; returns its bytes and what
    follows it (XFLIGHT, or nothing)."""
    hi, lo = unchar(field[0]), unchar(field[1]) if len(field) > 1 else -1
    if not (0 <= hi < 64 and 0 <= lo < 64) or len(field) < 2 + (hi << 6 | lo):
        raise bad("XEARLY")
    end = 2 + (hi << 6 | lo)
    try:
        return EARLY_ENCODING.decode(field[2:end]), field[end:]
    except RemoteProtocolError as exc:  # MalformedDataError: a dangling prefix
        raise bad("XEARLY") from exc


@dataclass(frozen=True, slots=True)
class Flight:
    """A first flight's announcement (the XFLIGHT field, PROTOCOL.md 14).

    Attributes:
        packets: the most data packets (sequence numbers 1..packets) sent
            before the answer, 1..:data:`MAX_FLIGHT_PACKETS`.
        length: the longest of them, MARK through CHECK.
        nonce: 12 bits that differ between two requests of one endpoint
            (and, very likely, of a restarted one): a listener tells a
            resent request from a restarted connector's by it.
    """

    packets: int
    length: int
    nonce: int

    SIZE = 5
    """Characters of the field."""

    def encode(self) -> bytes:
        """The five field characters."""
        return bytes(
            (
                tochar(self.packets),
                tochar(self.length >> 6 & 63),
                tochar(self.length & 63),
                tochar(self.nonce >> 6 & 63),
                tochar(self.nonce & 63),
            )
        )

    @classmethod
    def decode(cls, field: bytes, bad: Callable[[str], RemoteProtocolError]) -> Flight:
        """The field at the head of ``field``."""
        c = [unchar(x) for x in field[: cls.SIZE]]
        if len(c) != cls.SIZE or not all(0 <= x < 64 for x in c):
            raise bad("XFLIGHT")
        flight = cls(c[0], c[1] << 6 | c[2], c[3] << 6 | c[4])
        if not 1 <= flight.packets <= MAX_FLIGHT_PACKETS or not (
            MIN_PACKET_LENGTH <= flight.length <= min(MAX_PACKET_LENGTH, MAX_FLIGHT_LENGTH)
        ):
            raise bad("XFLIGHT")
        return flight


@dataclass(frozen=True, slots=True, kw_only=True)
class Negotiated:
    """What both sides use after the init exchange.

    Attributes:
        send_max_length: largest packet we send (the peer's receive limit).
        receive_max_length: largest packet we accept (ours).
        window: the smaller of the two offers (of the long windows when
            both offer long sequence numbers).
        check: block check on every packet after the exchange
            (:data:`BlockCheck.CRC32` when both agreed on it).
        encoding: the data-field encoding both directions use: a Kermit
            prefix profile, or a dense one (PROTOCOL.md section 10).
        peer: the peer's parameters as received.
        long_seq: both offered long sequence numbers: they are mod
            :data:`LONG_SEQ_MODULUS` on the wire (PROTOCOL.md section 9).
        expedited: both offered the expedited lane (PROTOCOL.md section 11).
        latest: both offered the latest-value lane (PROTOCOL.md section 12).
        correction: both read corrected data packets (PROTOCOL.md section 15).
    """

    send_max_length: int
    receive_max_length: int
    window: int
    check: BlockCheck
    encoding: DataCodec
    peer: InitParameters
    long_seq: bool = False
    expedited: bool = False
    latest: bool = False
    correction: bool = False

    @property
    def modulus(self) -> int:
        """The sequence number space on the wire: 64, or 262144 with long numbers."""
        return LONG_SEQ_MODULUS if self.long_seq else 64


def negotiate(mine: InitParameters, theirs: InitParameters) -> Negotiated:
    """Combine two offers (the same answer on both sides).

    Raises:
        RemoteProtocolError: the offers cannot work together: a different
            protocol version, or one side needs 8th-bit prefixing (a 7-bit
            printable line) and the other refuses it.  ``error_hint`` is the
            reason to send in the refusal.
    """
    if theirs.version != PROTOCOL_VERSION:
        got = "none (not a telelink endpoint)" if theirs.version is None else str(theirs.version)
        raise RemoteProtocolError(
            f"peer speaks protocol version {got}, this endpoint speaks {PROTOCOL_VERSION}",
            error_hint=f"Protocol version {got} not supported (want {PROTOCOL_VERSION})",
        )
    check: BlockCheck
    if mine.check == theirs.check and mine.check in (BlockCheck.SUM12, BlockCheck.CRC16):
        check = mine.check
    else:
        check = BlockCheck.SUM6  # Kermit: both must ask for the same type, else type 1.
    wants = {c for c in (mine.qbin, theirs.qbin) if c not in (ord("Y"), ord("N"))}
    if len(wants) > 1:
        raise RemoteProtocolError(
            "the two sides ask for different 8th-bit prefixes",
            error_hint="Conflicting 8th-bit prefixes",
        )
    qbin = next(iter(wants), None)
    if qbin is not None and ord("N") in (mine.qbin, theirs.qbin):
        raise RemoteProtocolError(
            "8th-bit prefixing is required (7-bit printable line) but refused",
            error_hint="8th-bit prefixing refused: a 7-bit line cannot carry the data",
        )
    rept = mine.rept if mine.rept is not None and mine.rept == theirs.rept else None
    if mine.qctl != theirs.qctl:
        raise RemoteProtocolError(
            "the two sides use different control prefixes",
            error_hint="Control prefix mismatch",
        )
    common = (mine.features or 0) & (theirs.features or 0)
    declared = (mine.features or 0) | (theirs.features or 0)
    encoding: DataCodec
    if qbin is None and common & FEATURE_ESCAPE:
        encoding = EscapeEncoding(unsafe=XON_XOFF if declared & FEATURE_XON_XOFF else b"")
    elif qbin is not None and common & FEATURE_RADIX91:
        encoding = Radix91Encoding()
    else:
        encoding = Encoding(qctl=mine.qctl, qbin=qbin, rept=rept)
    # Every endpoint that sets any of bits 2, 4, 8 decodes CRC-32; bit 8 is
    # a wish, granted when either side makes it (PROTOCOL.md 10.2).
    speaks = FEATURE_CRC32 | DENSE_FEATURES
    if (
        (mine.features or 0) & speaks
        and (theirs.features or 0) & speaks
        and declared & FEATURE_CRC32
    ):
        check = BlockCheck.CRC32
    long_seq = mine.long_window is not None and theirs.long_window is not None
    both_lanes = (mine.lanes or 0) & (theirs.lanes or 0)
    if mine.long_window is not None and theirs.long_window is not None:
        window = min(mine.long_window, theirs.long_window)
    else:
        window = min(mine.window, theirs.window)
    return Negotiated(
        send_max_length=theirs.max_packet_length,
        receive_max_length=mine.max_packet_length,
        window=window,
        check=check,
        encoding=encoding,
        peer=theirs,
        long_seq=long_seq,
        expedited=bool(common & FEATURE_EXPEDITED),
        latest=bool(common & FEATURE_EXPEDITED and both_lanes & LANE_LATEST),
        # A repair is one more try of the check: only a CRC is strong enough.
        correction=bool(
            common & FEATURE_EXPEDITED
            and both_lanes & LANE_CORRECTION
            and check in (BlockCheck.CRC16, BlockCheck.CRC32)
        ),
    )


def self_agreement(offer: InitParameters) -> Negotiated:
    """What a listener configured as ``offer`` describes would agree with it:
    what a first flight is cut by (PROTOCOL.md 14).  The same function of
    the request on both sides.

    Raises:
        RemoteProtocolError: the offer cannot agree with itself (never for
            an endpoint's own offer).
    """
    return negotiate(offer.answer(offer, offer.long_window), offer)


def flight_format(agreed: Negotiated) -> tuple[object, ...]:
    """What a data packet's bytes depend on: its block check, its data
    encoding and whether long sequence numbers head its field.  A first
    flight is taken only when the real agreement has the format the flight
    was cut by (:func:`self_agreement`)."""
    return (agreed.check, agreed.encoding, agreed.long_seq)
