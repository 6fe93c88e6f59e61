"""Corrected data packets: one damaged character per block repaired in place
(PROTOCOL.md section 15).

A byte error rate that costs an ARQ a resend in every tenth packet (1e-3 at
96 characters, 1e-4 at 1024) mostly damages *one* character of a packet.  A
``d`` packet carries, after its data, three printable characters per block
of at most 255 covered characters: two sums over GF(2^8) of the block's
characters (``A`` the plain sum, ``B`` the sum weighted by ``alpha^i``, a
one-error Reed-Solomon syndrome pair).  A receiver whose check fails
recomputes both sums; one damaged character at position ``i`` with error
``e`` shows as ``dA = e`` and ``dB = e alpha^i``, so ``i = log dB - log dA``
and the character is ``c ^ dA``.  The block check decides: the repaired
packet is taken only if it then passes, so a correction never delivers data
the check would have refused (the price, at most one more try of the check
per damaged packet, is stated in PROTOCOL.md 15.4).

The covered characters are LEN through the last data character before the
sums (the packet's header and its data, sequence characters included);
character ``i`` belongs to block ``i mod m``, so a burst of up to ``m``
characters lands one per block.  ``m`` is a function of the packet length
alone (:func:`blocks`), which the receiver has read before the data.

Sans-I/O and pure Python; the sender calls :func:`build_corrected`, the
parser :func:`repair`, the length chooser :func:`survival`.
"""

from __future__ import annotations

from ._checks import BlockCheck, check_chars
from ._dense import RADIX91_ALPHABET
from ._packet import Packet, _header, build_packet, packet_length
from ._wire import CR, EXTENDED_HEADER_LENGTH, MARK, NORMAL_HEADER_LENGTH

__all__ = [
    "BLOCK_SPAN",
    "CORRECTED_TYPE",
    "REPAIR_MAX_LENGTH",
    "REPAIR_TYPE",
    "TRAILER_PER_BLOCK",
    "apply_repair",
    "blocks",
    "build_corrected",
    "repair",
    "repair_field",
    "survival",
    "trailer",
    "trailer_length",
]

CORRECTED_TYPE = "d"
"""The type letter of a corrected data packet (a ``D`` with sums behind its data)."""

REPAIR_TYPE = "r"
"""The type letter of a repair packet: the sums of a ``D`` packet sent
without them, for a receiver that holds it damaged (PROTOCOL.md 15.6)."""

REPAIR_MAX_LENGTH = 4095
"""The longest packet a repair packet can name (its length in two
characters of six bits); a longer one is resent whole."""

BLOCK_SPAN = 255
"""The most covered characters in one block: ``alpha`` has order 255, so the
position ``log dB - log dA`` is unique only below it."""

TRAILER_PER_BLOCK = 3
"""Characters of one block's sums: ``A * 256 + B`` (0..65535) in three digits
of the radix-91 alphabet (91^3 = 753 571), most significant first."""

_POLY = 0x11D
"""x^8 + x^4 + x^3 + x^2 + 1, the usual Reed-Solomon field; ``alpha = 2``
generates its 255 nonzero elements."""

_EXP = [0] * 510
_LOG = [0] * 256
_x = 1
for _i in range(255):
    _EXP[_i] = _EXP[_i + 255] = _x
    _LOG[_x] = _i
    _x <<= 1
    if _x & 0x100:
        _x ^= _POLY
del _x, _i
_TIMES_ALPHA = bytes(_EXP[_LOG[v] + 1] if v else 0 for v in range(256))
"""``v * alpha`` for every ``v``."""

_DIGIT = [RADIX91_ALPHABET.index(c) if c in RADIX91_ALPHABET else -1 for c in range(256)]


def blocks(total_length: int, check_length: int) -> int:
    """Blocks of a ``d`` packet of ``total_length`` characters, MARK through
    CHECK: the fewest ``m >= 1`` whose ``255 m`` hold its covered characters
    (``total_length - 1 - check_length - 3 m``), i.e. ``ceil((total_length -
    1 - check_length) / 258)``."""
    return max(1, -(-(total_length - 1 - check_length) // (BLOCK_SPAN + TRAILER_PER_BLOCK)))


def trailer_length(total_length: int, check_length: int) -> int:
    """Characters of the sums in a ``d`` packet of ``total_length`` (MARK through CHECK)."""
    return TRAILER_PER_BLOCK * blocks(total_length, check_length)


def _sums(block: bytes) -> tuple[int, int]:
    """``(sum c_i, sum c_i alpha^i)`` over GF(2^8), by Horner from the end."""
    a = b = 0
    for c in reversed(block):
        a ^= c
        b = _TIMES_ALPHA[b] ^ c
    return a, b


def trailer(covered: bytes, m: int) -> bytes:
    """The sums of ``covered`` (LEN through the last data character) in ``m``
    blocks, as :data:`TRAILER_PER_BLOCK` characters each."""
    out = bytearray()
    for j in range(m):
        a, b = _sums(covered[j::m])
        v = a << 8 | b
        out += bytes(
            (
                RADIX91_ALPHABET[v // 8281],
                RADIX91_ALPHABET[v // 91 % 91],
                RADIX91_ALPHABET[v % 91],
            )
        )
    return bytes(out)


def _read_trailer(trail: bytes) -> list[tuple[int, int] | None]:
    """Each block's ``(A, B)``, None where its three characters are not sums
    (a character outside the alphabet, a value over 65535)."""
    sums: list[tuple[int, int] | None] = []
    for j in range(0, len(trail), TRAILER_PER_BLOCK):
        d0, d1, d2 = _DIGIT[trail[j]], _DIGIT[trail[j + 1]], _DIGIT[trail[j + 2]]
        v = d0 * 8281 + d1 * 91 + d2
        sums.append(None if min(d0, d1, d2) < 0 or v > 0xFFFF else (v >> 8, v & 0xFF))
    return sums


def build_corrected(seq: int, field: bytes, check: BlockCheck) -> bytes:
    """The wire form of a ``d`` packet: ``field`` (the encoded data, long
    sequence characters first) then its sums, with ``check`` and CR.

    Raises:
        LocalProtocolError: the packet would exceed the Kermit maximum.
    """
    k = int(check)
    m = 1
    while blocks(packet_length(len(field) + TRAILER_PER_BLOCK * m, check), k) > m:
        m += 1
    marked, _ = _header(seq, ord(CORRECTED_TYPE), len(field) + TRAILER_PER_BLOCK * m, k)
    covered = marked[1:] + field
    return build_packet(
        Packet(seq=seq, type=CORRECTED_TYPE, data=field + trailer(covered, m)), check, eol=CR
    )


def repair(packet: bytes, check: BlockCheck) -> bytes | None:
    """The packet ``packet`` (MARK through CHECK, framed, its check failed)
    with its damage repaired, or None.

    Two repairs are tried, each kept only if the check then passes: the
    data's (one character per block, where the sums point), and the sums'
    (the data as it came, the sums recomputed: damage in the sums alone).
    A repair never touches LEN, TYPE or the extended header (the parser has
    framed by them), and never makes SEQ leave 0..63 or a character a MARK.
    """
    k = int(check)
    total = len(packet)
    m = blocks(total, k)
    tail = TRAILER_PER_BLOCK * m
    extended = packet[1] == 32
    head = EXTENDED_HEADER_LENGTH if extended else NORMAL_HEADER_LENGTH
    if total - k - tail < head:
        return None
    covered = packet[1 : total - k - tail]
    trail = packet[total - k - tail : total - k]
    got = packet[total - k :]
    fixed = _fix(covered, trail, m, head - 1)
    if fixed is not None and check_chars(check, fixed + trail) == got:
        return b"\x01" + fixed + trail + got
    again = trailer(covered, m)
    if again != trail and check_chars(check, covered + again) == got:
        return b"\x01" + covered + again + got
    return None


def _fix(covered: bytes, trail: bytes, m: int, header: int) -> bytes | None:
    """``covered`` with one character per block corrected as the sums say, or
    None: nothing to correct, or a block the sums cannot explain by one
    damaged data character (``header``: covered characters LEN..HCHECK)."""
    out: bytearray | None = None
    for j, sums in enumerate(_read_trailer(trail)):
        if sums is None:
            return None
        block = covered[j::m]
        a, b = _sums(block)
        da, db = a ^ sums[0], b ^ sums[1]
        if not da and not db:
            continue
        if not da or not db:
            return None
        at = j + m * ((_LOG[db] - _LOG[da]) % 255)
        if at >= len(covered) or (at < header and at != 1):
            return None  # past the data, or LEN/TYPE/the extended header
        value = covered[at] ^ da
        if value == MARK or (at == 1 and not 32 <= value <= 95):
            return None
        if out is None:
            out = bytearray(covered)
        out[at] = value
    return None if out is None else bytes(out)


def repair_blocks(total_length: int, check_length: int) -> int:
    """Blocks of the sums a repair packet carries for a packet of
    ``total_length`` characters (MARK through CHECK): the fewest ``m >= 1``
    whose ``255 m`` hold its covered characters, ``total_length - 1 -
    check_length`` (no sums of its own among them)."""
    return max(1, -(-(total_length - 1 - check_length) // BLOCK_SPAN))


def repair_field(packet: bytes, check_length: int) -> bytes:
    """A repair packet's data after any long sequence characters, for the
    data packet ``packet`` (MARK through CHECK, as it was sent): its length
    in two characters, ``tochar(P >> 6) tochar(P & 63)``, then the sums of
    its covered characters (LEN through the last data character) in
    :func:`repair_blocks` blocks.

    Raises:
        ValueError: ``packet`` is longer than :data:`REPAIR_MAX_LENGTH`.
    """
    total = len(packet)
    if total > REPAIR_MAX_LENGTH:
        raise ValueError(f"a repair packet names lengths up to {REPAIR_MAX_LENGTH}, not {total}")
    m = repair_blocks(total, check_length)
    return bytes((32 + (total >> 6), 32 + (total & 63))) + trailer(
        packet[1 : total - check_length], m
    )


def apply_repair(damaged: bytes, field: bytes, check: BlockCheck) -> bytes | None:
    """``damaged`` (a packet MARK through CHECK whose check failed) repaired
    by the sums of a repair packet's ``field`` (:func:`repair_field`), or
    None: not the length the sums are for, nothing they can repair, or a
    repair the check still refuses.  As :func:`repair`, never LEN, TYPE or
    the extended header, never SEQ out of 0..63 or a character to a MARK;
    damage to the check itself is not repaired either (the sums all agree:
    nothing to correct)."""
    if len(field) < 2 or not (32 <= field[0] < 96 and 32 <= field[1] < 96):
        return None
    total = (field[0] - 32) << 6 | (field[1] - 32)
    k = int(check)
    head = EXTENDED_HEADER_LENGTH if total > 1 and damaged[1:2] == b" " else NORMAL_HEADER_LENGTH
    if total != len(damaged) or total - k < head or k < 3:
        return None
    m = repair_blocks(total, k)
    if len(field) != 2 + TRAILER_PER_BLOCK * m:
        return None
    got = damaged[total - k :]
    fixed = _fix(damaged[1 : total - k], field[2:], m, head - 1)
    if fixed is None or check_chars(check, fixed) != got:
        return None
    return b"\x01" + fixed + got


def survival(length: int, q: float, check_length: int) -> float:
    """Probability that a ``d`` packet of ``length`` characters (MARK through
    CHECK; one more for its CR) arrives whole or repaired when each character
    is damaged independently with probability ``q``: MARK, the header, the
    check and the CR intact, and at most one damaged character in each block
    of the rest (data and sums; damage to both a block's data and its sums is
    counted as repaired, a slight optimism at the rates where it matters)."""
    head = EXTENDED_HEADER_LENGTH if length > 96 else NORMAL_HEADER_LENGTH
    fixed = head + check_length + 1
    rest = max(length + 1 - fixed, 0)
    m = blocks(length, check_length)
    span = rest / m
    intact = 1.0 - q
    block = intact**span + span * q * intact ** max(span - 1.0, 0.0)
    return float(intact**fixed * block**m)
