"""Kermit file transfer: attribute (A) packets, their replies, file names and text records.

Sans-I/O helpers for the two roles.  Formats are C-Kermit's (``ckcfns.c``
sattr(), gattr(), rsattr()); each attribute is ``TAG tochar(len) VALUE``:

==== ==================================================================
tag  value
==== ==================================================================
``"`` file type: ``B8`` binary (8-bit bytes), ``AMJ`` text (records end in CR LF)
``#`` date: ``yyyymmdd hh:mm:ss`` (local time of the sending system)
``!`` length in K (1024 bytes), rounded up
``1`` length in bytes
``+`` disposition: ``R`` = RESEND (recovery); ``M`` mail, ``P`` print (refused here)
``@`` end of attributes (length 0)
==== ==================================================================

The ACK of an A packet: empty (or anything not starting with ``N``) accepts
the file; ``N`` followed by the tags of the attributes that made the receiver
refuse it (``N1``: the size does not fit; ``N+``: a disposition it cannot do;
``N"``: a type it cannot store) refuses it; for a RESEND, ``1 tochar(len)
digits`` gives the bytes the receiver already holds, and the sender starts
there.

File names (C-Kermit's SET FILE NAMES CONVERTED, the default of C-Kermit and
G-Kermit): sent in "common form" -- upper case, one dot, letters, digits, ``_``
and ``-`` only -- and on arrival, a name with no lower-case letter is stored
in lower case.  ``--literal-names`` (SET FILE NAMES LITERAL) turns both off.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = [
    "AttributeReply",
    "FileAttributes",
    "TextDecoder",
    "common_form",
    "decode_reply",
    "encode_attributes",
    "encode_reply",
    "local_form",
    "parse_attributes",
    "refusal_text",
    "to_crlf",
]

_MAX_DIGITS = 19
"""Length values longer than this are ignored (no file has 10**19 bytes)."""
_UNSAFE = re.compile(r"[^A-Z0-9._-]")


@dataclass(frozen=True, slots=True, kw_only=True)
class FileAttributes:
    """What an A packet said about the file that follows (all optional).

    Attributes:
        size: length in bytes (``1``), else from length in K (``!``), else None.
        text: the type is text (``"`` starting with ``A``); False for binary
            or when no type came.
        type: the raw type value (``B8``, ``AMJ``, ...), or None.
        date: the ``#`` value, ``yyyymmdd hh:mm:ss`` (or a prefix), or None.
        disposition: the ``+`` value's first character (``R`` = RESEND), or None.
    """

    size: int | None = None
    text: bool = False
    type: str | None = None
    date: str | None = None
    disposition: str | None = None


@dataclass(frozen=True, slots=True)
class AttributeReply:
    """The receiver's answer to an A packet.

    ``refuse`` holds the tags of the attributes that made it refuse the file
    (empty: accepted); ``resume_from`` answers a RESEND with the bytes already
    held (None: not a RESEND, or nothing held).
    """

    refuse: str = ""
    resume_from: int | None = None


def encode_attributes(
    *, size: int | None, text: bool, date: str | None, resend: bool = False
) -> bytes:
    """The A packet's data field, before prefix encoding (order as C-Kermit's sattr())."""
    out = bytearray()

    def put(tag: str, value: str) -> None:
        raw = value.encode("ascii")
        out.extend(tag.encode("ascii") + bytes([32 + len(raw)]) + raw)

    put('"', "AMJ" if text else "B8")
    if date:
        put("#", date[:17])
    if size is not None:
        put("!", str((size + 1023) // 1024))
        put("1", str(size))
    if resend:
        put("+", "R")
    put("@", "")
    return bytes(out)


def parse_attributes(field: bytes) -> FileAttributes:
    """Read a (decoded) A packet; unknown or malformed attributes are skipped."""
    size: int | None = None
    size_k: int | None = None
    ftype: str | None = None
    date: str | None = None
    disposition: str | None = None
    i = 0
    while i + 1 < len(field):
        tag, n = chr(field[i]), max(field[i + 1] - 32, 0)
        value = field[i + 2 : i + 2 + n].decode("ascii", "replace")
        i += 2 + n
        if tag == "1" and value.isdigit() and len(value) <= _MAX_DIGITS:
            size = int(value)
        elif tag == "!" and value.isdigit() and len(value) <= _MAX_DIGITS:
            size_k = int(value)
        elif tag == '"' and value:
            ftype = value
        elif tag == "#" and value:
            date = value
        elif tag == "+" and value:
            disposition = value[0]
        elif tag == "@":
            break
    if size is None and size_k is not None:
        size = size_k * 1024
    return FileAttributes(
        size=size,
        text=ftype is not None and ftype.startswith("A"),
        type=ftype,
        date=date,
        disposition=disposition,
    )


def encode_reply(reply: AttributeReply) -> bytes:
    """The ACK data for an A packet."""
    if reply.refuse:
        return b"N" + reply.refuse.encode("ascii")
    if reply.resume_from is not None:
        digits = str(reply.resume_from).encode("ascii")
        return b"1" + bytes([32 + len(digits)]) + digits
    return b""


def decode_reply(data: bytes) -> AttributeReply:
    """What the ACK of our A packet says (rsattr())."""
    if data[:1] == b"N":
        return AttributeReply(refuse=data[1:].decode("ascii", "replace") or "?")
    if data[:1] == b"1" and len(data) >= 2:
        digits = data[2 : 2 + max(data[1] - 32, 0)]
        if digits.isdigit() and len(digits) <= _MAX_DIGITS:
            return AttributeReply(resume_from=int(digits))
    return AttributeReply()


_REASONS = {
    "1": "size: it does not fit",
    "!": "size: it does not fit",
    '"': "type",
    "#": "date: not newer",
    "+": "disposition",
    "?": "name",
}


def refusal_text(tags: str) -> str:
    """Words for a refusal's tags (C-Kermit's getreason())."""
    return ", ".join(_REASONS.get(t, f"attribute {t!r}") for t in tags) or "no reason given"


def common_form(name: str) -> str:
    """``name`` in Kermit's common form: upper case, one dot, ``[A-Z0-9_-]`` otherwise.

    ``report.v2.pdf`` -> ``REPORT_V2.PDF``; ``my file~`` -> ``MY_FILE_``.
    """
    upper = name.upper()
    head, dot, tail = upper.rpartition(".")
    if dot and head:
        upper = head.replace(".", "_") + "." + tail
    converted = _UNSAFE.sub("_", upper)
    return converted or "_"


def local_form(name: str) -> str:
    """A received name as stored: lower-cased if it has no lower-case letter."""
    return name.lower() if name == name.upper() else name


def to_crlf(data: bytes) -> bytes:
    """Text records for the wire: every LF becomes CR LF (the local format is LF)."""
    return data.replace(b"\n", b"\r\n")


class TextDecoder:
    """Text records from the wire to the local format: CR LF becomes LF.

    A CR at the end of one packet may be followed by the LF at the start of
    the next, so one CR is held back; :meth:`flush` releases it at the end of
    the file.  A CR not followed by LF is kept.
    """

    def __init__(self) -> None:
        self._cr = False

    def feed(self, data: bytes) -> bytes:
        """Convert the next piece of the file."""
        if self._cr:
            data = b"\r" + data
            self._cr = False
        if data.endswith(b"\r"):
            data = data[:-1]
            self._cr = True
        return data.replace(b"\r\n", b"\n")

    def flush(self) -> bytes:
        """The end of the file: a held CR."""
        held, self._cr = self._cr, False
        return b"\r" if held else b""
