"""Kermit wire constants and character transforms.

References: Kermit Protocol Manual, 6th ed. (F. da Cruz, 1986), section 6 "Packet
format"; the byte-exact rules verified against G-Kermit 2.01 and C-Kermit 10.0
are summarised in the project's reference notes (reference/kermit.md, sections 1
and 5).
"""

from __future__ import annotations

import enum

__all__ = [
    "CR",
    "DEFAULT_MAX_PACKET_LENGTH",
    "EXTENDED_HEADER_LENGTH",
    "MARK",
    "MAX_EXTENDED_FIELD",
    "MAX_NORMAL_LEN",
    "MAX_PACKET_LENGTH",
    "MIN_PACKET_LENGTH",
    "NORMAL_HEADER_LENGTH",
    "SEQ_MODULUS",
    "PacketType",
    "ctl",
    "tochar",
    "unchar",
]

MARK = 0x01
"""SOH, the packet start mark (Kermit default MARK; never appears inside a packet)."""

CR = 0x0D
"""Carriage return, the default end-of-line byte appended after the check.

EOL is *not* part of the packet: it is not counted in LEN and not covered by the
block check (kermit.c spkt, gkermit.c spacket)."""

SEQ_MODULUS = 64
"""Sequence numbers are ``tochar(n mod 64)`` (Kermit manual section 6)."""

MAX_NORMAL_LEN = 94
"""Largest LEN of a normal packet: LEN is one printable char, ``tochar(94)`` = ``~``."""

NORMAL_HEADER_LENGTH = 4
"""MARK LEN SEQ TYPE."""

EXTENDED_HEADER_LENGTH = 7
"""MARK LEN(blank) SEQ TYPE LENX1 LENX2 HCHECK."""

MAX_EXTENDED_FIELD = 94 * 95 + 94
"""9024: the largest DATA+CHECK count LENX1/LENX2 can express (C-Kermit MAXRP)."""

MAX_PACKET_LENGTH = EXTENDED_HEADER_LENGTH + MAX_EXTENDED_FIELD
"""9031: the largest packet, counted from MARK through CHECK (see below)."""

DEFAULT_MAX_PACKET_LENGTH = 128
"""The paper's 128-byte packets (seed 003, section 9.2).

Throughout telelink a *packet length* counts every character from MARK through
the last CHECK character inclusive; it excludes the EOL byte and any padding.
A 128-character packet with a CRC-16 check is therefore an extended packet with
``128 - 7 - 3 = 118`` data characters and occupies 129 bytes on the line with
its CR.  (Kermit's own LEN field counts differently, from SEQ through CHECK; and
its MAXLX counts DATA+CHECK.  Both are derived from this one number.)"""

MIN_PACKET_LENGTH = NORMAL_HEADER_LENGTH + 3 + 5
"""12: the smallest configurable maximum, room for the longest token (5) and a CRC."""


def tochar(x: int) -> int:
    """Make a control quantity 0..94 printable (``x + 32``)."""
    return x + 32


def unchar(c: int) -> int:
    """Inverse of :func:`tochar` (``c - 32``)."""
    return c - 32


def ctl(c: int) -> int:
    """Toggle bit 6: maps 0..31 to '@'..'_', DEL to '?', and back."""
    return c ^ 64


class PacketType(enum.StrEnum):
    """Kermit packet types: one printable letter (Kermit manual section 6.3).

    Packets with a letter not listed here still parse (Packet.type is a plain
    ``str`` then); the layer above decides what to do with them.
    """

    SEND_INIT = "S"
    """Send-Init: the sender's parameters (seq 0; type-1 check unless FORCE-3)."""
    INIT = "I"
    """Init: parameter exchange without a file transfer (server mode; our connect)."""
    ACK = "Y"
    """Acknowledgement; may carry data (e.g. the peer's parameters)."""
    NAK = "N"
    """Negative acknowledgement; never carries data."""
    DATA = "D"
    """Data."""
    FILE = "F"
    """File header (file name)."""
    TEXT = "X"
    """Text header, instead of F, for screen output."""
    ATTRIBUTES = "A"
    """File attributes."""
    EOF = "Z"
    """End of file (data ``D`` = discard)."""
    BREAK = "B"
    """Break: end of transaction."""
    ERROR = "E"
    """Fatal error; the data is a message.  Never acknowledged."""
    RECEIVE_INIT = "R"
    """Receive-Init (server GET)."""
    GENERIC = "G"
    """Generic server command."""
    COMMAND = "C"
    """Host command."""
