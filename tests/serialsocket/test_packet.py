"""Packet framing: verified vectors from real Kermit programs, format boundaries."""

from __future__ import annotations

import pytest

from serialsocket import LocalProtocolError
from serialsocket.packets import (
    EIGHT_BIT_CLEAN,
    PRINTABLE,
    BlockCheck,
    Packet,
    PacketType,
    build_packet,
    check_chars,
    crc16_kermit,
    data_capacity,
    packet_length,
)

GKERMIT_D = bytes.fromhex(
    "014d234448656c6c6f2c204b65726d697421234d234a23402341234223bf23fe207e344120237e"
    "232326234a2d2e310d"
)
GKERMIT_EXTENDED_D = bytes.fromhex(
    "01202544212936234a54522f264d26234d26235b6a6a79262a26234923232326263c266f235956"
    "26235826234a2636762648264c5826772623442628712623447d234f264e2622265d233f262349"
    "61255426634b262346266b5346462661263826235e264d7b3b6926235c222a50360d"
)


def test_crc16_kermit_check_value() -> None:
    assert crc16_kermit(b"123456789") == 0x2189
    assert check_chars(BlockCheck.CRC16, b"123456789") == b'"&)'


def test_not_crc_xmodem() -> None:
    import binascii

    assert binascii.crc_hqx(b"123456789", 0) == 0x31C3 != crc16_kermit(b"123456789")


def test_gkermit_file_header() -> None:
    wire = build_packet(Packet(seq=1, type="F", data=b"HELLO.BIN"))
    assert wire == b"\x01.!FHELLO.BIN 6F\r"
    assert crc16_kermit(b".!FHELLO.BIN") == 0x05A6


def test_empty_ack_from_both_captures() -> None:
    assert build_packet(Packet(seq=3, type=PacketType.ACK)) == b"\x01%#Y/R9\r"
    assert crc16_kermit(b"%#Y") == 0xFC99


@pytest.mark.parametrize(
    ("data", "wire"),
    [
        (b"~' @-#Y3~*!J*0+++B\"U1A", b"\x019 S~' @-#Y3~*!J*0+++B\"U1AH\r"),  # G-Kermit
        (b'~/ @-#Y3~^>J)0___F"U1@', b'\x019 S~/ @-#Y3~^>J)0___F"U1@?\r'),  # C-Kermit
    ],
)
def test_send_init_packets_type_1(data: bytes, wire: bytes) -> None:
    assert build_packet(Packet(seq=0, type="S", data=data), BlockCheck.SUM6) == wire


def test_gkermit_data_packet_round_trips_byte_for_byte() -> None:
    field = EIGHT_BIT_CLEAN.encode(
        b"Hello, Kermit!\r\n\x00\x01\x02\xff\xfe" + b" " + b"A" * 20 + b" ~#&\n"
    )
    assert build_packet(Packet(seq=3, type="D", data=field)) == GKERMIT_D
    assert crc16_kermit(GKERMIT_D[1:-4]) == 0xD391


def test_gkermit_extended_packet() -> None:
    field = GKERMIT_EXTENDED_D[7:-4]
    assert len(field) == 101
    wire = build_packet(Packet(seq=5, type="D", data=field))
    assert wire == GKERMIT_EXTENDED_D
    assert wire[1:7] == b" %D!)6"
    assert crc16_kermit(wire[1:-4]) == 0xAC16
    assert check_chars(BlockCheck.SUM6, b" #D%2") == b"A"


@pytest.mark.parametrize("check", list(BlockCheck))
def test_normal_extended_boundary(check: BlockCheck) -> None:
    # LEN = data + check + 2 must stay <= 94; one more character goes extended
    # (C-Kermit once built LEN 95/96 as normal packets: ckwin PR 559).
    largest_normal = 94 - 2 - int(check)
    normal = build_packet(Packet(seq=0, type="D", data=b"x" * largest_normal), check)
    assert normal[1] == 32 + 94
    assert len(normal) - 1 == packet_length(largest_normal, check) == 96
    extended = build_packet(Packet(seq=0, type="D", data=b"x" * (largest_normal + 1)), check)
    assert extended[1] == 32
    assert len(extended) - 1 == packet_length(largest_normal + 1, check)


def test_default_128_byte_packet() -> None:
    assert data_capacity(128, BlockCheck.CRC16) == 118
    wire = build_packet(Packet(seq=0, type="D", data=b"x" * 118))
    assert len(wire) == 128 + 1  # plus CR
    assert data_capacity(96, BlockCheck.CRC16) == 89
    assert data_capacity(9031, BlockCheck.CRC16) == 9021


def test_largest_packet_and_beyond() -> None:
    wire = build_packet(Packet(seq=0, type="D", data=b"x" * 9021))
    assert len(wire) == 9031 + 1
    with pytest.raises(LocalProtocolError):
        build_packet(Packet(seq=0, type="D", data=b"x" * 9022))
    with pytest.raises(LocalProtocolError, match="outside"):
        data_capacity(9032, BlockCheck.CRC16)
    with pytest.raises(LocalProtocolError, match="outside"):
        data_capacity(11, BlockCheck.CRC16)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"seq": 64, "type": "D"},
        {"seq": -1, "type": "D"},
        {"seq": 0, "type": "DD"},
        {"seq": 0, "type": " "},
        {"seq": 0, "type": "D", "data": b"a\x01b"},
    ],
)
def test_invalid_packets(kwargs: dict[str, object]) -> None:
    with pytest.raises(LocalProtocolError):
        Packet(**kwargs)  # type: ignore[arg-type]


def test_known_types_become_enum_members_unknown_stay_strings() -> None:
    assert Packet(seq=0, type="D").type is PacketType.DATA
    assert Packet(seq=0, type="Q").type == "Q"


def test_padding_and_eol() -> None:
    wire = build_packet(Packet(seq=3, type="Y"), eol=None, padding=b"\x00\x00")
    assert wire == b"\x00\x00\x01%#Y/R9"
    assert PRINTABLE.encode(b"") == b""
