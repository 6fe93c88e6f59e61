"""serialsocket/PROTOCOL.md section 9: a whole exchange, byte by byte, that cannot drift.

Two real sans-I/O :class:`~serialsocket.Endpoint` s with the default
configuration run a scripted exchange -- connect (init and its acceptance),
data both ways (control, 8th-bit and repeat prefixes; a normal and an
extended packet), a packet damaged on the line and its NAK and resend, ACKs,
EOF both ways (the graceful close) -- plus a refused connect.  ``render()``
prints the section; the tests check that

* PROTOCOL.md holds exactly what the code produces today (regenerate with
  ``python -m tests.serialsocket.test_protocol_vectors``);
* the document's bytes follow sections 1-2 and reference/kermit.md when
  checked independently of the code: framing, LEN / LENX / HCHECK, a bitwise
  CRC-16/KERMIT, the prefix decoding, and the type, sequence number and data
  each vector's heading claims;
* the real packet parser, fed the document's bytes one at a time, accepts
  every packet and rejects the damaged one.
"""

from __future__ import annotations

import ast
import dataclasses
import pathlib
import re
from dataclasses import dataclass

import pytest

from serialsocket import ConnectionRequested, Endpoint, EndpointConfig, State
from serialsocket.packets import (
    PRINTABLE,
    BlockCheck,
    PacketParser,
    PacketReceived,
    PacketRejected,
    PacketType,
    RejectReason,
)

PROTOCOL = pathlib.Path(__file__).parents[2] / "serialsocket" / "PROTOCOL.md"
BEGIN, END = "<!-- vectors:begin -->\n", "\n<!-- vectors:end -->"

SOH, CR = 0x01, 0x0D
NAMES = {SOH: "SOH", CR: "CR", 0x20: "SP"}
"""How the text rows show the three bytes that are not visible characters."""

GREETING = b"hello\r\n\x80\x00\x00\x00\x00\x00"
"""Plain letters, two controls (``#``), an 8-bit byte (``&``) and a run (``~``)."""
INIT_MIN_FIELD = 9
"""An ACK with at least this many data characters is an init answer (section 2)."""
LONG = bytes(range(0x20, 0x7F))
"""All 95 printable characters, the three prefix characters among them: an extended packet."""


@dataclass(frozen=True)
class Vector:
    """One packet on the line: who sent it, what it is for, its bytes."""

    sender: str  # "A" (connects) or "B" (listens)
    note: str
    raw: bytes
    damaged: bool = False  # a copy the line damaged: the receiver rejects it


CLASSIC = EndpointConfig(dense=False, long_window=None, expedited=False)
"""The default configuration without the long-sequence offer a connector
without hints makes (PROTOCOL.md section 9), without the expedited lane's
offer (section 11) and, as by default, no dense-encoding offer (section 10):
the classic init and prefix-encoded data fields, readable by eye.  The
extensions have their own tests (test_long_seq.py, test_negotiation.py,
test_expedited.py)."""


def exchange() -> list[Vector]:
    """The scripted exchange between two classic endpoints, as the code makes it."""
    a, b = Endpoint(CLASSIC), Endpoint(CLASSIC)
    b.listen()
    out: list[Vector] = []
    t = 0.0
    ends = {"A": a, "B": b}

    def send(sender: str, *notes: str, damage: tuple[bytes, bytes] | None = None) -> None:
        nonlocal t
        src, dst = ends[sender], ends["B" if sender == "A" else "A"]
        raw = src.data_to_send(t)
        packets = [p + b"\r" for p in raw.split(b"\r")[:-1]]
        assert len(packets) == len(notes), (sender, raw)
        out.extend(Vector(sender, note, p) for note, p in zip(notes, packets, strict=True))
        if damage is not None:
            raw = raw.replace(*damage)
            out.append(Vector(sender, "what B receives: the line turned `o` into `O`", raw, True))
        t += 0.001
        dst.receive_data(raw, t)
        dst.events()

    a.connect(t)
    send("A", "connection request: A's parameters (section 3)")
    send("B", "accepted: B's parameters; both sides are now ESTABLISHED")
    a.send(GREETING, t)
    send("A", "first data packet (A's sequence space starts at 1)")
    send("B", "ACK of 1: B holds everything before 2, window 31")
    a.send(b"world", t)
    send("A", "second data packet ...", damage=(b"world", b"wOrld"))
    send("B", "... so B NAKs the packet it expects")
    send("A", "A resends packet 2 (the same bytes)")
    send("B", "ACK of 2")
    a.send(LONG, t)
    send("A", "an extended packet (section 1): 98 data characters do not fit a normal one")
    send("B", "ACK of 3")
    b.send(b"ok", t)
    send("B", "B's first data packet: B's own sequence space, also from 1")
    send("A", "ACK of B's 1")
    a.close(t)
    send("A", "A closes: EOF after its last data packet")
    send("B", "ACK of the EOF (4); A's direction is finished")
    b.close(t)
    send("B", "B closes too: its EOF")
    send(
        "A",
        "ACK of B's EOF: both of A's directions are done, A LINGERs",
        "the same ACK again: the ACK that completes a close goes three times",
        "and a third time (it may be the last packet before A's program exits)",
    )
    send(
        "B",
        "B's directions are done too, B LINGERs: its last ACK (of A's EOF) again",
        "and a third time",
    )
    assert (a.state, b.state) == (State.LINGER, State.LINGER)
    assert (a.data_to_send(t), b.data_to_send(t)) == (b"", b"")

    # A refused connect: the listener does not accept automatically and says why.
    c, d = (
        Endpoint(CLASSIC),
        Endpoint(dataclasses.replace(CLASSIC, auto_accept=False)),
    )
    d.listen()
    c.connect(0.0)
    request = c.data_to_send(0.0)
    d.receive_data(request, 0.0)
    assert any(isinstance(e, ConnectionRequested) for e in d.events())
    d.refuse("arm busy", 0.0)
    refusal = d.data_to_send(0.0)
    c.receive_data(refusal, 0.0)
    assert c.state is State.FAILED
    out.append(Vector("B", "a listener that refuses a connection request answers with E", refusal))
    return out


# -- the section ----------------------------------------------------------------------


def _cell(byte: int) -> str:
    if byte in NAMES:
        return NAMES[byte]
    assert 0x21 <= byte <= 0x7E, f"not printable: {byte:#04x}"
    return chr(byte)


def dump(raw: bytes) -> list[str]:
    """Rows of 16 bytes: hex, and under it the same bytes as characters."""
    rows = []
    for i in range(0, len(raw), 16):
        chunk = raw[i : i + 16]
        rows.append(" ".join(f"{b:02x}".rjust(3) for b in chunk))
        rows.append(" ".join(_cell(b).rjust(3) for b in chunk))
    return rows


def _describe(raw: bytes) -> tuple[str, bytes | None]:
    """``TYPE`` seq N, and the data: decoded for D and E, as sent otherwise; and the
    init data field when the packet carries one."""
    parser = PacketParser(check=BlockCheck.CRC16, init_check=BlockCheck.CRC16)
    parser.receive_data(raw)
    event = parser.next_event()
    assert isinstance(event, PacketReceived), event
    packet = event.packet
    form = "extended" if event.extended else "normal"
    head = f"`{packet.type}` seq {packet.seq}, {form}, {len(raw)} bytes"
    init = packet.type == PacketType.INIT or (
        packet.type == PacketType.ACK and len(packet.data) >= INIT_MIN_FIELD
    )
    if packet.type in (PacketType.DATA, PacketType.ERROR):
        data = PRINTABLE.decode(packet.data)
        return f"{head}, data {data!r} ({len(data)} bytes)", None
    return f"{head}, data field {bytes(packet.data)!r}", packet.data if init else None


INIT_FIELDS = [
    ("MAXL", 1, "tochar"),
    ("TIME", 1, "tochar"),
    ("NPAD", 1, "tochar"),
    ("PADC", 1, "ctl"),
    ("EOL", 1, "tochar"),
    ("QCTL", 1, "literal"),
    ("QBIN", 1, "literal"),
    ("CHKT", 1, "literal"),
    ("REPT", 1, "literal"),
    ("CAPAS", 1, "tochar"),
    ("WINDO", 1, "tochar"),
    ("MAXLX1", 1, "tochar"),
    ("MAXLX2", 1, "tochar"),
    ("CHKPNT", 1, "literal"),
    ("CHKINT", 3, "literal"),
    ("WHATAMI", 1, "tochar"),
    ("SYSID", 3, "tochar(length) + text"),
    ("WHATAMI2", 1, "tochar"),
    ("VERSION", 1, "tochar"),
    ("TIMEOUT", 3, "base 95, milliseconds"),
]
"""The init data field as telelink sends it (``serialsocket/_params.py``)."""


def _init_table(field: bytes) -> list[str]:
    rows = ["| field | chars | hex | value |", "|---|---|---|---|"]
    at = 0
    for name, width, how in INIT_FIELDS:
        chars = field[at : at + width]
        at += width
        if how == "tochar":
            value = str(chars[0] - 32)
        elif how == "ctl":
            value = f"{chars[0] ^ 64} (ctl)"
        elif how.startswith("base 95"):
            value = f"{(chars[0] - 32) * 95 * 95 + (chars[1] - 32) * 95 + chars[2] - 32} ms"
        elif how.startswith("tochar(length)"):
            value = f"{chars[0] - 32} characters: `{chars[1:].decode()}`"
        else:
            value = "literal"
        shown = repr(chars).replace("|", "\\|")
        rows.append(f"| {name} | `{shown}` | {chars.hex(' ')} | {value} |")
    if at < len(field):  # fields a later protocol revision added
        rest = field[at:]
        shown = repr(rest).replace("|", "\\|")
        rows.append(f"| (later fields) | `{shown}` | {rest.hex(' ')} | see `_params.py` |")
    return rows


def render() -> str:
    """The body of PROTOCOL.md's vector section, between its markers."""
    lines = [
        "Generated by `python -m tests.serialsocket.test_protocol_vectors` from two real",
        "endpoints with `EndpointConfig(long_window=None, expedited=False)`: the",
        "defaults without the long-sequence offer of section 9 and the expedited",
        "lane of section 11 (and, as by default, no dense offer of section 10):",
        "CRC-16 on every packet, the printable profile, window 31,",
        "packets up to 128 characters; `tests/serialsocket/test_protocol_vectors.py`",
        "checks that this block equals what the code produces and recomputes every",
        "length, check and data field independently. Each packet is shown as rows of",
        "16 bytes: hex, and under it the same bytes as characters (`SOH` 0x01, `CR`",
        "0x0d, `SP` 0x20; everything else is the printable character itself).",
        "",
    ]
    for n, v in enumerate(exchange(), start=1):
        other = "B" if v.sender == "A" else "A"
        field = None
        if v.damaged:
            title = f"**{n}. {v.sender} → {other}** ({v.note})"
        else:
            described, field = _describe(v.raw)
            title = f"**{n}. {v.sender} → {other}** {v.note}: {described}"
        lines += [title, "", "```", *dump(v.raw), "```", ""]
        if field is not None:
            lines += ["Its data field, by init field (section 3):", "", *_init_table(field), ""]
    return "\n".join(lines).rstrip("\n")


# -- reading the document back -----------------------------------------------------------

HEADING = re.compile(
    r"^\*\*(\d+)\. ([AB]) → ([AB])\*\* (?:.*?: `(\w)` seq (\d+), (normal|extended), (\d+) bytes"
    r"(?:, data (b.*) \((\d+) bytes\)|, data field (b.*))|\((.*)\))$"
)


@dataclass(frozen=True)
class DocVector:
    number: int
    sender: str
    heading: re.Match[str]
    raw: bytes


def document_vectors() -> list[DocVector]:
    """Every vector of PROTOCOL.md, its bytes read from the hex rows (checked against
    the character rows)."""
    text = PROTOCOL.read_text(encoding="utf-8")
    section = text[text.index(BEGIN) + len(BEGIN) : text.index(END)]
    found = []
    lines = section.splitlines()
    for i, line in enumerate(lines):
        match = HEADING.match(line)
        if match is None:
            continue
        assert lines[i + 1 : i + 3] == ["", "```"], line
        end = lines.index("```", i + 3)
        rows = lines[i + 3 : end]
        raw = bytearray()
        for hex_row, text_row in zip(rows[::2], rows[1::2], strict=True):
            cells = bytes(int(c, 16) for c in hex_row.split())
            shown = [text_row[j : j + 3].strip() for j in range(0, len(text_row), 4)]
            assert len(shown) == len(cells), line
            for byte, cell in zip(cells, shown, strict=True):
                expected = {"SOH": SOH, "CR": CR, "SP": 0x20}.get(cell)
                assert byte == (expected if expected is not None else ord(cell)), (line, cell)
            raw += cells
        found.append(DocVector(int(match[1]), match[2], match, bytes(raw)))
    return found


def crc16_kermit(data: bytes) -> int:
    """Bitwise CRC-16/KERMIT (reflected 0x1021 = 0x8408, init 0, no final XOR)."""
    crc = 0
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8408 if crc & 1 else crc >> 1
    return crc


def decode_printable(field: bytes) -> bytes:
    """reference/kermit.md section 3: REPT count, then QBIN, then QCTL, then the char."""
    out = bytearray()
    i = 0
    while i < len(field):
        count = 1
        if field[i] == ord("~"):
            count, i = field[i + 1] - 32, i + 2
        high = 0
        if field[i] == ord("&"):
            high, i = 0x80, i + 1
        char = field[i]
        if char == ord("#"):
            i += 1
            char = field[i]
            if 63 <= (char & 0x7F) <= 95:
                char ^= 64
        out += bytes([char | high]) * count
        i += 1
    return bytes(out)


def check_framing(raw: bytes) -> tuple[str, int, bytes]:
    """Framing, lengths and checks as the document specifies; returns (type, seq, data field)."""
    assert raw[0] == SOH
    assert raw[-1] == CR
    body = raw[1:-4]  # LEN through the last DATA character: what the CRC covers
    check = raw[-4:-1]
    crc = crc16_kermit(body)
    assert check == bytes([32 + (crc >> 12 & 0x0F), 32 + (crc >> 6 & 0x3F), 32 + (crc & 0x3F)])
    if raw[1] == 0x20:  # extended: LEN = SP, LENX1 LENX2 count DATA + CHECK
        header = raw[1:6]
        total = sum(header)
        assert raw[6] == 32 + ((total + ((total & 0xC0) >> 6)) & 0x3F)  # type-1 HCHECK
        assert (raw[4] - 32) * 95 + (raw[5] - 32) == len(raw) - 8
        assert len(raw) - 1 > 96  # too long for a normal packet
        data = raw[7:-4]
    else:
        assert raw[1] - 32 == len(raw) - 3  # SEQ through CHECK
        data = raw[4:-4]
    return chr(raw[3]), raw[2] - 32, data


def test_the_document_holds_the_vectors_the_code_makes() -> None:
    text = PROTOCOL.read_text(encoding="utf-8")
    section = text[text.index(BEGIN) + len(BEGIN) : text.index(END)]
    assert section == render(), (
        "regenerate with: python -m tests.serialsocket.test_protocol_vectors "
        "(and paste it between the markers)"
    )


def test_the_vectors_follow_the_document_independently_of_the_code() -> None:
    vectors = document_vectors()
    assert [v.number for v in vectors] == list(range(1, len(vectors) + 1))
    kinds = set()
    for v in vectors:
        m = v.heading
        if m[11] is not None:  # the damaged copy: its check fails
            with pytest.raises(AssertionError):
                check_framing(v.raw)
            continue
        ptype, seq, field = check_framing(v.raw)
        assert (ptype, seq, len(v.raw)) == (m[4], int(m[5]), int(m[7]))
        assert (m[6] == "extended") == (v.raw[1] == 0x20)
        kinds.add(ptype)
        if m[8] is not None:  # D and E: the claimed data, decoded by hand
            claimed = ast.literal_eval(m[8])  # a bytes literal written by render()
            assert decode_printable(field) == claimed
            assert len(claimed) == int(m[9])
        elif m[10] is not None:
            assert field == ast.literal_eval(m[10])
    # Every packet type of section 2, the long form and a refusal are shown.
    assert kinds == {"I", "Y", "D", "N", "Z", "E"}
    assert any(m.heading[6] == "extended" for m in vectors)


def test_the_init_fields_say_what_section_3_says() -> None:
    init = next(v for v in document_vectors() if v.heading[4] == "I")
    _, _, field = check_framing(init.raw)
    assert field[:9] == b"~  @-#&5~"  # MAXL 94, TIME, NPAD 0, PADC NUL, EOL CR, #, &, FORCE-3, ~
    assert field[9] - 32 == 2 | 4  # CAPAS: long packets, sliding windows
    assert field[10] - 32 == 31  # WINDO
    # MAXLX: DATA + CHECK of 1024, the measured length's receive limit (PROTOCOL.md 4.7)
    assert (field[11] - 32) * 95 + field[12] - 32 == 1024 - 7
    assert field[13:17] == b"0___"  # CHKPNT, CHKINT
    assert field[17:21] == b'@"TL'  # WHATAMI, SYSID "TL"


def test_the_parser_accepts_every_packet_and_rejects_the_damaged_one() -> None:
    vectors = document_vectors()
    parser = PacketParser(check=BlockCheck.CRC16, init_check=BlockCheck.CRC16)
    for v in vectors:
        for byte in v.raw:  # one byte at a time
            parser.receive_data(bytes([byte]))
        event = parser.next_event()
        if v.heading[11] is not None:
            assert isinstance(event, PacketRejected)
            assert event.reason is RejectReason.BAD_CHECK
        else:
            assert isinstance(event, PacketReceived)
            assert (event.packet.type, event.packet.seq) == (v.heading[4], int(v.heading[5]))
        assert parser.next_event() is None


if __name__ == "__main__":
    print(BEGIN + render() + END)
