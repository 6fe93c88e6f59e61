"""Kermit data-field prefix encoding, vectorised with numpy and ``bytes`` tricks.

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
characters, stored zero-padded in one machine word.  A buffer is encoded by
gathering the words (``ndarray.take``) and deleting the padding with
``bytes.translate(None, b"\\0")``, which runs at memory speed; zero never
occurs inside a token (NUL is always control-prefixed).  Runs of three or more
equal bytes are found with one comparison of the buffer against itself shifted
by one; the few runs of ordinary data are spliced in as repeat tokens.

*Decoding* is harder because a character's role depends on what came before
(``##`` is a literal ``#``; ``~#`` is a repeat count of 3).  The roles follow a
five-state machine (see ``_T`` below) whose state only changes inside chains of
prefix characters; after any ordinary character the state is back at "token
start" (unless that character was a repeat count).

* Short fields (one packet's data field) are split with one regular
  expression whose alternatives are exactly the machine's prefixed tokens
  (``re.split`` with a capturing group: ordinary characters between tokens
  come out as runs), and each prefixed token is looked up in a table.
* Long fields (a window of packets decoded together) guess that every
  character follows a token start, then let the guesses settle: fields under
  64 KiB recompute every position from the state two characters back (the
  machine's table composed with itself), longer ones only the positions
  whose predecessor changed.  Real data settles in a few rounds; an
  adversarial field such as ``####...`` would need one round per character
  or two, so after ``_MAX_ROUNDS`` we switch to the short-field decoder,
  which is exact for every input.  Once the states are known, every output
  byte is computed in place (XOR 64 after QCTL, OR 128 after QBIN) and the
  literals are compressed out in one pass.

:func:`_reference_encode`, :func:`_reference_encode_prefix` and
:func:`_reference_decode` are the plain one-token-at-a-time definitions
(gkermit.c order); the tests check the fast paths against them for every
profile.

The decoder accepts what real Kermit peers send: raw 8-bit bytes when 8th-bit
prefixing is off, unprefixed control characters (C-Kermit leaves several C0
characters unprefixed by default), and prefix characters in positions where
G-Kermit's decoder takes them literally.  It rejects only what no decoder can
interpret: a field that ends inside a token, or a repeat count outside 1..94.
"""

from __future__ import annotations

import bisect
import functools
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

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

_VECTOR_FROM = 768
"""Fields at least this long decode with the vectorised path: it costs
~30 us + 7 ns per character of random binary (a few dozen numpy calls), the
regular-expression path 35-55 ns per character (CPU time on the 2-core
reference machine; the two cross near 700-1000 characters)."""

_SPLICE_RUNS_PER = 1024
"""Encode runs one by one (a Python loop) while there are at most one per this
many bytes, as in ordinary data; denser runs take the all-numpy path."""

_MAX_ROUNDS = 32
"""Fixed-point rounds before the decoder falls back to the short-field path.

Real encoders never chain more than four prefix characters, so valid data
converges within a handful of rounds; the bound only matters for hostile input."""

# Character classes for decoding.
_OTHER, _C_REPT, _C_QBIN, _C_QCTL = 0, 1, 2, 3
# Decoder states: before a token, after REPT, after the count, after QBIN, after QCTL.
_S0, _COUNT, _AFTER_COUNT, _AFTER_QBIN, _AFTER_QCTL = 0, 1, 2, 3, 4

# _T[state, class] -> next state.  Rows: S0, COUNT, AFTER_COUNT, AFTER_QBIN, AFTER_QCTL.
# Columns: other, REPT char, QBIN char, QCTL char.  This mirrors gkermit.c decode():
# after REPT the next char is always the count; after the count only QBIN/QCTL are
# prefixes; after QBIN only QCTL is; after QCTL the next char is always literal.
# A character is a literal exactly when the state after it is S0.
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

_T_TUPLE: tuple[tuple[int, ...], ...] = tuple(tuple(int(x) for x in row) for row in _T)
"""``_T`` as Python ints, for the few steps :meth:`Encoding.plain_whole` takes."""

_UNKNOWN = -1
"""Not a decoder state: :meth:`Encoding._state_at` could not tell."""

_PLAIN_CHAIN_MAX = 8
"""Prefix characters in a row :meth:`Encoding.plain_whole` reads before it
gives up (a real encoder writes at most three, ``&#&`` for 0xA6, and a
fourth character before a quoted REPT: ``&#~``)."""

_T_FLAT = _T.ravel()
"""Row-major flattening: ``_T_FLAT[state * 4 + class]`` is a 1-D gather."""
_T_TRANS = _T_FLAT.tobytes().ljust(256, b"\0")
"""The same table as a ``bytes.translate`` table (indices 0..19 used)."""
_T2_TRANS = bytes(
    int(_T[_T[s, c1], c2]) for s in range(5) for c1 in range(4) for c2 in range(4)
).ljust(256, b"\0")
"""Two steps at once: ``_T2_TRANS[state * 16 + class1 * 4 + class2]`` (indices 0..79)."""

_DENSE_BELOW = 1 << 16
"""Fields shorter than this settle their states with whole-array rounds two
characters at a time; longer ones with sparse one-character rounds."""

_CTL_RANGE = bytes(64 if 63 <= (c & 0x7F) <= 95 else 0 for c in range(256))
"""``translate`` table: 64 where ``ctl()`` applies after QCTL ('?'..'_', either half)."""


def _lookup(table: bytes, index: npt.NDArray[np.int8]) -> npt.NDArray[np.int8]:
    """``table[index]`` element-wise, through ``bytes.translate``."""
    return np.frombuffer(index.tobytes().translate(table), np.int8)


def _legal_prefix(c: int) -> bool:
    """Kermit allows prefix characters 33..62 and 96..126 (ckcfns.c spar)."""
    return 33 <= c <= 62 or 96 <= c <= 126


def _dangling() -> MalformedDataError:
    return MalformedDataError(
        "data field ends inside a prefix sequence",
        error_hint="Malformed data field (dangling prefix)",
    )


def _bad_count() -> MalformedDataError:
    return MalformedDataError(
        "repeat count outside 1..94", error_hint="Malformed data field (repeat count)"
    )


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
        tok = _token_table(self.qctl, self.qbin, self.rept)
        runs = self._runs(arr)
        if runs is None:
            return tok.packed.take(arr).tobytes().translate(None, b"\0")
        run_start, run_len = runs
        if run_start.size * _SPLICE_RUNS_PER > arr.size:
            units, counts = self._split_runs(arr, run_start, run_len)
            out, _ = self._emit(units, counts, None)
            return out
        # Few runs (ordinary data): encode the stretches between them whole and
        # write each run's tokens directly.
        assert self.rept is not None
        packed, tokens = tok.packed, tok.tokens
        parts: list[bytes] = []
        prev = 0
        for s, n in zip(run_start.tolist(), run_len.tolist(), strict=True):
            parts.append(packed.take(arr[prev:s]).tobytes())
            parts.append(_run_tokens(self.rept, tokens[arr[s]], n))
            prev = s + n
        parts.append(packed.take(arr[prev:]).tobytes())
        return b"".join(parts).translate(None, b"\0")

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
            # The field must end at a token that more source cannot change: the
            # slice may cut a run short (two bytes of a longer run are two
            # tokens that fit where its repeat token does not).
            # (At most two units are open, so most slices need no look.)
            final = (
                span >= total
                or used_units < len(units) - 2
                or used_units < len(units) - self._open_units(chunk)
            )
            if final:
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
        # Then only the last field can reach the end of the slice early.  The
        # first guess scales by the token widths of the first 256 bytes (plus
        # 12 %): binary data needs about half the bytes that text does.
        sample = bytes(view[:256]).translate(tok.width_table)
        span = int(capacity * count * len(sample) * 1.12 / sum(sample)) + 64
        while True:
            arr = np.frombuffer(view[:span], dtype=np.uint8)
            units, counts = self._units(arr)
            if counts is None:
                ends = np.cumsum(tok.width.take(units), dtype=np.int64)
            else:
                lens = tok.width.take(units).astype(np.int64)
                lens += 2 * (counts >= _MIN_RUN)
                ends = np.cumsum(lens)
            if ends[-1] > capacity * count or span >= len(view):
                break
            span *= 4
        if counts is None:
            flat = tok.packed.take(units).tobytes().translate(None, b"\0")
        else:
            flat, _ = self._emit(units, counts, None)
        # Each field ends at the last token that fits: a binary search per
        # field (a few dozen searches; a numpy call each would cost more).
        # (A memoryview of the int64 array: bisect reads it without converting
        # thousands of elements to Python ints first.)
        char_ends = ends.data
        src_ends = None if counts is None else np.cumsum(counts).data
        n_units = len(char_ends)
        fields: list[tuple[bytes, int]] = []
        append = fields.append
        bisect_right = bisect.bisect_right
        char_base = unit_base = src_base = made = 0
        more = len(view) > len(arr)
        # With more source beyond the slice, its last units may not be final:
        # a run the slice cut short is one or two single tokens here and one
        # repeat token in the whole (encode_prefix's _open_units).  A field
        # that would take any of them, or end at the slice's end, is cut by
        # encode_prefix, which reads as far as it needs.
        final_units = n_units - max(self._open_units(arr), 1) if more else n_units
        # A field holds at least capacity / 5 tokens (one is at most 5
        # characters) and at most `capacity` (one is at least 1): search there.
        # (Plain comparisons, not min(): this loop runs once per packet.)
        fewest = capacity // MAX_TOKEN_LENGTH
        while unit_base < n_units:
            lo = unit_base + fewest
            if lo > n_units:
                lo = n_units
            hi = unit_base + capacity
            if hi > n_units:
                hi = n_units
            cut = bisect_right(char_ends, char_base + capacity, lo, hi)
            if cut > final_units:
                field = self.encode_prefix(view[src_base:], capacity)
                append(field)
                rest = src_base + field[1]
                if made + 1 < count and rest < len(view):
                    fields.extend(self.encode_fields(view[rest:], capacity, count - made - 1))
                return fields
            char_end = char_ends[cut - 1]
            src_end = cut if src_ends is None else src_ends[cut - 1]
            append((flat[char_base:char_end], src_end - src_base))
            made += 1
            if made == count:
                return fields
            char_base, unit_base, src_base = char_end, cut, src_end
        if len(fields) < count and src_base < len(view):
            fields.extend(self.encode_fields(view[src_base:], capacity, count - len(fields)))
        return fields

    def _open_units(self, chunk: U8) -> int:
        """Units at the end of a slice that more source could still change: the
        piece of its trailing run of equal bytes after the run's whole
        ``_MAX_RUN``-byte tokens (one repeat token, or one or two single ones)."""
        if self.rept is None:
            return 0
        differ = np.flatnonzero(chunk != chunk[-1])
        run = chunk.size - (int(differ[-1]) + 1 if differ.size else 0)
        rest = run % _MAX_RUN
        return rest if rest < _MIN_RUN else 1

    def _runs(self, arr: U8) -> tuple[I64, I64] | None:
        """Maximal runs of at least three equal bytes: (starts, lengths), or None.

        ``arr[t] == arr[t+1] == arr[t+2]`` marks a triple; the triples of one
        run are consecutive positions, and those of two runs are at least three
        apart, so runs are the groups of consecutive triple positions.
        """
        if self.rept is None or arr.size < _MIN_RUN:
            return None
        same = arr[1:] == arr[:-1]
        triple = same[1:] & same[:-1]
        if not triple.any():
            return None
        at = np.flatnonzero(triple)
        breaks = np.flatnonzero(np.diff(at) != 1)
        first = at[np.concatenate(([0], breaks + 1))]
        last = at[np.concatenate((breaks, [at.size - 1]))]
        return first, last - first + _MIN_RUN

    def _units(self, arr: U8) -> tuple[U8, I64 | None]:
        """Split a buffer into tokens: (byte values, repeat counts or None)."""
        runs = self._runs(arr)
        if runs is None:
            return arr, None
        return self._split_runs(arr, *runs)

    @staticmethod
    def _split_runs(arr: U8, run_start: I64, run_len: I64) -> tuple[U8, I64]:
        """Tokens of a buffer whose runs are known: one unit per byte outside
        the runs, one per repeat token inside (94 bytes each, then the rest).
        """
        n = arr.size
        full, rest = np.divmod(run_len, _MAX_RUN)
        # Drop every byte inside a run, then re-admit one representative
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

        Tokens are gathered zero-padded, one machine word each, and the padding
        is deleted.  Zero never occurs inside a token (NUL is always
        control-prefixed) nor in a repeat prefix, so the squeeze is exact.
        """
        tok = _token_table(self.qctl, self.qbin, self.rept)
        rep = None if counts is None else counts >= _MIN_RUN
        n_units = units.size
        if capacity is not None:
            lens = tok.width.take(units).astype(np.int32)
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
        grid: npt.NDArray[np.unsignedinteger[Any]]
        if rep is None or counts is None or self.rept is None or not rep.any():
            grid = tok.packed.take(units)
        else:
            # Little-endian 8-byte rows: REPT, count, then the token's three bytes.
            grid = tok.packed64.take(units)
            prefix = np.uint64(self.rept) | (
                counts[rep].astype(np.uint64) + np.uint64(32)
            ) << np.uint64(8)
            grid[rep] |= prefix
        return grid.tobytes().translate(None, b"\0"), n_units

    # -- decoding ---------------------------------------------------------------

    def decode(self, field: bytes | bytearray | memoryview) -> bytes:
        """Decode one data field back to the original bytes.

        Raises:
            MalformedDataError: the field ends inside a token or carries a
                repeat count outside 1..94.
        """
        raw = bytes(field)
        if len(raw) < _VECTOR_FROM:
            return self._decode_split(raw)
        return self._decode_vector(raw)

    def decode_fields(self, fields: Sequence[bytes]) -> bytes:
        """Decode consecutive data fields (what one read delivered) together.

        Exactly as the fields one by one: a token never crosses a field, so a
        field that ends inside a prefix sequence is malformed even when the
        next field would complete it.  A long input takes the vectorised path
        once, checking that every field boundary is a token boundary.

        Raises:
            MalformedDataError: as :meth:`decode`, for any of the fields.
        """
        if len(fields) == 1:
            return self.decode(fields[0])
        raw = b"".join(fields)
        if len(raw) < _VECTOR_FROM:
            return b"".join(map(self.decode, fields))
        settled = self._settled_states(raw)
        if settled is None:
            return b"".join(map(self.decode, fields))
        st, cls = settled
        if _T_FLAT[st[-1] * 4 + cls[-1]] != _S0:
            raise _dangling()
        cuts = np.cumsum(np.fromiter(map(len, fields[:-1]), np.int64, len(fields) - 1))
        cuts = cuts[cuts < len(raw)]
        if cuts.size and (st[cuts] != _S0).any():
            raise _dangling()
        return self._emit_decoded(raw, st)

    def plain_whole(self, field: bytes) -> bool:
        """``field`` holds no repeat token and ends on a token boundary.

        Such a field decodes without error (every token is whole) to at most
        ``len(field)`` bytes (only a repeat token yields more bytes than it
        has characters), so a receiver may count it against its buffer at
        ``len(field)`` and decode it later together with the fields that
        follow it (``Receiver.take_fields``).  False says nothing: decode it
        now.  Cheap for real fields: it reads only the REPT characters (a
        quoted ``~`` in binary data) and the field's end, each with the
        prefix characters just before it.
        """
        rept = self.rept
        if rept is not None:
            at = field.find(rept)
            while at >= 0:
                if self._state_at(field, at) in (_S0, _UNKNOWN):
                    return False  # a repeat prefix (or too long a chain to tell)
                at = field.find(rept, at + 1)
        return self._state_at(field, len(field)) == _S0

    def _state_at(self, field: bytes, at: int) -> int:
        """The decoder's state before ``field[at]`` (``_S0``: a token starts
        there), read from the chain of prefix characters just before it, for
        a field with no repeat token before ``at``; ``_UNKNOWN`` when the
        chain is longer than :data:`_PLAIN_CHAIN_MAX` (the caller gives up)."""
        qctl, qbin, rept = self.qctl, self.qbin, self.rept
        i = at
        while i and (field[i - 1] == qctl or field[i - 1] == qbin or field[i - 1] == rept):
            i -= 1
            if at - i > _PLAIN_CHAIN_MAX:
                return _UNKNOWN
        # The character before the chain is an ordinary one that is not a
        # repeat count (no repeat token comes before): a token ends there.
        state = _S0
        for c in field[i:at]:
            cls = _C_QCTL if c == qctl else _C_QBIN if c == qbin else _C_REPT
            state = _T_TUPLE[state][cls]
        return state

    def _decode_split(self, raw: bytes) -> bytes:
        """Short fields: tokenise with one regular expression, look tokens up."""
        table = _split_table(self.qctl, self.qbin, self.rept)
        parts = table.pattern.split(raw)
        if len(parts) == 1:
            if table.prefix.search(raw) is not None:
                raise _dangling()
            return raw
        # A prefix character outside every token can only be one that ran out
        # of field (every prefixed token is at most 5 characters, so a failed
        # match is within the last 4): check the last few ordinary runs.
        search = table.prefix.search
        for plain in parts[-7::2]:
            if search(plain) is not None:
                raise _dangling()
        parts[1::2] = map(table.tokens.__getitem__, parts[1::2])
        return b"".join(parts)

    def _decode_vector(self, raw: bytes) -> bytes:
        """Long fields: all positions at once (see the module docstring)."""
        settled = self._settled_states(raw)
        if settled is None:
            return self._decode_split(raw)
        st, cls = settled
        if _T_FLAT[st[-1] * 4 + cls[-1]] != _S0:
            raise _dangling()
        return self._emit_decoded(raw, st)

    def _settled_states(
        self, raw: bytes
    ) -> tuple[npt.NDArray[np.int8], npt.NDArray[np.int8]] | None:
        """The tokeniser's state before each character of ``raw`` (non-empty)
        and each character's class, or None if they have not settled after
        ``_MAX_ROUNDS`` (the caller then tokenises sequentially)."""
        n = len(raw)
        # All small-table lookups go through bytes.translate: it runs at memory
        # speed, several times faster than numpy fancy indexing on int8 tables.
        cls_table, start_table = _class_table(self.qctl, self.qbin, self.rept)
        cls = np.frombuffer(raw.translate(cls_table), np.int8)
        # st[i] is the state before character i.  Round 0 guesses that the
        # character before is a token start; then the guesses settle.
        st = np.empty(n, dtype=np.int8)
        st[0] = _S0
        st[1:] = np.frombuffer(raw.translate(start_table), np.int8)[:-1]
        settled = (
            self._settle_in_pairs(st, cls) if n < _DENSE_BELOW else self._settle_sparse(st, cls)
        )
        return (st, cls) if settled else None

    @staticmethod
    def _settle_in_pairs(st: npt.NDArray[np.int8], cls: npt.NDArray[np.int8]) -> bool:
        """Fixed point of the states, two characters per step (medium fields).

        ``st[i] = T2[st[i-2], cls[i-2], cls[i-1]]`` with ``T2`` the machine's
        table composed with itself: every full-array round fixes chains two
        characters further, so a field needs half the rounds, each a handful
        of numpy calls (their fixed cost is what matters below ~64 KiB).
        Returns False if it has not settled after ``_MAX_ROUNDS``.
        """
        if st.size < 3:
            return True
        pair = cls[:-2] * 4 + cls[1:-1]
        for _ in range(_MAX_ROUNDS):
            # _lookup written out, compared as bytes: np.array_equal's own
            # checks cost more than the comparison on a field of a few KB.
            new = (st[:-2] * 16 + pair).tobytes().translate(_T2_TRANS)
            if new == st[2:].tobytes():
                return True
            st[2:] = np.frombuffer(new, np.int8)
        return False

    @staticmethod
    def _settle_sparse(st: npt.NDArray[np.int8], cls: npt.NDArray[np.int8]) -> bool:
        """Fixed point of the states: one full round, then only the positions
        whose predecessor changed (long fields, where whole-array passes cost
        more than calls).  Returns False if not settled after ``_MAX_ROUNDS``."""
        n = st.size
        new = _lookup(_T_TRANS, st[:-1] * 4 + cls[:-1])
        changed = np.flatnonzero(new != st[1:]) + 1
        st[1:] = new
        pending = changed[changed < n - 1] + 1
        rounds = 1
        while pending.size:
            rounds += 1
            if rounds > _MAX_ROUNDS:
                return False
            new = _T_FLAT[st[pending - 1] * 4 + cls[pending - 1]]
            changed = pending[new != st[pending]]
            st[pending] = new
            pending = changed[changed < n - 1] + 1
        return True

    def _emit_decoded(self, raw: bytes, st: npt.NDArray[np.int8]) -> bytes:
        """The bytes of a field whose states are known."""
        arr = np.frombuffer(raw, dtype=np.uint8)
        n = arr.size
        # Every output byte in place: the character, ctl()'d after QCTL, with
        # bit 7 set when its token had QBIN (just before it, or before its QCTL).
        after_qctl = st == _AFTER_QCTL
        after_qbin = st == _AFTER_QBIN
        qbin = after_qbin
        qbin[1:] |= after_qctl[1:] & after_qbin[:-1]
        flip = np.frombuffer(raw.translate(_CTL_RANGE), np.uint8) * after_qctl
        value = (arr ^ flip) | (qbin.view(np.uint8) << 7)
        literal = np.empty(n, dtype=np.bool_)
        literal[:-1] = st[1:] == _S0
        literal[-1] = True
        # (The arrays' own methods: np.flatnonzero and np.compress add a
        # Python wrapper each, a few us on a field of a few KB.)
        count_at = (st == _COUNT).nonzero()[0]
        if count_at.size == 0:
            out: bytes = value.compress(literal).tobytes()
            return out
        counts = arr[count_at].astype(np.int64) - 32
        if counts.min() < 1 or counts.max() > _MAX_RUN:
            raise _bad_count()
        # Each count belongs to the first literal after it (at most 3 further on).
        if count_at.size * _SPLICE_RUNS_PER <= n:
            # Few runs: compress the stretches between them, splice the runs in.
            parts: list[bytes] = []
            prev = 0
            for at, count in zip(count_at.tolist(), counts.tolist(), strict=True):
                lit = at + 1 + int(np.argmax(literal[at + 1 : at + 5]))
                parts.append(np.compress(literal[prev:at], value[prev:at]).tobytes())
                parts.append(bytes((int(value[lit]),)) * count)
                prev = lit + 1
            parts.append(np.compress(literal[prev:], value[prev:]).tobytes())
            return b"".join(parts)
        lit_at = np.flatnonzero(literal)
        reps = np.ones(lit_at.size, dtype=np.int64)
        reps[np.searchsorted(lit_at, count_at, side="right")] = counts
        return np.repeat(value.take(lit_at), reps).tobytes()

    def _decode_sequential(self, field: bytes) -> bytes:
        """The reference decoder (:func:`_reference_decode`); kept for the fuzzers."""
        return _reference_decode(self, field)


def _run_tokens(rept: int, token: bytes, n: int) -> bytes:
    """The repeat tokens of a run of ``n`` >= 3 bytes whose own token is ``token``."""
    full, rest = divmod(n, _MAX_RUN)
    out = (bytes((rept, _MAX_RUN + 32)) + token) * full
    if rest >= _MIN_RUN:
        return out + bytes((rept, rest + 32)) + token
    return out + token * rest


@dataclass(frozen=True, slots=True)
class _TokenTable:
    """Every byte value's token, zero-padded and packed little-endian.

    ``width_table`` is ``width`` as a ``translate`` table; ``packed`` holds
    the token in its low bytes (uint16 when no token is
    longer than two characters, else uint32); ``packed64`` holds it in bytes
    2..4, leaving bytes 0..1 free for a repeat prefix and count; ``tokens``
    are the same as ``bytes``.
    """

    width: U8
    width_table: bytes
    packed: npt.NDArray[np.uint16] | npt.NDArray[np.uint32]
    packed64: npt.NDArray[np.uint64]
    tokens: tuple[bytes, ...]


def _token(b: int, qctl: int, qbin: int | None, specials: set[int]) -> bytes:
    """The token of one byte value (reference/kermit.md section 3, steps 2-4)."""
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
    return bytes(chars)


@functools.lru_cache(maxsize=16)
def _token_table(qctl: int, qbin: int | None, rept: int | None) -> _TokenTable:
    """Build the token table of one prefix profile (cached: profiles are few)."""
    specials = {c for c in (qctl, qbin, rept) if c is not None}
    tokens = tuple(_token(b, qctl, qbin, specials) for b in range(256))
    width = np.array([len(t) for t in tokens], dtype=np.uint8)
    words = np.array([int.from_bytes(t, "little") for t in tokens], dtype=np.uint32)
    packed: npt.NDArray[np.uint16] | npt.NDArray[np.uint32]
    packed = words.astype(np.uint16) if int(width.max()) <= 2 else words
    packed64 = words.astype(np.uint64) << np.uint64(16)
    for arr in (width, packed, packed64):
        arr.setflags(write=False)
    return _TokenTable(width, width.tobytes(), packed, packed64, tokens)


@functools.lru_cache(maxsize=16)
def _class_table(qctl: int, qbin: int | None, rept: int | None) -> tuple[bytes, bytes]:
    """Two translate tables: the decoder class of each character (prefixes match
    the full byte), and the state after it when it starts a token."""
    cls = bytearray(256)
    cls[qctl] = _C_QCTL
    if qbin is not None:
        cls[qbin] = _C_QBIN
    if rept is not None:
        cls[rept] = _C_REPT
    return bytes(cls), bytes(cls).translate(_T_TRANS)


class _TokenDict(dict[bytes, bytes]):
    """Decoded value of every prefixed token without a repeat count; tokens with
    one (rare: runs) are decoded on demand and not kept, so the table stays
    bounded whatever a peer sends."""

    __slots__ = ("rept",)

    def __init__(self, rept: int | None) -> None:
        super().__init__()
        self.rept = rept

    def __missing__(self, token: bytes) -> bytes:
        # Only REPT count ... reaches here: every other token is in the table.
        count = token[1] - 32
        if not 1 <= count <= _MAX_RUN:
            raise _bad_count()
        rest = token[2:]
        return (self[rest] if len(rest) > 1 else rest) * count


@dataclass(frozen=True, slots=True)
class _SplitTable:
    """The short-field decoder of one profile.

    ``pattern`` matches one prefixed token exactly as the state machine reads
    it (``_T``): ``QCTL any``; ``QBIN (QCTL any | not-QCTL)``;
    ``REPT any (QBIN (QCTL any | not-QCTL) | QCTL any | not-QBIN-or-QCTL)``.
    ``prefix`` finds any prefix character.
    """

    pattern: re.Pattern[bytes]
    prefix: re.Pattern[bytes]
    tokens: _TokenDict


@functools.lru_cache(maxsize=16)
def _split_table(qctl: int, qbin: int | None, rept: int | None) -> _SplitTable:
    q = re.escape(bytes((qctl,)))
    alts = [q + b"."]
    after_count = [q + b"."]
    plain_after_count = q
    if qbin is not None:
        b = re.escape(bytes((qbin,)))
        qbin_token = b + b"(?:" + q + b".|[^" + q + b"])"
        alts.append(qbin_token)
        after_count.append(qbin_token)
        plain_after_count += b
    if rept is not None:
        r = re.escape(bytes((rept,)))
        after_count.append(b"[^" + plain_after_count + b"]")
        alts.append(r + b".(?:" + b"|".join(after_count) + b")")
    pattern = re.compile(b"(" + b"|".join(alts) + b")", re.DOTALL)
    chars = bytes(c for c in (qctl, qbin, rept) if c is not None)
    prefix = re.compile(b"[" + re.escape(chars) + b"]")
    tokens = _TokenDict(rept)
    enc = Encoding(qctl=qctl, qbin=qbin, rept=rept)
    for c in range(256):
        tokens[bytes((qctl, c))] = _reference_decode(enc, bytes((qctl, c)))
        if qbin is not None:
            tokens[bytes((qbin, qctl, c))] = _reference_decode(enc, bytes((qbin, qctl, c)))
            if c != qctl:
                tokens[bytes((qbin, c))] = _reference_decode(enc, bytes((qbin, c)))
    return _SplitTable(pattern, prefix, tokens)


# -- reference implementations (the definitions the tests hold the fast paths to) --


def _reference_tokens(enc: Encoding, data: bytes) -> list[tuple[bytes, int]]:
    """Tokenise ``data`` one byte at a time: ``(token, bytes it carries)`` pairs."""
    specials = {c for c in (enc.qctl, enc.qbin, enc.rept) if c is not None}
    out: list[tuple[bytes, int]] = []
    i, n = 0, len(data)
    while i < n:
        b = data[i]
        run = 1
        while enc.rept is not None and i + run < n and data[i + run] == b and run < _MAX_RUN:
            run += 1
        token = _token(b, enc.qctl, enc.qbin, specials)
        if run >= _MIN_RUN:
            assert enc.rept is not None
            out.append((bytes((enc.rept, run + 32)) + token, run))
            i += run
        else:
            out.append((token, 1))
            i += 1
    return out


def _reference_encode(enc: Encoding, data: bytes) -> bytes:
    """Encode one byte (or one run) at a time (reference/kermit.md section 3)."""
    return b"".join(token for token, _ in _reference_tokens(enc, data))


def _reference_encode_prefix(enc: Encoding, data: bytes, capacity: int) -> tuple[bytes, int]:
    """The longest run of whole tokens that fits in ``capacity``, and the bytes it carries."""
    field = bytearray()
    used = 0
    for token, n in _reference_tokens(enc, data):
        if len(field) + len(token) > capacity:
            break
        field += token
        used += n
    return bytes(field), used


def _reference_decode(enc: Encoding, field: bytes) -> bytes:
    """Decode one token at a time (gkermit.c decode order)."""
    out = bytearray()
    append = out.append
    rept, qbin, qctl = enc.rept, enc.qbin, enc.qctl
    i, n = 0, len(field)
    while i < n:
        c = field[i]
        i += 1
        if c != rept and c != qbin and c != qctl:
            append(c)
            continue
        count = 1
        if c == rept:
            if i + 1 >= n:
                raise _dangling()
            count = field[i] - 32
            if not 1 <= count <= _MAX_RUN:
                raise _bad_count()
            c = field[i + 1]
            i += 2
        high = 0
        if c == qbin:
            if i >= n:
                raise _dangling()
            high = 0x80
            c = field[i]
            i += 1
        if c == qctl:
            if i >= n:
                raise _dangling()
            c = field[i]
            i += 1
            if 63 <= (c & 0x7F) <= 95:
                c ^= 64
        if count == 1:
            append(c | high)
        else:
            out += bytes((c | high,)) * count
    return bytes(out)


PRINTABLE = Encoding()
"""The default profile: ``#`` controls, ``&`` 8th bit, ``~`` repeats; printable output."""

EIGHT_BIT_CLEAN = Encoding(qbin=None)
"""For lines known to carry all 256 byte values: no 8th-bit prefixing."""
