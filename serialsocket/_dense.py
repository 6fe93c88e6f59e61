"""Dense data-field encodings for telelink-to-telelink links (issue 21; PROTOCOL.md section 10).

Kermit's prefix encoding (``_encoding``) costs 1.27 wire characters per random
byte on an 8-bit line and 1.78 on a printable one.  Two denser encodings of a
packet's data field, as pure functions (byte-level definitions and the wire
ratios: serialsocket/DENSE.md):

* :class:`EscapeEncoding`, for 8-bit lines: every byte travels as itself except
  a small *reserved* set -- the MARK (SOH), the escape byte, and whatever the
  line cannot carry (``unsafe``, e.g. XON/XOFF under software flow control) --
  each sent as ``ESC, byte ^ 0x40`` (ZMODEM's ZDLE convention).  1 + k/256
  characters per random byte for k reserved bytes: 1.008 with the default
  two, 1.023 with XON/XOFF in both parities.
* :class:`Radix91Encoding`, for printable lines: 13 bytes (104 bits) become
  eight 13-bit groups, each two characters of a 91-character alphabet
  (91^2 = 8281 >= 2^13): 16/13 = 1.231 characters per byte.  The alphabet is
  ``!``..``}`` without ``#`` and ``&`` -- no space, no DEL, none of Kermit's
  default prefixes ``#&~`` -- so a dense field is also a prefix-encoded field
  that decodes to itself (a classic decoder or packet trace sees it verbatim).

Two telelink endpoints agree on them in the init exchange (XCAPAS;
:func:`serialsocket._params.negotiate`): the escape code on an 8-bit line,
radix 91 on a printable one.  Both decode exactly one packet's data field
(tokens never cross fields; the field's length alone tells where a radix-91
field's short tail is), accept only the canonical encoding of some byte string
(every field has one decoding and every byte string one encoding), and raise
:class:`~serialsocket.MalformedDataError` on anything else.  Both offer the
interface of :class:`~serialsocket.packets.Encoding` that a sender and a
receiver use: ``encode``, ``encode_prefix``, ``encode_fields``, ``decode``.
"""

from __future__ import annotations

import array
import bisect
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from ._errors import LocalProtocolError, MalformedDataError
from ._wire import MARK

__all__ = [
    "DEFAULT_ESCAPE",
    "RADIX91_ALPHABET",
    "XON_XOFF",
    "EscapeEncoding",
    "Radix91Encoding",
]

U8 = npt.NDArray[np.uint8]

DEFAULT_ESCAPE = 0x18
"""CAN, ZMODEM's ZDLE: a control character, so text almost never pays for it."""

XON_XOFF = bytes((0x11, 0x13, 0x91, 0x93))
"""DC1/DC3 and their 8th-bit twins: what software flow control reserves."""

_FLIP = 0x40
"""``ESC, byte ^ 0x40``: the second byte of an escape (ZMODEM's ZDLE rule)."""


def _malformed(what: str) -> MalformedDataError:
    return MalformedDataError(what, error_hint=f"Malformed dense data field ({what})")


def _check_capacity(capacity: int, smallest: int) -> None:
    if capacity < smallest:
        raise LocalProtocolError(
            f"data field capacity {capacity} is below {smallest}: "
            "use a larger maximum packet length"
        )


# -- the 8-bit line: escape only what the line cannot carry ------------------------------


@dataclass(frozen=True, slots=True)
class EscapeEncoding:
    """Escape only the reserved bytes: MARK, the escape byte, and ``unsafe``.

    A reserved byte ``b`` is sent as ``escape, b ^ 0x40``; every other byte as
    itself.  The second byte of an escape must itself be safe, so no reserved
    byte may be another one XOR 0x40 (checked).

    Attributes:
        unsafe: bytes the line cannot carry, declared by either side (for
            example :data:`XON_XOFF`).
        escape: the escape byte, reserved too; default CAN (0x18).

    Raises:
        LocalProtocolError: a reserved byte's escaped form is itself reserved
            (e.g. declaring both 0x01 and 0x41 unsafe).
    """

    unsafe: bytes = b""
    escape: int = DEFAULT_ESCAPE
    _reserved: bytes = field(init=False, repr=False, compare=False)
    _pairs: tuple[tuple[bytes, bytes], ...] = field(init=False, repr=False, compare=False)
    _cost: bytes = field(init=False, repr=False, compare=False)
    _is_reserved: npt.NDArray[np.bool_] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not 0 <= self.escape <= 255:
            raise LocalProtocolError(f"escape byte {self.escape} is not a byte")
        reserved = sorted({MARK, self.escape, *self.unsafe})
        clash = [b for b in reserved if b ^ _FLIP in reserved]
        if clash:
            raise LocalProtocolError(
                f"reserved bytes {bytes(clash)!r}: each one's escaped form "
                "(byte ^ 0x40) is reserved too"
            )
        # The escape byte is replaced first, so no later pass meets an escape
        # byte that an earlier one produced.
        order = [self.escape] + [b for b in reserved if b != self.escape]
        pairs = tuple((bytes((b,)), bytes((self.escape, b ^ _FLIP))) for b in order)
        cost = bytes(2 if b in reserved else 1 for b in range(256))
        object.__setattr__(self, "_reserved", bytes(reserved))
        object.__setattr__(self, "_pairs", pairs)
        object.__setattr__(self, "_cost", cost)
        is_reserved = np.zeros(256, dtype=np.bool_)
        is_reserved[reserved] = True
        object.__setattr__(self, "_is_reserved", is_reserved)

    @property
    def reserved(self) -> bytes:
        """Every byte that is escaped, ascending."""
        return self._reserved

    @property
    def random_ratio(self) -> float:
        """Expected wire characters per uniformly random byte: 1 + k/256."""
        return 1 + len(self._reserved) / 256

    def encode(self, data: bytes | bytearray | memoryview) -> bytes:
        """Encode a whole buffer (one ``bytes.replace`` per reserved byte)."""
        out = bytes(data)
        for raw, escaped in self._pairs:
            out = out.replace(raw, escaped)
        return out

    def decode(self, field: bytes | bytearray | memoryview) -> bytes:
        """Decode one data field.

        Raises:
            MalformedDataError: a reserved byte appears unescaped, or an escape
                byte is not followed by the escaped form of a reserved byte
                (including an escape at the end of the field).
        """
        raw = bytes(field)
        plain = raw.translate(None, self._reserved)
        if len(plain) == len(raw):
            return raw
        arr = np.frombuffer(raw, np.uint8)
        at = np.flatnonzero(arr == self.escape)
        # Escaped forms are never reserved, so every reserved byte in a valid
        # field is an escape byte, and no two escapes overlap.
        if at.size != len(raw) - len(plain):
            raise _malformed("unescaped reserved byte")
        if at[-1] == arr.size - 1:
            raise _malformed("escape byte at the end of the field")
        decoded = arr[at + 1] ^ np.uint8(_FLIP)
        if not self._is_reserved.take(decoded).all():
            raise _malformed("escape byte not followed by an escaped reserved byte")
        out = arr.copy()
        out[at + 1] = decoded
        keep = np.ones(arr.size, dtype=np.bool_)
        keep[at] = False
        return np.compress(keep, out).tobytes()

    def decode_fields(self, fields: Sequence[bytes]) -> bytes:
        """Decode consecutive data fields together, exactly as the fields one
        by one: an escape never crosses a field, so a field that ends in the
        escape byte is malformed even when the next one starts with an escaped
        form.  Otherwise the concatenation decodes as the fields do.

        Raises:
            MalformedDataError: as :meth:`decode`, for any of the fields.
        """
        escape = self.escape
        for f in fields[:-1]:
            if f and f[-1] == escape:
                raise _malformed("escape byte at the end of the field")
        return self.decode(b"".join(fields))

    def encode_prefix(
        self, data: bytes | bytearray | memoryview, capacity: int
    ) -> tuple[bytes, int]:
        """The longest prefix of ``data`` whose encoding fits in ``capacity``
        characters (an escape pair is never split), and how many bytes it carries.

        Raises:
            LocalProtocolError: ``capacity`` is below 2 (one escaped byte).
        """
        fields = self.encode_fields(data, capacity, 1)
        return fields[0] if fields else (b"", 0)

    def encode_fields(
        self, data: bytes | bytearray | memoryview, capacity: int, count: int
    ) -> list[tuple[bytes, int]]:
        """Cut up to ``count`` consecutive data fields of at most ``capacity``
        characters, each the longest that fits; ``(field, bytes carried)`` pairs.

        Raises:
            LocalProtocolError: ``capacity`` is below 2 (one escaped byte).
        """
        _check_capacity(capacity, 2)
        view = memoryview(data).cast("B")
        if len(view) == 0 or count < 1:
            return []
        chunk = bytes(view[: capacity * count])
        ends = np.cumsum(np.frombuffer(chunk.translate(self._cost), np.uint8), dtype=np.int64)
        char_ends = ends.data
        flat = self.encode(chunk)
        fields: list[tuple[bytes, int]] = []
        src = char = 0
        while len(fields) < count and src < len(chunk):
            cut = bisect.bisect_right(char_ends, char + capacity, src)
            end = char_ends[cut - 1]
            fields.append((flat[char:end], cut - src))
            src, char = cut, end
        return fields


# -- the printable line: radix 91 ----------------------------------------------------------

RADIX91_ALPHABET = bytes(c for c in range(33, 126) if c not in b"#&")
"""The 91 digits, in value order: ``!``..``}`` without ``#`` and ``&`` (``~`` is
126, past the end).  No space, no DEL, no Kermit prefix, no control character."""

_BLOCK_BYTES = 13
_BLOCK_CHARS = 16
_TAIL_CHARS = (0, 2, 3, 4, 5, 7, 8, 9, 10, 12, 13, 14, 15)
"""Characters for a tail of 0..12 bytes: ``ceil(8r/13)`` groups, two characters
each except a last group of at most 6 bits, which takes one."""
_TAIL_BYTES = {chars: r for r, chars in enumerate(_TAIL_CHARS)}

_DIGIT_OF = bytes(RADIX91_ALPHABET.index(c) if c in RADIX91_ALPHABET else 255 for c in range(256))
"""``translate`` table: a character's digit value, 255 outside the alphabet."""
_CHAR_OF = RADIX91_ALPHABET.ljust(256, b"\0")
"""``translate`` table: digit value to character."""


def _tail_plan(r: int) -> tuple[int, int]:
    """For a tail of ``r`` bytes: (13-bit groups used, bits in the last one)."""
    bits = 8 * r
    groups = -(-bits // 13)
    return groups, bits - 13 * (groups - 1)


_PLAN = tuple((13 * k // 8, 11 - 13 * k % 8) for k in range(8))
"""Group ``k`` of a block: its first byte, and the right shift that brings it
to the bottom of the 24-bit window starting at that byte (big-endian)."""


_FIRST = np.array([i for i, _ in _PLAN])
_SHIFT = np.array([shift for _, shift in _PLAN], dtype=np.uint32)
_SMALL = 256
_HIGH_SHIFTS = np.array([43, 30, 17, 4], dtype=np.uint64)
_LOW_SHIFTS = np.array([26, 13, 0], dtype=np.uint64)
"""Below this many blocks a few whole-matrix numpy calls (with gathers) beat
the column-by-column path's hundred small ones; above, the column path's
contiguous arithmetic wins (about ten times faster per block)."""


def _block_digits(blocks: U8) -> U8:
    """``(n, 13)`` bytes to ``(n, 16)`` digit values.

    Column by column (byte ``i`` of every block is one strided view): every
    numpy call works on ``n`` contiguous elements, no fancy indexing.  Small
    inputs (a window of packets) take the same arithmetic on the whole
    ``(n, 8)`` matrix of groups instead.
    """
    n = blocks.shape[0]
    if n < _SMALL:
        padded = np.zeros((n, _BLOCK_BYTES + 1), dtype=np.uint32)
        padded[:, :_BLOCK_BYTES] = blocks
        window = (
            (padded[:, _FIRST] << np.uint32(16))
            | (padded[:, _FIRST + 1] << np.uint32(8))
            | padded[:, _FIRST + 2]
        )
        group = (window >> _SHIFT) & np.uint32(0x1FFF)
        high = group // np.uint32(91)
        out = np.empty((n, _BLOCK_CHARS), dtype=np.uint8)
        out[:, 0::2] = high
        out[:, 1::2] = group - high * np.uint32(91)
        return out
    cols = [blocks[:, i].astype(np.uint32) for i in range(_BLOCK_BYTES)]
    digits = np.empty((n, _BLOCK_CHARS), dtype=np.uint8)
    for k, (i, shift) in enumerate(_PLAN):
        window = (cols[i] << np.uint32(16)) | (cols[i + 1] << np.uint32(8))
        if i + 2 < _BLOCK_BYTES:
            window |= cols[i + 2]
        group = (window >> np.uint32(shift)) & np.uint32(0x1FFF)
        high = group // np.uint32(91)
        digits[:, 2 * k] = high
        digits[:, 2 * k + 1] = group - high * np.uint32(91)
    return digits


def _block_bytes(digits: U8) -> U8:
    """``(n, 16)`` digit values to ``(n, 13)`` bytes; rejects pairs worth >= 8192."""
    n = digits.shape[0]
    if n < _SMALL:
        pairs = digits.astype(np.uint64)
        groups = pairs[:, 0::2] * np.uint64(91) + pairs[:, 1::2]
        if int(groups.max()) >= 1 << 13:
            raise _malformed("radix-91 pair worth 8192 or more")
        # The groups' bit fields do not overlap, so their sum is their OR.
        words = np.empty((n, 2), dtype=">u8")
        words[:, 0] = (groups[:, :4] << _HIGH_SHIFTS).sum(axis=1) | (groups[:, 4] >> np.uint64(9))
        words[:, 1] = (groups[:, 5:] << _LOW_SHIFTS).sum(axis=1) | (
            (groups[:, 4] & np.uint64(0x1FF)) << np.uint64(39)
        )
        raw = words.view(np.uint8).reshape(n, 16)
        blocks = np.empty((n, _BLOCK_BYTES), dtype=np.uint8)
        blocks[:, :7] = raw[:, 1:8]
        blocks[:, 7:] = raw[:, 10:16]
        return blocks
    cols = digits.T.astype(np.uint64)
    g = [cols[2 * k] * np.uint64(91) + cols[2 * k + 1] for k in range(8)]
    if max(int(x.max()) for x in g) >= 1 << 13:
        raise _malformed("radix-91 pair worth 8192 or more")
    # Bytes 0..6 are the top 56 bits (groups 0..3 and the top 4 bits of
    # group 4), bytes 7..12 the low 48 bits.
    high = (
        (g[0] << np.uint64(43))
        | (g[1] << np.uint64(30))
        | (g[2] << np.uint64(17))
        | (g[3] << np.uint64(4))
        | (g[4] >> np.uint64(9))
    )
    low = (
        ((g[4] & np.uint64(0x1FF)) << np.uint64(39))
        | (g[5] << np.uint64(26))
        | (g[6] << np.uint64(13))
        | g[7]
    )
    words = np.empty((n, 2), dtype=">u8")
    words[:, 0] = high
    words[:, 1] = low
    raw = words.view(np.uint8).reshape(n, 16)
    blocks = np.empty((n, _BLOCK_BYTES), dtype=np.uint8)
    blocks[:, :7] = raw[:, 1:8]
    blocks[:, 7:] = raw[:, 10:16]
    return blocks


def _tail_digits(tails: U8) -> U8:
    """``(m, r)`` tails (all ``r`` bytes, 0 < r < 13) to ``(m, T[r])`` digit values."""
    m, r = tails.shape
    padded = np.zeros((m, _BLOCK_BYTES), dtype=np.uint8)
    padded[:, :r] = tails
    digits = _block_digits(padded)
    groups, last_bits = _tail_plan(r)
    if last_bits > 6:
        return digits[:, : 2 * groups]
    last = 2 * (groups - 1)
    value = digits[:, last].astype(np.uint32) * np.uint32(91) + digits[:, last + 1]
    digits[:, last] = value >> np.uint32(7)
    return digits[:, : last + 1]


def _tail_bytes(digits: U8, r: int) -> U8:
    """Inverse of :func:`_tail_digits`; rejects nonzero padding bits."""
    m = digits.shape[0]
    groups, last_bits = _tail_plan(r)
    padded = np.zeros((m, _BLOCK_CHARS), dtype=np.uint8)
    if last_bits > 6:
        padded[:, : 2 * groups] = digits
    else:
        last = 2 * (groups - 1)
        padded[:, :last] = digits[:, :last]
        if int(digits[:, last].max()) >= 64:
            raise _malformed("radix-91 pair worth 8192 or more")
        value = digits[:, last].astype(np.uint32) << np.uint32(7)
        high = value // np.uint32(91)
        padded[:, last] = high
        padded[:, last + 1] = value - high * np.uint32(91)
    blocks = _block_bytes(padded)
    if blocks[:, r:].any():
        raise _malformed("nonzero padding bits in the radix-91 tail")
    return blocks[:, :r]


@dataclass(frozen=True, slots=True)
class Radix91Encoding:
    """Radix-91 packing of 13-byte blocks into 16 printable characters.

    A field of ``13q + r`` bytes (``r`` < 13) is ``q`` blocks of 16 characters
    and a tail of ``_TAIL_CHARS[r]`` characters (0, 2, 3, 4, 5, 7, 8, 9, 10,
    12, 13, 14 or 15): its length alone says how many bytes it carries.
    Within a block the 104 bits, big-endian, are cut into eight 13-bit groups
    ``v``, each sent as ``ALPHABET[v // 91], ALPHABET[v % 91]``.  A tail is
    zero-padded to 13 bytes and encoded as a block, keeping the groups that
    hold its bits; a last group holding at most 6 bits is sent as one
    character, ``ALPHABET[v >> 7]``.  Padding bits must be zero.
    """

    def encode(self, data: bytes | bytearray | memoryview) -> bytes:
        """Encode a whole buffer (vectorised over its blocks)."""
        raw = bytes(data)
        q, r = divmod(len(raw), _BLOCK_BYTES)
        parts: list[bytes] = []
        if q:
            blocks = np.frombuffer(raw, np.uint8, q * _BLOCK_BYTES).reshape(q, _BLOCK_BYTES)
            parts.append(_block_digits(blocks).tobytes().translate(_CHAR_OF))
        if r:
            parts.append(_encode_tail(raw[q * _BLOCK_BYTES :]))
        return b"".join(parts)

    def decode(self, field: bytes | bytearray | memoryview) -> bytes:
        """Decode one data field.

        Raises:
            MalformedDataError: a character outside the alphabet, a length no
                byte string encodes to, a pair worth 8192 or more, or nonzero
                padding bits in the tail.
        """
        raw = bytes(field)
        q, rest = divmod(len(raw), _BLOCK_CHARS)
        r = _TAIL_BYTES.get(rest)
        if r is None:
            raise _malformed(f"length {len(raw)} is not a radix-91 field length")
        if raw.translate(None, RADIX91_ALPHABET):
            raise _malformed("character outside the radix-91 alphabet")
        digit_bytes = raw.translate(_DIGIT_OF)
        parts: list[bytes] = []
        if q and q >= _SMALL_FIELD_BLOCKS:
            digits = np.frombuffer(digit_bytes, np.uint8, q * _BLOCK_CHARS)
            parts.append(_block_bytes(digits.reshape(q, _BLOCK_CHARS)).tobytes())
        elif q:
            parts.append(_blocks_small(digit_bytes, q))
        if r:
            parts.append(_decode_tail(digit_bytes[q * _BLOCK_CHARS :], r))
        return b"".join(parts)

    @staticmethod
    def bytes_for(capacity: int) -> int:
        """The most bytes whose encoding fits in ``capacity`` characters."""
        q, rest = divmod(capacity, _BLOCK_CHARS)
        return q * _BLOCK_BYTES + bisect.bisect_right(_TAIL_CHARS, rest) - 1

    def encode_prefix(
        self, data: bytes | bytearray | memoryview, capacity: int
    ) -> tuple[bytes, int]:
        """Encode the longest prefix of ``data`` that fits in ``capacity`` characters.

        Raises:
            LocalProtocolError: ``capacity`` is below 2 (one byte).
        """
        _check_capacity(capacity, 2)
        view = memoryview(data).cast("B")
        n = min(len(view), self.bytes_for(capacity))
        return self.encode(view[:n]), n

    def encode_fields(
        self, data: bytes | bytearray | memoryview, capacity: int, count: int
    ) -> list[tuple[bytes, int]]:
        """Cut up to ``count`` consecutive fields of at most ``capacity`` characters.

        Every full field carries :meth:`bytes_for` ``(capacity)`` bytes, so the
        full fields are one ``(fields, bytes)`` array: their blocks and their
        tails are each encoded in one vectorised pass.

        Raises:
            LocalProtocolError: ``capacity`` is below 2 (one byte).
        """
        _check_capacity(capacity, 2)
        view = memoryview(data).cast("B")
        per = self.bytes_for(capacity)
        full = min(count, len(view) // per)
        fields: list[tuple[bytes, int]] = []
        if full:
            rows = np.frombuffer(view, np.uint8, full * per).reshape(full, per)
            q, r = divmod(per, _BLOCK_BYTES)
            parts = []
            if q:
                blocks = rows[:, : q * _BLOCK_BYTES].reshape(full * q, _BLOCK_BYTES)
                parts.append(_block_digits(blocks).reshape(full, q * _BLOCK_CHARS))
            if r:
                parts.append(_tail_digits(rows[:, q * _BLOCK_BYTES :]))
            digits = parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)
            chars = digits.tobytes().translate(_CHAR_OF)
            width = digits.shape[1]
            fields = [(chars[i * width : (i + 1) * width], per) for i in range(full)]
        if len(fields) < count and full * per < len(view):
            fields.append((self.encode(view[full * per :]), len(view) - full * per))
        return fields

    def decode_fields(self, fields: Sequence[bytes]) -> bytes:
        """Decode consecutive data fields (what one read delivered), as
        ``b"".join(map(decode, fields))`` but vectorised over the runs of
        equal-length fields (a sender's full packets all have one length).

        A radix-91 field's tail sits at its end, so fields cannot simply be
        concatenated and decoded as one.

        Raises:
            MalformedDataError: as :meth:`decode`, for any of the fields.
        """
        out: list[bytes] = []
        at, n = 0, len(fields)
        while at < n:
            length = len(fields[at])
            end = at + 1
            while end < n and len(fields[end]) == length:
                end += 1
            if end - at == 1 or length == 0:
                out.extend(self.decode(f) for f in fields[at:end])
            else:
                out.append(self._decode_equal(fields[at:end], length))
            at = end
        return b"".join(out)

    @staticmethod
    def _decode_equal(fields: Sequence[bytes], length: int) -> bytes:
        q, rest = divmod(length, _BLOCK_CHARS)
        r = _TAIL_BYTES.get(rest)
        if r is None:
            raise _malformed(f"length {length} is not a radix-91 field length")
        m = len(fields)
        joined = b"".join(fields)
        if joined.translate(None, RADIX91_ALPHABET):
            raise _malformed("character outside the radix-91 alphabet")
        digits = np.frombuffer(joined.translate(_DIGIT_OF), np.uint8)
        rows = digits.reshape(m, length)
        parts = []
        if q:
            blocks = rows[:, : q * _BLOCK_CHARS].reshape(m * q, _BLOCK_CHARS)
            parts.append(_block_bytes(blocks).reshape(m, q * _BLOCK_BYTES))
        if r:
            parts.append(_tail_bytes(rows[:, q * _BLOCK_CHARS :], r))
        out = parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)
        return out.tobytes()


_SMALL_FIELD_BLOCKS = 12
"""Fields of fewer blocks (a packet of up to ~200 characters) decode in plain
Python: 11 us against numpy's 21 us for one 128-character packet's field;
the two cross near 15 blocks (CPU time, 2-core reference machine)."""

_PAIR_VALUE = array.array(
    "h",
    (
        hi * 91 + lo if hi < 91 and lo < 91 and hi * 91 + lo < 8192 else -1
        for hi in range(256)
        for lo in range(256)
    ),
)
"""Value of a two-digit pair read as one big-endian 16-bit word; -1 if invalid."""


def _blocks_small(digits: bytes, q: int) -> bytes:
    """The ``q`` blocks at the start of ``digits`` (digit values) in plain Python:
    the ``8q`` 13-bit groups side by side are exactly the ``13q`` bytes."""
    values = list(map(_PAIR_VALUE.__getitem__, struct.unpack_from(f">{8 * q}H", digits)))
    if min(values) < 0:
        raise _malformed("radix-91 pair worth 8192 or more")
    acc = 0
    for v in values:
        acc = acc << 13 | v
    return acc.to_bytes(q * _BLOCK_BYTES, "big")


def _encode_tail(tail: bytes) -> bytes:
    """The characters of a tail of 1..12 bytes (see :class:`Radix91Encoding`)."""
    r = len(tail)
    groups, last_bits = _tail_plan(r)
    value = int.from_bytes(tail.ljust(_BLOCK_BYTES, b"\0"), "big")
    out = bytearray()
    for g in range(groups):
        v = value >> (13 * (7 - g)) & 0x1FFF
        if g == groups - 1 and last_bits <= 6:
            out.append(RADIX91_ALPHABET[v >> 7])
        else:
            out += bytes((RADIX91_ALPHABET[v // 91], RADIX91_ALPHABET[v % 91]))
    return bytes(out)


def _decode_tail(digits: bytes, r: int) -> bytes:
    """Inverse of :func:`_encode_tail`, from digit values; checks the padding."""
    groups, last_bits = _tail_plan(r)
    value = 0
    at = 0
    for g in range(groups):
        if g == groups - 1 and last_bits <= 6:
            v = digits[at] << 7
            at += 1
        else:
            v = digits[at] * 91 + digits[at + 1]
            at += 2
        if v >= 1 << 13:
            raise _malformed("radix-91 pair worth 8192 or more")
        value |= v << (13 * (7 - g))
    full = value.to_bytes(_BLOCK_BYTES, "big")
    if any(full[r:]):
        raise _malformed("nonzero padding bits in the radix-91 tail")
    return full[:r]
