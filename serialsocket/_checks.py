"""Kermit block checks, types 1, 2 and 3 (reference/kermit.md section 2).

Every check covers the characters from LEN through the last DATA character, as
sent (after prefix encoding): MARK, CHECK and EOL are excluded; in extended
packets LENX1, LENX2 and HCHECK are included.

Type 3 is CRC-16/KERMIT (poly 0x1021 reflected, init 0, no final XOR; check
value 0x2189 for "123456789").  It is computed by crcmod's predefined
``kermit`` function (a C extension), *not* :func:`binascii.crc_hqx`, which is
CRC-16/XMODEM.  The 16-bit value is sent high to low as 4+6+6 bits through
``tochar``, not byte-swapped.

CRC-32 (:data:`BlockCheck.CRC32`, :func:`crc32_ieee`, :func:`crc32_chars`) is
the stronger check two telelink endpoints negotiate in the init exchange's
XCAPAS field (PROTOCOL.md section 10; serialsocket/DENSE.md): the ZMODEM /
IEEE 802.3 CRC (poly 0x04C11DB7 reflected, init and final XOR 0xFFFFFFFF;
check value 0xCBF43926 for "123456789"), computed by :func:`zlib.crc32`.  It
is not a Kermit block-check type: it never appears in the CHKT field.
"""

from __future__ import annotations

import enum
import zlib
from collections.abc import Callable

import crcmod.predefined

__all__ = [
    "CRC32_LENGTH",
    "BlockCheck",
    "check_chars",
    "check_length",
    "crc16_kermit",
    "crc32_chars",
    "crc32_ieee",
]

crc16_kermit: Callable[..., int] = crcmod.predefined.mkCrcFun("kermit")
"""CRC-16/KERMIT of a byte string (crcmod's C implementation when available);
an optional second argument continues from a previous result."""


def _raw_crc16() -> tuple[Callable[[bytes, int, bytes], int], bytes]:
    """crcmod's function and table behind :func:`crc16_kermit`, to call
    ``fun(data, 0, table)`` without its Python wrapper (once per packet on the
    hot paths); the wrapper itself if crcmod is laid out differently."""
    defaults = getattr(crc16_kermit, "__defaults__", None)
    if defaults is not None and len(defaults) == 3:
        init, table, fun = defaults
        if callable(fun) and init == 0 and fun(b"123456789", 0, table) == 0x2189:
            return fun, table
    return (lambda data, crc, table: crc16_kermit(data, crc)), b""


_CRC16_FUN, _CRC16_TABLE = _raw_crc16()


class BlockCheck(enum.IntEnum):
    """Block check types (Kermit manual section 6.2; CHKT field of the Send-Init)."""

    SUM6 = 1
    """Type 1: 6-bit folded arithmetic sum, one character."""
    SUM12 = 2
    """Type 2: 12-bit arithmetic sum, two characters.  Avoid: E-Kermit and
    G-Kermit compare it against the unmasked sum and reject packets whose sum
    is >= 4096 (reference/kermit.md section 2)."""
    CRC16 = 3
    """Type 3: CRC-16/KERMIT, three characters.  telelink's default."""
    CRC32 = 6
    """CRC-32/ISO-HDLC, six characters (:func:`crc32_chars`): telelink to
    telelink only, agreed through XCAPAS (PROTOCOL.md section 10), never sent
    in CHKT.  Its value is its length, as for the Kermit types, so
    ``int(check)`` is the check's width everywhere."""


def check_length(check: BlockCheck) -> int:
    """Number of characters the check occupies in a packet (1, 2, 3 or 6)."""
    return int(check)


def check_chars(check: BlockCheck, covered: bytes) -> bytes:
    """The printable check characters for ``covered`` (LEN through DATA).

    Args:
        check: the block check type in force for this packet.
        covered: the exact bytes from LEN through the last DATA byte.

    Returns:
        1, 2, 3 or 6 bytes, each in 32..95.
    """
    if check is BlockCheck.CRC32:
        return crc32_chars(covered)
    if check is BlockCheck.CRC16:
        crc = crc16_kermit(covered)
        return bytes(((crc >> 12 & 0x0F) + 32, (crc >> 6 & 0x3F) + 32, (crc & 0x3F) + 32))
    s = sum(covered)
    if check is BlockCheck.SUM6:
        return bytes((((s + ((s & 0xC0) >> 6)) & 0x3F) + 32,))
    s &= 0xFFF
    return bytes(((s >> 6 & 0x3F) + 32, (s & 0x3F) + 32))


CRC32_LENGTH = 6
"""Characters of a CRC-32 check: 2 + 5 x 6 bits."""


def crc32_ieee(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-32/ISO-HDLC (ZMODEM's 32-bit CRC, IEEE 802.3): check("123456789") = 0xCBF43926.

    Args:
        data: the bytes.
        crc: a previous result, to continue over a following piece.
    """
    return zlib.crc32(data, crc)


def crc32_chars(covered: bytes | bytearray | memoryview) -> bytes:
    """The CRC-32 of ``covered`` as six printable characters, high to low.

    The 32-bit value is cut like type 3's 16 (4+6+6): 2 bits, then five
    groups of 6, each through ``tochar`` -- every character in 32..95.
    """
    crc = zlib.crc32(covered)
    return bytes(((crc >> shift) & 0x3F) + 32 for shift in (30, 24, 18, 12, 6, 0))
