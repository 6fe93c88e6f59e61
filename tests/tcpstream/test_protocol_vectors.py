"""PROTOCOL.md section 13 holds exactly the bytes the code produces, and the bytes
follow the document's rules when checked independently of the code."""

from __future__ import annotations

import hashlib
import hmac
import pathlib
import struct

from tcpstream.commands import PACKET_SIZE, PacketKind, decode_packet

from .vectors import KEY, render, session_vectors

PROTOCOL = pathlib.Path(__file__).parents[2] / "tcpstream" / "PROTOCOL.md"


def test_the_document_holds_the_vectors_the_code_makes() -> None:
    text = PROTOCOL.read_text()
    begin, end = "<!-- vectors:begin -->\n", "\n<!-- vectors:end -->"
    section = text[text.index(begin) + len(begin) : text.index(end)]
    assert section == render(), "regenerate with: python -m tests.tcpstream.vectors"


def test_every_packet_kind_is_covered() -> None:
    vectors, _ = session_vectors()
    kinds = {PacketKind(v.raw[3]) for v in vectors}
    assert kinds == set(PacketKind)
    assert all(len(v.raw) == PACKET_SIZE for v in vectors)


def test_the_vectors_follow_section_8_independently_of_the_code() -> None:
    """Recompute the session key and every tag from the document's formulas."""
    vectors, secrets = session_vectors()
    by_name = {v.name: v for v in vectors}
    hello, challenge = by_name["HELLO"].raw, by_name["CHALLENGE"].raw
    identity, incarnation, client_nonce = hello[56:88], hello[88:96], hello[96:112]
    server_nonce = challenge[56:72]
    transcript = client_nonce + server_nonce + identity + incarnation + b"\x00"
    ks = hmac.new(KEY, b"telelink-v1 session key" + transcript, hashlib.sha256).digest()
    assert ks == secrets["session key Ks"]
    counters = {"C -> A": 0, "A -> C": 0}
    for v in vectors:
        if v.name == "REFUSE":
            continue  # the unkeyed session
        counter = struct.unpack_from("!Q", v.raw, 16)[0]
        assert counter == counters[v.direction] + 1, v.name  # 1, 2, 3... per direction
        counters[v.direction] = counter
        if v.name in ("HELLO", "CHALLENGE"):
            assert v.raw[200:] == bytes(16), v.name  # sent before Ks is known: untagged
            continue
        direction = b"\x01" if v.direction == "C -> A" else b"\x02"
        tag = hmac.new(ks, direction + v.raw[:200], hashlib.sha256).digest()[:16]
        assert v.raw[200:] == tag, v.name
        decode_packet(v.raw)  # and each one is a valid packet
    auth = by_name["AUTH"].raw
    assert auth[56:88] == secrets["client proof"]
    assert by_name["GRANT"].raw[56:88] == secrets["server proof"]
