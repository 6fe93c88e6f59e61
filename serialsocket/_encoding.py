"""Kermit data-field prefix encoding, vectorised with numpy.

Theory of operation
-------------------
Kermit turns each source byte into a *token* (reference/kermit.md section 3)::

    [REPT tochar(n)] [QBIN] [QCTL] char

applied in that order: a run of 3..94 equal bytes becomes one token with a
repeat count; with 8th-bit prefixing a byte >= 128 gets QBIN and loses bit 7;
a control character (low 7 bits < 32 or = 127) gets QCTL and is sent as
``ctl(byte)``; a byte whose low 7 bits equal an active prefix character gets
QCTL and is sent as itself.

*Encoding* is a table lookup: every byte value has a fixed token of 1..3
characters, so a whole buffer is encoded with a few array operations (token
lengths, a cumulative sum for output offsets, and up to three scatters).  Runs
are found with one comparison of the buffer against itself shifted by one.

*Decoding* is harder because a character's role depends on what came before
(``##`` is a literal ``#``; ``~#`` is a repeat count of 3).  The roles follow a
five-state machine (see ``_T`` below) whose state only changes inside chains of
prefix characters; after any ordinary character the state is back at "token
start" (unless that character was a repeat count).  So we guess that every
character starts in "token start", then repeatedly recompute only the positions
whose predecessor's state differs from the guess.  Real data converges in a few
rounds; an adversarial field such as ``####...`` would need one round per
character, so after ``_MAX_ROUNDS`` we switch to the sequential decoder, which
is the reference implementation and is exact for every input.

The decoder accepts what real Kermit peers send: raw 8-bit bytes when 8th-bit
prefixing is off, unprefixed control characters (C-Kermit leaves several C0
characters unprefixed by default), and prefix characters in positions where
G-Kermit's decoder takes them literally.  It rejects only what no decoder can
interpret: a field that ends inside a token, or a repeat count outside 1..94.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ._errors import LocalProtocolError, MalformedDataError

__all__ = ["EIGHT_BIT_CLEAN", "MAX_TOKEN_LENGTH", "PRINTABLE", "Encoding"]

U8 = npt.NDArray[np.uint8]
I64 = npt.NDArray[np.int64]

MAX_TOKEN_LENGTH = 5
"""Longest encoding of one token: REPT, count, QBIN, QCTL, char."""

_MAX_RUN = 94
"""A repeat count is one ``tochar`` character, so runs longer than 94 are split."""

_MIN_RUN = 3
"""Runs of two are sent twice: ``~"X`` would be longer than ``XX``."""

_SEQUENTIAL_BELOW = 640
"""Fields shorter than this decode faster one token at a time: the vectorised
path has a fixed cost of ~60 us, the sequential one ~0.12 us per character of
random binary (measured on the 2-core reference machine; the two cross at
600-700 characters)."""

_MAX_ROUNDS = 32
"""Fixed-point rounds before the decoder falls back to the sequential path.

Real encoders never chain more than four prefix characters, so valid data
converges within a handful of rounds; the bound only matters for hostile input."""

# Character classes for decoding.
_OTHER, _C_REPT, _C_QBIN, _C_QCTL = 0, 1, 2, 3
# Decoder states: before a token, after REPT, after the count, after QBIN, after QCTL.
_S0, _COUNT, _AFTER_COUNT, _AFTER_QBIN, _AFTER_QCTL = 0, 1, 2, 3, 4
# Roles of a character in its token.
_LIT, _REPT, _CNT, _QBIN, _QCTL = 0, 1, 2, 3, 4

# _T[state, class] -> next state.  Rows: S0, COUNT, AFTER_COUNT, AFTER_QBIN, AFTER_QCTL.
# Columns: other, REPT char, QBIN char, QCTL char.  This mirrors gkermit.c decode():
# after REPT the next char is always the count; after the count only QBIN/QCTL are
# prefixes; after QBIN only QCTL is; after QCTL the next char is always literal.
_T = np.array(
    [
        [_S0, _COUNT, _AFTER_QBIN, _AFTER_QCTL],
        [_AFTER_COUNT, _AFTER_COUNT, _AFTER_COUNT, _AFTER_COUNT],
        [_S0, _S0, _AFTER_QBIN, _AFTER_QCTL],
        [_S0, _S0, _S0, _AFTER_QCTL],
        [_S0, _S0, _S0, _S0],
    ],
    dtype=np.int8,
)
_R = np.array(
    [
        [_LIT, _REPT, _QBIN, _QCTL],
        [_CNT, _CNT, _CNT, _CNT],
        [_LIT, _LIT, _QBIN, _QCTL],
        [_LIT, _LIT, _LIT, _QCTL],
        [_LIT, _LIT, _LIT, _LIT],
    ],
    dtype=np.int8,
)

_T_FLAT = _T.ravel()
"""Row-major flattening: ``_T_FLAT[state * 4 + class]`` is a 1-D gather."""
_T_TRANS = _T_FLAT.tobytes().ljust(256, b"\0")
_R_TRANS = _R.ravel().tobytes().ljust(256, b"\0")
"""The same tables as ``bytes.translate`` tables (indices 0..19 used)."""


def _lookup(table: bytes, index: npt.NDArray[np.int8]) -> bytes:
    """``table[index]`` element-wise, through ``bytes.translate``."""
    return index.tobytes().translate(table)


def _legal_prefix(c: int) -> bool:
    """Kermit allows prefix characters 33..62 and 96..126 (ckcfns.c spar)."""
    return 33 <= c <= 62 or 96 <= c <= 126


@dataclass(frozen=True, slots=True)
class Encoding:
    """A prefix-encoding profile: which prefix characters are in force.

    Attributes:
        qctl: control prefix (Kermit QCTL), always active; default ``#``.
        qbin: 8th-bit prefix (QBIN) or None when 8-bit bytes travel raw
            (the line is 8-bit clean); default ``&``.
        rept: repeat-count prefix (REPT) or None for no run compression;
            default ``~``.

    With ``qbin`` set, every encoded character is printable ASCII (32..126):
    the paper's requirement for a line that carries only printable ASCII plus
    SOH and CR.  Without it, bytes 0xA0..0xFE travel raw.  All C0 controls,
    DEL, C1 controls and 0xFF are always prefixed, so SOH and CR never appear
    in a data field under any profile.

    Raises:
        LocalProtocolError: a prefix is not a legal Kermit prefix character
            (33..62 or 96..126) or two prefixes are the same.
    """

    qctl: int = ord("#")
    qbin: int | None = ord("&")
    rept: int | None = ord("~")

    def __post_init__(self) -> None:
        chars = [c for c in (self.qctl, self.qbin, self.rept) if c is not None]
        for c in chars:
            if not _legal_prefix(c):
                raise LocalProtocolError(f"illegal prefix character {c!r}: use 33..62 or 96..126")
        if len(set(chars)) != len(chars):
            raise LocalProtocolError(f"prefix characters must differ: {bytes(chars)!r}")

    @property
    def printable(self) -> bool:
        """True when every encoded character is printable ASCII (8th-bit prefixing on)."""
        return self.qbin is not None

    # -- encoding ---------------------------------------------------------------

    def encode(self, data: bytes | bytearray | memoryview) -> bytes:
        """Encode a whole buffer into one data field (no length limit)."""
        arr = np.frombuffer(data, dtype=np.uint8)
        if arr.size == 0:
            return b""
        units, counts = self._units(arr)
        out, _ = self._emit(units, counts, None)
        return out

    def encode_prefix(
        self, data: bytes | bytearray | memoryview, capacity: int
    ) -> tuple[bytes, int]:
        """Encode as much of ``data`` as fits in ``capacity`` characters.

        Tokens are never split across packets.  Work is proportional to the
        capacity, not to ``len(data)``, so a long send queue can be cut into
        packets one at a time.

        Args:
            data: the bytes waiting to be sent.
            capacity: room in the data field, at least :data:`MAX_TOKEN_LENGTH`.

        Returns:
            ``(field, consumed)``: the encoded data field (at most ``capacity``
            characters) and how many bytes of ``data`` it carries; ``consumed``
            is at least 1 when ``data`` is not empty.

        Raises:
            LocalProtocolError: ``capacity`` is too small to hold any token.
        """
        if capacity < MAX_TOKEN_LENGTH:
            raise LocalProtocolError(
                f"data field capacity {capacity} is below {MAX_TOKEN_LENGTH}: "
                "use a larger maximum packet length"
            )
        view = memoryview(data).cast("B")
        total = len(view)
        if total == 0:
            return b"", 0
        # Each byte costs at least one character unless it is part of a run, so
        # start with `capacity` bytes and widen only for compressible data.
        span = capacity
        while True:
            chunk = np.frombuffer(view[:span], dtype=np.uint8)
            units, counts = self._units(chunk)
            out, used_units = self._emit(units, counts, capacity)
            if used_units < len(units) or span >= total:
                consumed = used_units if counts is None else int(counts[:used_units].sum())
                return out, consumed
            span *= 4

    def encode_fields(
        self, data: bytes | bytearray | memoryview, capacity: int, count: int
    ) -> list[tuple[bytes, int]]:
        """Cut up to ``count`` consecutive data fields in one vectorised pass.

        Equivalent to calling :meth:`encode_prefix` ``count`` times on what is
        left, but the per-call cost is paid once: a sender filling a window of
        31 packets encodes them together.

        Returns:
            A list of ``(field, consumed)`` pairs, in order, stopping early when
            ``data`` runs out.

        Raises:
            LocalProtocolError: ``capacity`` is too small to hold any token.
        """
        if capacity < MAX_TOKEN_LENGTH:
            raise LocalProtocolError(
                f"data field capacity {capacity} is below {MAX_TOKEN_LENGTH}: "
                "use a larger maximum packet length"
            )
        view = memoryview(data).cast("B")
        if len(view) == 0 or count < 1:
            return []
        if count == 1:
            return [self.encode_prefix(view, capacity)]
        tok = _token_table(self.qctl, self.qbin, self.rept)
        # Take enough source to fill every field: more than count x capacity
        # characters once encoded (compressible data needs a wider slice).
        # Then only the last field can reach the end of the slice early.
        span = capacity * count
        while True:
            arr = np.frombuffer(view[:span], dtype=np.uint8)
            units, counts = self._units(arr)
            lens = tok.width[units].astype(np.int64)
            if counts is not None:
                lens += 2 * (counts >= _MIN_RUN)
            ends = np.cumsum(lens)
            if ends[-1] > capacity * count or span >= len(view):
                break
            span *= 4
        flat, _ = self._emit(units, counts, None)
        src_ends = np.cumsum(counts) if counts is not None else np.arange(1, units.size + 1)
        fields: list[tuple[bytes, int]] = []
        char_base = unit_base = src_base = 0
        while len(fields) < count and unit_base < units.size:
            cut = int(np.searchsorted(ends, char_base + capacity, side="right"))
            if cut == units.size and len(fields) == count - 1 and len(view) > len(arr):
                # The last field may want more source than the slice held.
                field, used = self.encode_prefix(view[src_base:], capacity)
                fields.append((field, used))
                return fields
            char_end = int(ends[cut - 1])
            src_end = int(src_ends[cut - 1])
            fields.append((flat[char_base:char_end], src_end - src_base))
            char_base, unit_base, src_base = char_end, cut, src_end
        if len(fields) < count and src_base < len(view):
            fields.extend(self.encode_fields(view[src_base:], capacity, count - len(fields)))
        return fields

    def _units(self, arr: U8) -> tuple[U8, I64 | None]:
        """Split a buffer into tokens: (byte values, repeat counts or None).

        Only runs of three or more are touched; every other byte stays its own
        token, so data without long runs costs two comparisons.
        """
        n = arr.size
        if self.rept is None or n < _MIN_RUN:
            return arr, None
        same = arr[1:] == arr[:-1]
        if not bool(np.any(same[1:] & same[:-1])):
            return arr, None
        starts = np.flatnonzero(np.concatenate(([True], ~same)))
        lengths = np.diff(np.append(starts, n))
        is_long = lengths >= _MIN_RUN
        run_start, run_len = starts[is_long], lengths[is_long]
        full, rest = np.divmod(run_len, _MAX_RUN)
        # Drop every byte inside a long run, then re-admit one representative
        # byte per token: one per full 94-byte chunk, one for a tail of 3..93,
        # or the tail's one or two bytes themselves.
        edge = np.zeros(n + 1, dtype=np.int32)
        np.add.at(edge, run_start, 1)
        np.add.at(edge, run_start + run_len, -1)
        keep = np.cumsum(edge[:n]) == 0
        counts = np.ones(n, dtype=np.int64)
        n_full = int(full.sum())
        if n_full:
            chunk_index = np.arange(n_full) - np.repeat(np.cumsum(full) - full, full)
            chunk_pos = np.repeat(run_start, full) + chunk_index * _MAX_RUN
            keep[chunk_pos] = True
            counts[chunk_pos] = _MAX_RUN
        tail = run_start + full * _MAX_RUN
        tail_rep = rest >= _MIN_RUN
        keep[tail[tail_rep]] = True
        counts[tail[tail_rep]] = rest[tail_rep]
        keep[tail[(rest == 1) | (rest == 2)]] = True
        keep[tail[rest == 2] + 1] = True
        return arr[keep], counts[keep]

    def _emit(self, units: U8, counts: I64 | None, capacity: int | None) -> tuple[bytes, int]:
        """Write tokens; with a capacity, only the longest prefix that fits.

        Tokens are laid out in a zero-padded grid, one row per token, and the
        padding is squeezed out.  Zero never occurs inside a token (NUL is
        always control-prefixed), so the squeeze is exact.
        """
        tok = _token_table(self.qctl, self.qbin, self.rept)
        tok_len = tok.width
        rep = None if counts is None else counts >= _MIN_RUN
        n_units = units.size
        if capacity is not None:
            lens = tok_len[units].astype(np.int32)
            if rep is not None:
                lens += 2 * rep
            ends = np.cumsum(lens)
            if ends[-1] > capacity:
                n_units = int(np.searchsorted(ends, capacity, side="right"))
                units = units[:n_units]
                if rep is not None and counts is not None:
                    rep, counts = rep[:n_units], counts[:n_units]
        if n_units == 0:
            return b"", 0
        if rep is None or counts is None or self.rept is None or not rep.any():
            grid = tok.packed32[units].view(np.uint8)
        else:
            # Little-endian 8-byte rows: REPT, count, then the token's three bytes.
            rows = tok.packed64[units]
            prefix = np.uint64(self.rept) | (
                counts[rep].astype(np.uint64) + np.uint64(32)
            ) << np.uint64(8)
            rows[rep] |= prefix
            grid = rows.view(np.uint8)
        return grid[grid != 0].tobytes(), n_units

    # -- decoding ---------------------------------------------------------------

    def decode(self, field: bytes | bytearray | memoryview) -> bytes:
        """Decode one data field back to the original bytes.

        Raises:
            MalformedDataError: the field ends inside a token or carries a
                repeat count outside 1..94.
        """
        raw_field = bytes(field)
        if len(raw_field) < _SEQUENTIAL_BELOW:
            return self._decode_sequential(raw_field)
        arr = np.frombuffer(raw_field, dtype=np.uint8)
        n = arr.size
        # All small-table lookups go through bytes.translate: it runs at memory
        # speed, several times faster than numpy fancy indexing on int8 tables.
        cls = np.frombuffer(
            raw_field.translate(_class_table(self.qctl, self.qbin, self.rept)), np.int8
        )
        st = np.zeros(n, dtype=np.int8)
        # Round 0 guesses "token start" everywhere; round 1 redoes every position
        # at once; later rounds touch only positions whose predecessor changed.
        st[1:] = np.frombuffer(_lookup(_T_TRANS, cls[:-1]), np.int8)
        new = np.frombuffer(_lookup(_T_TRANS, st[:-1] * 4 + cls[:-1]), np.int8)
        changed = np.flatnonzero(new != st[1:]) + 1
        st[1:] = new
        pending = changed[changed < n - 1] + 1
        rounds = 1
        while pending.size:
            rounds += 1
            if rounds > _MAX_ROUNDS:
                return self._decode_sequential(raw_field)
            new = _T_FLAT[st[pending - 1] * 4 + cls[pending - 1]]
            changed = pending[new != st[pending]]
            st[pending] = new
            pending = changed[changed < n - 1] + 1
        if _T_FLAT[st[-1] * 4 + cls[-1]] != _S0:
            raise MalformedDataError(
                "data field ends inside a prefix sequence",
                error_hint="Malformed data field (dangling prefix)",
            )
        role = np.frombuffer(_lookup(_R_TRANS, st * 4 + cls), np.int8)
        lit = np.flatnonzero(role == _LIT)
        values = arr[lit].copy()
        lit_state = st[lit]
        escaped = lit_state == _AFTER_QCTL
        low = values & 0x7F
        values[escaped & (low >= 63) & (low <= 95)] ^= 64
        # Walk back from each literal over its QCTL and QBIN to find the token's prefixes.
        at = lit - escaped
        prev_state = st[at]
        has_qbin = prev_state == _AFTER_QBIN
        values[has_qbin] |= 0x80
        at = at - has_qbin
        has_count = st[at] == _AFTER_COUNT
        if not has_count.any():
            return values.tobytes()
        counts = np.ones(values.size, dtype=np.int64)
        raw = arr[at[has_count] - 1].astype(np.int64) - 32
        if raw.min() < 1 or raw.max() > _MAX_RUN:
            raise MalformedDataError(
                "repeat count outside 1..94", error_hint="Malformed data field (repeat count)"
            )
        counts[has_count] = raw
        return np.repeat(values, counts).tobytes()

    def _decode_sequential(self, field: bytes) -> bytes:
        """Reference decoder, one token at a time (gkermit.c decode order).

        Plain characters (most of any field) take one comparison chain and an
        ``append``; only prefixed tokens go through the full decode.
        """
        out = bytearray()
        append = out.append
        rept, qbin, qctl = self.rept, self.qbin, self.qctl
        i, n = 0, len(field)
        dangling = MalformedDataError(
            "data field ends inside a prefix sequence",
            error_hint="Malformed data field (dangling prefix)",
        )
        while i < n:
            c = field[i]
            i += 1
            if c != rept and c != qbin and c != qctl:
                append(c)
                continue
            count = 1
            if c == rept:
                if i + 1 >= n:
                    raise dangling
                count = field[i] - 32
                if not 1 <= count <= _MAX_RUN:
                    raise MalformedDataError(
                        "repeat count outside 1..94",
                        error_hint="Malformed data field (repeat count)",
                    )
                c = field[i + 1]
                i += 2
            high = 0
            if c == qbin:
                if i >= n:
                    raise dangling
                high = 0x80
                c = field[i]
                i += 1
            if c == qctl:
                if i >= n:
                    raise dangling
                c = field[i]
                i += 1
                if 63 <= (c & 0x7F) <= 95:
                    c ^= 64
            if count == 1:
                append(c | high)
            else:
                out += bytes((c | high,)) * count
        return bytes(out)


@dataclass(frozen=True, slots=True)
class _TokenTable:
    """Every byte value's token, zero-padded and packed little-endian.

    ``packed32`` holds the token in bytes 0..2; ``packed64`` holds it in bytes
    2..4, leaving bytes 0..1 free for a repeat prefix and count.
    """

    width: U8
    packed32: npt.NDArray[np.uint32]
    packed64: npt.NDArray[np.uint64]


@functools.lru_cache(maxsize=16)
def _token_table(qctl: int, qbin: int | None, rept: int | None) -> _TokenTable:
    """Build the token table of one prefix profile (cached: profiles are few)."""
    tok = np.zeros((256, 4), dtype=np.uint8)
    width = np.zeros(256, dtype=np.uint8)
    specials = {c for c in (qctl, qbin, rept) if c is not None}
    for b in range(256):
        chars: list[int] = []
        c = b
        if qbin is not None and c & 0x80:
            chars.append(qbin)
            c &= 0x7F
        low = c & 0x7F
        if low < 32 or low == 127:
            chars += [qctl, c ^ 64]
        elif low in specials:
            chars += [qctl, c]
        else:
            chars.append(c)
        tok[b, : len(chars)] = chars
        width[b] = len(chars)
    packed32 = tok.view("<u4").reshape(256).astype(np.uint32)
    packed64 = packed32.astype(np.uint64) << np.uint64(16)
    for arr in (width, packed32, packed64):
        arr.setflags(write=False)
    return _TokenTable(width, packed32, packed64)


@functools.lru_cache(maxsize=16)
def _class_table(qctl: int, qbin: int | None, rept: int | None) -> bytes:
    """Decoder character classes as a translate table; prefixes match the full byte."""
    cls = bytearray(256)
    cls[qctl] = _C_QCTL
    if qbin is not None:
        cls[qbin] = _C_QBIN
    if rept is not None:
        cls[rept] = _C_REPT
    return bytes(cls)


PRINTABLE = Encoding()
"""The default profile: ``#`` controls, ``&`` 8th bit, ``~`` repeats; printable output."""

EIGHT_BIT_CLEAN = Encoding(qbin=None)
"""For lines known to carry all 256 byte values: no 8th-bit prefixing."""
