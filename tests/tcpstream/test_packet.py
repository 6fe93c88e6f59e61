"""The fixed-size packet: exact layout, round trips and the strict-decoding matrix."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tcpstream import CommandCode, FailureReason
from tcpstream.commands import (
    NUMERIC_KINDS,
    PACKET_SIZE,
    BadField,
    BadMagic,
    BadVersion,
    NonFiniteWord,
    Packet,
    PacketError,
    PacketKind,
    UnknownCommand,
    UnknownKind,
    WrongSize,
    decode_packet,
    encode_packet,
    pack_text,
    unpack_text,
    words_body,
)

FINITE = st.floats(allow_nan=False, allow_infinity=False)


def sample(kind: PacketKind = PacketKind.COMMAND) -> Packet:
    return Packet(
        kind=kind,
        flags=0x0001,
        code=CommandCode.MOVE_TO_POSITION,
        status=0,
        request_id=0x01020304,
        counter=0x1122334455667788,
        aux=(1.0, -2.0, 0.5, 0.0),
        body=words_body([float(i) for i in range(18)]),
    )


def test_size_is_216() -> None:
    assert PACKET_SIZE == 216
    assert len(encode_packet(sample())) == 216


def test_exact_bytes_of_the_header() -> None:
    raw = encode_packet(sample())
    assert raw[:2] == b"TL"
    assert raw[2] == 1  # version
    assert raw[3] == PacketKind.COMMAND == 6
    assert raw[4:6] == b"\x00\x01"  # flags, big-endian
    assert raw[6:8] == b"\x00\x05"  # MOVE_TO_POSITION
    assert raw[8:10] == b"\x00\x00"  # status
    assert raw[10:12] == b"\x00\x00"  # reserved
    assert raw[12:16] == b"\x01\x02\x03\x04"  # request id
    assert raw[16:24] == bytes.fromhex("1122334455667788")  # counter
    assert raw[24:32] == struct.pack("!d", 1.0)  # aux[0]
    assert raw[56:64] == struct.pack("!d", 0.0)  # body word 0
    assert raw[192:200] == struct.pack("!d", 17.0)  # body word 17
    assert raw[200:216] == bytes(16)  # no key: zero tag


@pytest.mark.parametrize("kind", list(PacketKind))
def test_round_trip_every_kind(kind: PacketKind) -> None:
    packet = sample(kind)
    assert decode_packet(encode_packet(packet)) == packet


@given(
    kind=st.sampled_from(sorted(NUMERIC_KINDS)),
    flags=st.integers(0, 7),  # COMMAND refuses unknown flag bits
    code=st.sampled_from(list(CommandCode)),
    status=st.integers(0, 0xFFFF),
    rid=st.integers(0, 2**32 - 1),
    counter=st.integers(0, 2**64 - 1),
    aux=st.tuples(FINITE, FINITE, FINITE, FINITE),
    words=st.lists(FINITE, min_size=18, max_size=18),
)
def test_round_trip_property(
    kind: PacketKind,
    flags: int,
    code: CommandCode,
    status: int,
    rid: int,
    counter: int,
    aux: tuple[float, float, float, float],
    words: list[float],
) -> None:
    packet = Packet(kind, flags, code, status, rid, counter, aux, words_body(words))
    back = decode_packet(encode_packet(packet))
    assert back == packet
    assert back.words() == tuple(words)


def corrupt(offset: int, value: bytes) -> bytes:
    raw = bytearray(encode_packet(sample()))
    raw[offset : offset + len(value)] = value
    return bytes(raw)


NAN = struct.pack("!d", math.nan)
INF = struct.pack("!d", math.inf)


@pytest.mark.parametrize(
    ("data", "error", "reason"),
    [
        pytest.param(b"", WrongSize, FailureReason.BAD_PACKET, id="empty"),
        pytest.param(encode_packet(sample())[:-1], WrongSize, FailureReason.BAD_PACKET, id="short"),
        pytest.param(
            encode_packet(sample()) + b"\0", WrongSize, FailureReason.BAD_PACKET, id="long"
        ),
        pytest.param(corrupt(0, b"XL"), BadMagic, FailureReason.BAD_PACKET, id="magic-0"),
        pytest.param(corrupt(1, b"X"), BadMagic, FailureReason.BAD_PACKET, id="magic-1"),
        pytest.param(corrupt(2, b"\x02"), BadVersion, FailureReason.BAD_PACKET, id="version"),
        pytest.param(corrupt(2, b"\x00"), BadVersion, FailureReason.BAD_PACKET, id="version-0"),
        pytest.param(corrupt(3, b"\x00"), UnknownKind, FailureReason.BAD_PACKET, id="kind-0"),
        pytest.param(corrupt(3, b"\x0e"), UnknownKind, FailureReason.BAD_PACKET, id="kind-14"),
        pytest.param(corrupt(3, b"\xff"), UnknownKind, FailureReason.BAD_PACKET, id="kind-255"),
        pytest.param(corrupt(10, b"\x00\x01"), BadField, FailureReason.BAD_PACKET, id="reserved"),
        pytest.param(corrupt(4, b"\x00\x08"), BadField, FailureReason.BAD_PACKET, id="flags"),
        pytest.param(corrupt(4, b"\x80\x00"), BadField, FailureReason.BAD_PACKET, id="flags-hi"),
        pytest.param(corrupt(24, NAN), NonFiniteWord, FailureReason.BAD_PACKET, id="aux-nan"),
        pytest.param(corrupt(48, INF), NonFiniteWord, FailureReason.BAD_PACKET, id="aux-inf"),
        pytest.param(corrupt(56, NAN), NonFiniteWord, FailureReason.BAD_PACKET, id="arg-nan"),
        pytest.param(corrupt(192, INF), NonFiniteWord, FailureReason.BAD_PACKET, id="arg-inf"),
        pytest.param(
            corrupt(6, b"\x00\x00"), UnknownCommand, FailureReason.UNKNOWN_COMMAND, id="code-0"
        ),
        pytest.param(
            corrupt(6, b"\x00\x12"), UnknownCommand, FailureReason.UNKNOWN_COMMAND, id="code-18"
        ),
        pytest.param(
            corrupt(6, b"\xff\xff"), UnknownCommand, FailureReason.UNKNOWN_COMMAND, id="code-max"
        ),
    ],
)
def test_strict_decoding_matrix(
    data: bytes, error: type[PacketError], reason: FailureReason
) -> None:
    with pytest.raises(error) as info:
        decode_packet(data)
    assert info.value.reason is reason
    assert info.value.message


def test_errors_after_the_kind_carry_the_request_id() -> None:
    with pytest.raises(UnknownCommand) as info:
        decode_packet(corrupt(6, b"\x00\x63"))
    assert info.value.request_id == 0x01020304
    with pytest.raises(BadMagic) as magic:
        decode_packet(corrupt(0, b"ZZ"))
    assert magic.value.request_id == 0  # nothing after a bad magic is trusted


def test_handshake_bodies_are_bytes_not_numbers() -> None:
    # A HELLO's body is identity bytes: NaN bit patterns there are fine.
    body = NAN * 18
    packet = Packet(PacketKind.HELLO, body=body)
    assert decode_packet(encode_packet(packet)).body == body
    # The same bytes in a numeric kind are refused both ways.
    with pytest.raises(ValueError, match="finite"):
        encode_packet(Packet(PacketKind.TELEMETRY, body=body))
    raw = bytearray(encode_packet(packet))
    raw[3] = PacketKind.TELEMETRY
    with pytest.raises(NonFiniteWord):
        decode_packet(bytes(raw))


def test_encode_refuses_wrong_shapes() -> None:
    with pytest.raises(ValueError, match="body"):
        encode_packet(Packet(PacketKind.HEARTBEAT, body=b"short"))
    with pytest.raises(ValueError, match="aux"):
        encode_packet(Packet(PacketKind.HEARTBEAT, aux=(1.0,)))


def test_text_is_cut_at_a_character_boundary() -> None:
    text = "é" * 100  # 200 bytes of UTF-8
    raw = pack_text(text)
    assert len(raw) == 144
    assert unpack_text(raw) == "é" * 72
    assert unpack_text(pack_text("ok")) == "ok"
