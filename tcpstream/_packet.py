"""The fixed-size command packet: layout, kinds, strict decoding (PROTOCOL.md section 2).

Seed 003 section 9.1: "These commands are encoded into fixed sized command
packets and then sent over the socket stream."  Every packet, in both
directions and in every phase of a session, is exactly :data:`PACKET_SIZE`
bytes in network byte order::

    offset size field
         0    2 magic        b"TL"
         2    1 version      1
         3    1 kind         PacketKind
         4    2 flags        kind-specific bits (CommandFlags for COMMAND)
         6    2 code         CommandCode (0 where no command is meant)
         8    2 status       FailureReason / RefuseReason / CloseReason
        10    2 reserved     must be 0
        12    4 request_id   controller-chosen command identity (u32)
        16    8 counter      per-session, per-direction, strictly increasing (u64)
        24   32 aux          4 x float64 (detail words)
        56  144 body         18 x float64 words, or bytes for the handshake kinds
       200   16 tag          truncated HMAC-SHA256 over bytes 0..199 (zeros without a key)

The codec is pure: it knows nothing about sessions, keys or state.  It
checks everything one packet can be checked for on its own and raises a
:class:`PacketError` subclass naming the field; the session turns that into a
counted event and a ``FAILED`` reply, never a crash.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass, field

from ._commands import ARGUMENT_WORDS, AUX_WORDS, CommandCode, CommandFlags, FailureReason

__all__ = [
    "BODY_SIZE",
    "MAGIC",
    "PACKET_SIZE",
    "PROTOCOL_VERSION",
    "SIGNED_SIZE",
    "TAG_SIZE",
    "BadField",
    "BadMagic",
    "BadVersion",
    "NonFiniteWord",
    "Packet",
    "PacketError",
    "PacketKind",
    "UnknownCommand",
    "UnknownKind",
    "WrongSize",
    "decode_packet",
    "encode_packet",
    "pack_text",
    "unpack_text",
    "words_body",
]

MAGIC = b"TL"
PROTOCOL_VERSION = 1

_HEADER = struct.Struct("!2sBBHHHHIQ4d")
"""Bytes 0..55: everything before the body."""
_WORDS = struct.Struct(f"!{ARGUMENT_WORDS}d")
BODY_SIZE = _WORDS.size  # 144
TAG_SIZE = 16
"""HMAC-SHA256 truncated to 128 bits: forging needs ~2^128 tries, and one wrong
tag costs the attacker the connection (see the garbage limit in the session)."""
SIGNED_SIZE = _HEADER.size + BODY_SIZE  # 200: the bytes the tag covers
PACKET_SIZE = SIGNED_SIZE + TAG_SIZE  # 216

_CODES = frozenset(int(c) for c in CommandCode)
_KNOWN_FLAGS = sum(int(f) for f in CommandFlags)
_ZERO_AUX = (0.0,) * AUX_WORDS
_ZERO_BODY = bytes(BODY_SIZE)
_ZERO_TAG = bytes(TAG_SIZE)


class PacketKind(enum.IntEnum):
    """What a packet is (u8 at offset 3).  PROTOCOL.md section 3 gives each one's fields.

    HELLO .. REFUSE are the connection request and grant of seed 003 section 9.1
    ("the controlling agent ... must first make a request for connection.  If the
    manipulator grants the request, then a full-duplex stream of commands may be
    passed"); COMMAND .. FAILED are the pipelined confirmation; the rest keep the
    session alive and safe.
    """

    HELLO = 1
    """Controller -> arm: identity, incarnation, role wanted, client nonce."""
    CHALLENGE = 2
    """Arm -> controller (only with a key): server nonce."""
    AUTH = 3
    """Controller -> arm: HMAC proof over both nonces and the identity."""
    GRANT = 4
    """Arm -> controller: role granted, timing parameters, server's own proof."""
    REFUSE = 5
    """Arm -> controller: refusal reason (status) and text (body); then close."""
    COMMAND = 6
    """Controller -> arm: command code, flags, request id, eighteen argument words."""
    ACCEPTED = 7
    """Arm -> controller: the command is queued (aux[0] = queue position)."""
    COMPLETED = 8
    """Arm -> controller: done; body = feedback array, aux = result words."""
    FAILED = 9
    """Arm -> controller: failed; status = FailureReason, aux = detail, body = text."""
    TELEMETRY = 10
    """Arm -> controller and observers: body = feedback array, aux[0] = sample number."""
    HEARTBEAT = 11
    """Both ways, when otherwise idle: proves the link and the peer are alive."""
    EMERGENCY_STOP = 12
    """Controller -> arm: halt now, bypassing the queue (request id like a command)."""
    BYE = 13
    """Either way: the session ends (status = CloseReason); the sender closes next."""


NUMERIC_KINDS = frozenset(
    {
        PacketKind.COMMAND,
        PacketKind.ACCEPTED,
        PacketKind.COMPLETED,
        PacketKind.TELEMETRY,
        PacketKind.HEARTBEAT,
        PacketKind.EMERGENCY_STOP,
    }
)
"""Kinds whose body is eighteen float64 words, all of which must be finite."""


class PacketError(Exception):
    """A packet that cannot be decoded; ``reason`` is the code for the ``FAILED`` reply.

    Raised by :func:`decode_packet`.  The session counts it and answers; the
    connection survives (up to the garbage limit).
    """

    reason: FailureReason = FailureReason.BAD_PACKET

    def __init__(self, message: str, *, request_id: int = 0) -> None:
        super().__init__(message)
        self.message = message
        self.request_id = request_id
        """The request id, when the header was readable enough to trust it (else 0)."""


class WrongSize(PacketError):
    """Not exactly :data:`PACKET_SIZE` bytes."""


class BadMagic(PacketError):
    """The first two bytes are not ``b"TL"``: not our protocol, or framing lost."""


class BadVersion(PacketError):
    """A protocol version this implementation does not speak."""


class UnknownKind(PacketError):
    """A kind byte outside :class:`PacketKind`."""


class BadField(PacketError):
    """A field that must be zero is not, or a value out of its range."""


class NonFiniteWord(PacketError):
    """NaN or infinity in a word that must be a number."""


class UnknownCommand(PacketError):
    """A COMMAND whose code is not a :class:`CommandCode`."""

    reason = FailureReason.UNKNOWN_COMMAND


def words_body(words: tuple[float, ...] | list[float]) -> bytes:
    """Eighteen float64 words as a body (network byte order)."""
    return _WORDS.pack(*words)


def pack_text(text: str, size: int = BODY_SIZE) -> bytes:
    """UTF-8 text NUL-padded to ``size`` bytes, cut at a character boundary if too long."""
    raw = text.encode("utf-8")[:size]
    # Cutting mid-character would make the peer's strict decode fail; back off.
    while raw:
        try:
            raw.decode("utf-8")
            break
        except UnicodeDecodeError:
            raw = raw[:-1]
    return raw.ljust(size, b"\0")


def unpack_text(raw: bytes) -> str:
    """Inverse of :func:`pack_text`; undecodable bytes become U+FFFD (text is informative)."""
    return raw.rstrip(b"\0").decode("utf-8", errors="replace")


@dataclass(frozen=True, slots=True)
class Packet:
    """One decoded packet.  ``body`` is raw: use :meth:`words` for the numeric kinds."""

    kind: PacketKind
    flags: int = 0
    code: int = 0
    status: int = 0
    request_id: int = 0
    counter: int = 0
    aux: tuple[float, ...] = _ZERO_AUX
    body: bytes = _ZERO_BODY
    tag: bytes = field(default=_ZERO_TAG, compare=False)

    def words(self) -> tuple[float, ...]:
        """The body as eighteen float64 words."""
        return _WORDS.unpack(self.body)

    def describe(self) -> str:
        """One line for a packet trace: kind, counter, request id, code, status, numbers."""
        parts = [f"{self.kind.name} #{self.counter}"]
        if self.request_id:
            parts.append(f"rid={self.request_id}")
        if self.code:
            name = CommandCode(self.code).name if self.code in _CODES else str(self.code)
            parts.append(f"code={name}")
        if self.flags:
            parts.append(f"flags={self.flags:#x}")
        if self.status:
            parts.append(f"status={self.status}")
        if any(self.aux):
            parts.append("aux=" + ",".join(f"{x:g}" for x in self.aux))
        if self.kind in NUMERIC_KINDS and any(self.body):
            parts.append("w=" + ",".join(f"{x:g}" for x in self.words()))
        elif self.kind in (PacketKind.FAILED, PacketKind.REFUSE, PacketKind.BYE):
            parts.append(repr(unpack_text(self.body)))
        return " ".join(parts)


def encode_packet(packet: Packet) -> bytes:
    """The packet's :data:`SIGNED_SIZE` signed bytes followed by its tag.

    Raises ``ValueError`` for a field out of range or a word that is not finite
    (a local bug, not a peer's: :func:`decode_packet` would reject the packet).
    """
    if len(packet.body) != BODY_SIZE or len(packet.tag) != TAG_SIZE:
        raise ValueError(f"body must be {BODY_SIZE} bytes and tag {TAG_SIZE}")
    if len(packet.aux) != AUX_WORDS:
        raise ValueError(f"aux must be {AUX_WORDS} words")
    # The receiver's decode_packet rejects these; never put one on the wire.
    if not all(math.isfinite(w) for w in packet.aux):
        raise ValueError(f"aux words must be finite, got {packet.aux!r}")
    if packet.kind in NUMERIC_KINDS and not all(
        math.isfinite(w) for w in _WORDS.unpack(packet.body)
    ):
        raise ValueError(f"{packet.kind.name} body words must be finite")
    head = _HEADER.pack(
        MAGIC,
        PROTOCOL_VERSION,
        packet.kind,
        packet.flags,
        packet.code,
        packet.status,
        0,
        packet.request_id,
        packet.counter,
        *packet.aux,
    )
    return head + packet.body + packet.tag


def decode_packet(data: bytes) -> Packet:
    """Strictly decode one packet; raises a :class:`PacketError` subclass naming the fault.

    Checked, in order: size, magic, version, kind, reserved field, finite aux
    words (every kind), finite body words (numeric kinds), and for COMMAND a
    known command code and no unknown flag bits.  Authentication (tag) and
    sequencing (counter) are the session's business, not the codec's.
    """
    if len(data) != PACKET_SIZE:
        raise WrongSize(f"packet is {len(data)} bytes, expected {PACKET_SIZE}")
    (magic, version, kind, flags, code, status, reserved, request_id, counter, *aux) = (
        _HEADER.unpack_from(data)
    )
    if magic != MAGIC:
        raise BadMagic(f"magic {magic!r}, expected {MAGIC!r}: not a telelink packet")
    if version != PROTOCOL_VERSION:
        raise BadVersion(f"protocol version {version}; this end speaks {PROTOCOL_VERSION}")
    try:
        pkind = PacketKind(kind)
    except ValueError:
        raise UnknownKind(f"unknown packet kind {kind}", request_id=request_id) from None
    if reserved != 0:
        raise BadField(f"reserved field is {reserved:#06x}, must be 0", request_id=request_id)
    for i, word in enumerate(aux):
        if not math.isfinite(word):
            raise NonFiniteWord(f"aux word {i} is {word!r}", request_id=request_id)
    body = bytes(data[_HEADER.size : SIGNED_SIZE])
    if pkind in NUMERIC_KINDS:
        for i, word in enumerate(_WORDS.unpack(body)):
            if not math.isfinite(word):
                raise NonFiniteWord(f"body word {i} is {word!r}", request_id=request_id)
    if pkind is PacketKind.COMMAND:
        if code not in _CODES:
            raise UnknownCommand(f"unknown command code {code}", request_id=request_id)
        if flags & ~_KNOWN_FLAGS:
            raise BadField(
                f"unknown command flag bits {flags & ~_KNOWN_FLAGS:#06x}", request_id=request_id
            )
    return Packet(
        kind=pkind,
        flags=flags,
        code=code,
        status=status,
        request_id=request_id,
        counter=counter,
        aux=tuple(aux),
        body=body,
        tag=bytes(data[SIGNED_SIZE:PACKET_SIZE]),
    )
