"""The teleoperation channel's compact packets (PROTOCOL.md section 14).

Seed 004: the hand controller's forward loop sends "incremental trajectory
information to the remote site" every sampling interval, and "the sensed
force/torque information is sent from the remote site" back.  The command
packet is 216 bytes; at 2400 bit/s that is close to a second of line per
sample, so the sample stream has its own compact packets on its own stream.
Every packet starts with the same eight bytes::

    offset size field
         0    2 magic     b"TT"
         2    1 version   1
         3    1 kind      TeleopKind (fixes the packet's size)
         4    4 counter   per channel and direction: 1, 2, 3, ... (u32)

and, once both ends hold the channel key, ends with an 8-byte tag.  The codec
is pure: sizes, fields and ranges; keys, counters and state are the
connection's business (``_teleop_connection``).
"""

from __future__ import annotations

import enum
import hashlib
import hmac
import math
import struct
from dataclasses import dataclass

__all__ = [
    "HEADER_SIZE",
    "MAGIC",
    "TAG_SIZE",
    "TELEOP_VERSION",
    "Buttons",
    "ContactFlags",
    "Reply",
    "ReplyStatus",
    "Sample",
    "TeleopKind",
    "TeleopMode",
    "TeleopPacketError",
    "channel_key",
    "client_proof",
    "decode_header",
    "decode_reply",
    "decode_sample",
    "encode_reply",
    "encode_sample",
    "server_proof",
    "sign",
    "size_of",
    "tag_for",
]

MAGIC = b"TT"
"""Not ``b"TL"``: a teleoperation packet can never be mistaken for a command packet."""
TELEOP_VERSION = 1
TAG_SIZE = 8
"""HMAC-SHA256 cut to 64 bits.  Half the command packet's: a forger gets one try
per connection (a failed tag is counted and eight in a row end the channel) and a
sample is worth a few milliseconds of motion; the 8 bytes saved are 15 % of a sample."""

_HEAD = struct.Struct("!2sBBI")
HEADER_SIZE = _HEAD.size  # 8
_SAMPLE = struct.Struct("!IBBBBd6f")  # after the header: 36 bytes
_REPLY = struct.Struct("!IBBBBdf6f6f6f")  # after the header: 92 bytes
_IDENTITY = 32
_NONCE = 16
_PROOF = 32


class TeleopKind(enum.IntEnum):
    """What a teleoperation packet is (u8 at offset 3); each kind has one size."""

    HELLO = 1
    """Operator -> arm: identity (32 bytes), nonce (16).  56 bytes, never tagged."""
    CHALLENGE = 2
    """Arm -> operator (keyed arm only): nonce (16).  24 bytes, never tagged."""
    AUTH = 3
    """Operator -> arm: proof (32).  48 bytes, tagged."""
    GRANT = 4
    """Arm -> operator: proof (32), rate deadman (f32 s), control rate (f32 Hz).  56 bytes."""
    REFUSE = 5
    """Arm -> operator: reason (u8), then the arm closes.  16 bytes, never tagged."""
    SAMPLE = 6
    """Operator -> arm: one hand-controller sample.  56 bytes, tagged."""
    REPLY = 7
    """Arm -> operator: force/torque, commanded and actual pose, flags.  108 bytes, tagged."""
    STOP = 8
    """Operator -> arm: emergency stop, ahead of any sample.  24 bytes, tagged."""
    BYE = 9
    """Either way: the channel ends (reason u8).  24 bytes, tagged."""


_SIZES = {
    TeleopKind.HELLO: HEADER_SIZE + _IDENTITY + _NONCE,
    TeleopKind.CHALLENGE: HEADER_SIZE + _NONCE,
    TeleopKind.AUTH: HEADER_SIZE + _PROOF + TAG_SIZE,
    TeleopKind.GRANT: HEADER_SIZE + _PROOF + 8 + TAG_SIZE,
    TeleopKind.REFUSE: HEADER_SIZE + 8,
    TeleopKind.SAMPLE: HEADER_SIZE + _SAMPLE.size + TAG_SIZE,
    TeleopKind.REPLY: HEADER_SIZE + _REPLY.size + TAG_SIZE,
    TeleopKind.STOP: HEADER_SIZE + 8 + TAG_SIZE,
    TeleopKind.BYE: HEADER_SIZE + 8 + TAG_SIZE,
}
UNTAGGED = frozenset({TeleopKind.HELLO, TeleopKind.CHALLENGE, TeleopKind.REFUSE})
"""Kinds sent before the sender can know the channel key."""


class TeleopMode(enum.IntEnum):
    """Seed 004's modes (SAMPLE byte 12).  Force feedback is a button, not a mode."""

    JOINT = 1
    """Hand-controller joint to arm joint, scaled; words = accumulated joint increments (rad)."""
    CARTESIAN = 2
    """Hand motion to end-effector motion; words = accumulated dX (m, m, m, rad, rad, rad)."""
    RATE = 3
    """Handle deflection from neutral sets speed; words = the deflection now (not accumulated)."""
    INDEX = 4
    """Cartesian with the index clutch in use: identical words; the arm shows the clutch."""


class Buttons(enum.IntFlag):
    """SAMPLE byte 13: the FRHC's buttons and the operator's menu choices."""

    ENGAGED = 0x01
    """Index button: the robot follows (clear = clutch open, the hand moves freely)."""
    FORCE_REFLECTION = 0x02
    """Top-right button: reflect contact forces to the hand (direct force reflection)."""
    POSE_CHANGE = 0x04
    """Middle button: the arm may pass a singular region (else it bounces off)."""
    TOOL_FRAME = 0x08
    """Cartesian increments are in the tool frame (clear: the world frame)."""
    SHARED_COMPLIANCE = 0x10
    """The arm yields to contact itself (local compliance at the remote site)."""


class ContactFlags(enum.IntFlag):
    """REPLY byte 13: what the arm felt and did."""

    CONTACT = 0x01
    FORCE_LIMIT = 0x02
    """The contact force passed the limit: the arm stopped."""
    BOUNCED = 0x04
    """A step into a singular region was refused (no pose-change button)."""
    CLUTCHED = 0x08
    """The latest sample had ENGAGED clear: the arm holds still."""
    JOINT_LIMIT = 0x10
    COMPLIANT = 0x20
    """Shared compliance is yielding: the actual pose lags the command because of contact."""


class ReplyStatus(enum.IntEnum):
    """REPLY byte 12: whether the arm follows samples."""

    FOLLOWING = 0
    STOPPED = 1
    """An emergency stop (STOP packet or the command session) latched; samples are ignored."""
    DEADMAN = 2
    """Rate mode: no sample for the deadman time; the arm stopped and waits for a new sample."""
    FORCE_LIMIT = 3
    """The force limit stopped the arm; it resumes when ENGAGED is released and pressed again."""


_BUTTONS = sum(int(b) for b in Buttons)
_FLAGS = sum(int(f) for f in ContactFlags)
_WORD_BOUND = 1.0e6
"""Every word's magnitude bound (m, rad, N): far beyond any hand controller, and
it keeps float32 away from infinity when the arm adds to it."""


class TeleopPacketError(Exception):
    """A teleoperation packet that cannot be decoded: counted and dropped, never raised out."""

    resync: bool = False

    def __init__(self, message: str, *, resync: bool = False) -> None:
        super().__init__(message)
        self.message = message
        self.resync = resync


@dataclass(frozen=True, slots=True)
class Sample:
    """One hand-controller sample (PROTOCOL.md 14.3).

    ``words`` mean, by mode: JOINT the hand controller's accumulated joint
    increments; CARTESIAN and INDEX the accumulated hand increments dX (position
    m, rotation vector rad, hand-controller frame); RATE the deflection from
    neutral.  "Accumulated" is the running sum since the channel opened of every
    increment made while ENGAGED: the arm moves by the difference between the
    sample it applies and the one it applied before, so a sample skipped or
    coalesced on the way loses no motion.
    """

    sample: int
    """The operator's sample number (1, 2, ...); gaps are samples never sent."""
    mode: TeleopMode
    buttons: Buttons
    trigger: int
    """0 gripper open .. 255 closed."""
    stamp: float
    """When the hand controller was sampled (s, the operator's clock)."""
    words: tuple[float, float, float, float, float, float]


@dataclass(frozen=True, slots=True)
class Reply:
    """The arm's answer (PROTOCOL.md 14.4): what it applied and what it feels."""

    sample: int
    """The last sample applied (0: none yet)."""
    status: ReplyStatus
    flags: ContactFlags
    mode: int
    """The mode of the last sample applied (0: none yet)."""
    gripper: int
    """Gripper closure 0 open .. 255 closed."""
    stamp: float
    """The applied sample's stamp, echoed: the operator's age measure."""
    held: float
    """Seconds from the arm receiving that sample to this reply."""
    force: tuple[float, float, float, float, float, float]
    """Wrist force/torque (N, N m; base frame)."""
    commanded: tuple[float, float, float, float, float, float]
    """Commanded hand pose: position (m) and rotation vector (rad), base frame."""
    actual: tuple[float, float, float, float, float, float]
    """Actual hand pose, the same way."""


def size_of(kind: TeleopKind) -> int:
    return _SIZES[kind]


def _head(kind: TeleopKind, counter: int) -> bytes:
    if not 0 <= counter < 2**32:
        raise ValueError(f"counter {counter} outside u32")
    return _HEAD.pack(MAGIC, TELEOP_VERSION, kind, counter)


def decode_header(data: bytes | bytearray | memoryview) -> tuple[TeleopKind, int, int]:
    """(kind, counter, size) from the first :data:`HEADER_SIZE` bytes.

    Raises :class:`TeleopPacketError` with ``resync`` set for a bad magic (the
    reader skips to the next ``b"TT"``), else for a bad version or kind; and
    without ``resync`` for fewer bytes than a header (the reader never asks then).
    """
    if len(data) < HEADER_SIZE:
        raise TeleopPacketError(f"{len(data)} bytes: a header is {HEADER_SIZE}")
    magic, version, kind, counter = _HEAD.unpack_from(data)
    if magic != MAGIC:
        raise TeleopPacketError(f"magic {magic!r}, expected {MAGIC!r}", resync=True)
    if version != TELEOP_VERSION:
        raise TeleopPacketError(f"teleoperation version {version}, this end speaks 1", resync=True)
    try:
        k = TeleopKind(kind)
    except ValueError:
        raise TeleopPacketError(f"unknown teleoperation kind {kind}", resync=True) from None
    return k, counter, _SIZES[k]


def _finite(words: tuple[float, ...] | list[float], what: str) -> None:
    for i, w in enumerate(words):
        if not math.isfinite(w) or abs(w) > _WORD_BOUND:
            raise TeleopPacketError(f"{what} word {i} is {w!r}: not finite or beyond 1e6")


def _check_local(words: tuple[float, ...] | list[float], what: str) -> None:
    try:
        _finite(words, what)
    except TeleopPacketError as exc:
        raise ValueError(exc.message) from None


def _tagged(signed: bytes, key: bytes | None, direction: bytes) -> bytes:
    return signed + (tag_for(key, direction, signed) if key else bytes(TAG_SIZE))


def tag_for(key: bytes, direction: bytes, signed: bytes) -> bytes:
    """HMAC-SHA256(channel key, direction || signed bytes), first 8 bytes."""
    return hmac.new(key, direction + signed, hashlib.sha256).digest()[:TAG_SIZE]


def sign(kind: TeleopKind, counter: int, body: bytes, key: bytes | None, direction: bytes) -> bytes:
    """Header + body (+ tag for the tagged kinds): one whole packet."""
    signed = _head(kind, counter) + body
    if kind in UNTAGGED:
        raw = signed
    else:
        raw = _tagged(signed, key, direction)
    if len(raw) != _SIZES[kind]:
        raise ValueError(f"{kind.name} is {_SIZES[kind]} bytes, built {len(raw)}")
    return raw


def encode_sample(s: Sample, counter: int, key: bytes | None, direction: bytes) -> bytes:
    """A SAMPLE packet; ``ValueError`` for a field out of range (a local bug)."""
    _check_local(s.words, "sample")
    if not math.isfinite(s.stamp) or not 0 <= s.trigger <= 255 or not 0 < s.sample < 2**32:
        raise ValueError(f"sample fields out of range: {s!r}")
    body = _SAMPLE.pack(s.sample, s.mode, s.buttons, s.trigger, 0, s.stamp, *s.words)
    return sign(TeleopKind.SAMPLE, counter, body, key, direction)


def decode_sample(raw: bytes) -> Sample:
    """The SAMPLE's fields (header and tag already checked by the caller)."""
    number, mode, buttons, trigger, reserved, stamp, *words = _SAMPLE.unpack_from(raw, HEADER_SIZE)
    if reserved:
        raise TeleopPacketError(f"reserved byte is {reserved}, must be 0")
    try:
        m = TeleopMode(mode)
    except ValueError:
        raise TeleopPacketError(f"unknown mode {mode}") from None
    if buttons & ~_BUTTONS:
        raise TeleopPacketError(f"unknown button bits {buttons & ~_BUTTONS:#04x}")
    if number == 0:
        raise TeleopPacketError("sample number 0 (they start at 1)")
    _finite([stamp], "stamp")
    _finite(words, "sample")
    w = tuple(float(x) for x in words)
    return Sample(number, m, Buttons(buttons), trigger, stamp, (w[0], w[1], w[2], w[3], w[4], w[5]))


def encode_reply(r: Reply, counter: int, key: bytes | None, direction: bytes) -> bytes:
    """A REPLY packet; ``ValueError`` for a non-finite word (a local bug)."""
    _check_local([r.stamp, r.held, *r.force, *r.commanded, *r.actual], "reply")
    if not 0 <= r.gripper <= 255 or not 0 <= r.sample < 2**32 or not 0 <= r.mode <= 255:
        raise ValueError(f"reply fields out of range: {r!r}")
    body = _REPLY.pack(
        r.sample,
        r.status,
        r.flags,
        r.mode,
        r.gripper,
        r.stamp,
        r.held,
        *r.force,
        *r.commanded,
        *r.actual,
    )
    return sign(TeleopKind.REPLY, counter, body, key, direction)


def _six(v: list[float]) -> tuple[float, float, float, float, float, float]:
    return (v[0], v[1], v[2], v[3], v[4], v[5])


def decode_reply(raw: bytes) -> Reply:
    """The REPLY's fields (header and tag already checked by the caller)."""
    number, status, flags, mode, gripper, stamp, held, *words = _REPLY.unpack_from(raw, HEADER_SIZE)
    try:
        st = ReplyStatus(status)
    except ValueError:
        raise TeleopPacketError(f"unknown reply status {status}") from None
    if flags & ~_FLAGS:
        raise TeleopPacketError(f"unknown contact flag bits {flags & ~_FLAGS:#04x}")
    _finite([stamp, held, *words], "reply")
    w = [float(x) for x in words]
    return Reply(
        number,
        st,
        ContactFlags(flags),
        mode,
        gripper,
        stamp,
        held,
        _six(w[0:6]),
        _six(w[6:12]),
        _six(w[12:18]),
    )


# --- the channel handshake (PROTOCOL.md 14.2) -------------------------------------------

_CLIENT_LABEL = b"telelink-v1 teleop client proof"
_SERVER_LABEL = b"telelink-v1 teleop server proof"
_KEY_LABEL = b"telelink-v1 teleop channel key"


def _transcript(client_nonce: bytes, server_nonce: bytes, identity: bytes) -> bytes:
    return client_nonce + server_nonce + identity


def client_proof(key: bytes, client_nonce: bytes, server_nonce: bytes, identity: bytes) -> bytes:
    msg = _CLIENT_LABEL + _transcript(client_nonce, server_nonce, identity)
    return hmac.new(key, msg, hashlib.sha256).digest()


def server_proof(key: bytes, client_nonce: bytes, server_nonce: bytes, identity: bytes) -> bytes:
    msg = _SERVER_LABEL + _transcript(client_nonce, server_nonce, identity)
    return hmac.new(key, msg, hashlib.sha256).digest()


def channel_key(key: bytes, client_nonce: bytes, server_nonce: bytes, identity: bytes) -> bytes:
    msg = _KEY_LABEL + _transcript(client_nonce, server_nonce, identity)
    return hmac.new(key, msg, hashlib.sha256).digest()
