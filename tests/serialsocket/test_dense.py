"""Dense data-field encodings (issue 21) and the CRC-32 check: exact bytes,
round trips, references, canonical decoding, typed errors, field cutting."""

from __future__ import annotations

import crcmod.predefined
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from serialsocket import LocalProtocolError, MalformedDataError
from serialsocket._checks import CRC32_LENGTH, crc32_chars, crc32_ieee
from serialsocket._dense import (
    RADIX91_ALPHABET,
    XON_XOFF,
    EscapeEncoding,
    Radix91Encoding,
    _encode_tail,
)
from serialsocket.packets import (
    EIGHT_BIT_CLEAN,
    PRINTABLE,
    Encoding,
    Packet,
    PacketParser,
    PacketReceived,
    build_packet,
)

from .strategies import payloads

RADIX91 = Radix91Encoding()
ESCAPES = [
    EscapeEncoding(),
    EscapeEncoding(unsafe=XON_XOFF),
    EscapeEncoding(unsafe=b"\r\n\xff", escape=0x7D),
    EscapeEncoding(unsafe=bytes(range(32))[::2]),
]
DENSE = [RADIX91, *ESCAPES]
encodings = st.sampled_from(DENSE)
long_payloads = st.one_of(payloads, st.binary(min_size=500, max_size=5000))


def reference_escape(enc: EscapeEncoding, data: bytes) -> bytes:
    out = bytearray()
    for b in data:
        out += bytes((enc.escape, b ^ 0x40)) if b in enc.reserved else bytes((b,))
    return bytes(out)


def reference_radix91(data: bytes) -> bytes:
    """Straight from the definition: big-endian 104-bit blocks, 13-bit groups."""
    out = bytearray()
    for at in range(0, len(data), 13):
        block = data[at : at + 13]
        value = int.from_bytes(block.ljust(13, b"\0"), "big")
        bits = 8 * len(block)
        groups = -(-bits // 13)
        for g in range(groups):
            v = value >> (13 * (7 - g)) & 0x1FFF
            if g == groups - 1 and bits - 13 * g <= 6:
                out.append(RADIX91_ALPHABET[v >> 7])
            else:
                out += bytes((RADIX91_ALPHABET[v // 91], RADIX91_ALPHABET[v % 91]))
    return bytes(out)


def test_radix91_alphabet_is_printable_without_space_or_prefixes() -> None:
    assert len(RADIX91_ALPHABET) == 91
    assert len(set(RADIX91_ALPHABET)) == 91
    assert all(33 <= c <= 125 for c in RADIX91_ALPHABET)
    assert not set(b" #&~\x7f") & set(RADIX91_ALPHABET)


def digits(*values: int) -> bytes:
    return bytes(RADIX91_ALPHABET[v] for v in values)


@pytest.mark.parametrize(
    ("data", "wire"),
    [
        (b"", b""),
        (b"\x00", b"!!"),
        (b"\xff", digits(89, 61)),  # one group 0x1FE0 = 8160 = 89 * 91 + 61
        (b"\xff\xff", digits(90, 1, 7 << 3)),  # 8191, then 3 bits 111 in one char
        (b"\x00" * 13, b"!" * 16),
        (b"\xff" * 13, digits(90, 1) * 8),  # eight groups 8191 = 90 * 91 + 1
    ],
)
def test_radix91_exact_bytes(data: bytes, wire: bytes) -> None:
    assert RADIX91.encode(data) == wire == reference_radix91(data)
    assert RADIX91.decode(wire) == data


def test_radix91_length_table() -> None:
    # 13 bytes -> 16 characters; a tail of r bytes has a length of its own.
    lengths = [len(RADIX91.encode(bytes(r))) for r in range(27)]
    assert lengths[:14] == [0, 2, 3, 4, 5, 7, 8, 9, 10, 12, 13, 14, 15, 16]
    assert lengths[26] == 32
    assert len(set(lengths)) == 27
    assert _encode_tail(b"\x80\x00") == bytes((RADIX91_ALPHABET[4096 // 91],)) + bytes(
        (RADIX91_ALPHABET[4096 % 91], RADIX91_ALPHABET[0])
    )


def test_escape_exact_bytes() -> None:
    enc = EscapeEncoding(unsafe=XON_XOFF)
    assert enc.reserved == b"\x01\x11\x13\x18\x91\x93"
    assert enc.encode(b"a\x01b\x18\x11\x93\x0d\xff") == b"a\x18Ab\x18X\x18Q\x18\xd3\x0d\xff"
    assert EscapeEncoding().encode(bytes(range(256))) == (
        b"\x00\x18A" + bytes(range(2, 0x18)) + b"\x18X" + bytes(range(0x19, 256))
    )


@given(enc=encodings, data=long_payloads)
@example(enc=RADIX91, data=b"\xff" * 1300)
@example(enc=ESCAPES[1], data=XON_XOFF * 300 + b"\x01\x18")
def test_round_trip_and_matches_reference(
    enc: Radix91Encoding | EscapeEncoding, data: bytes
) -> None:
    wire = enc.encode(data)
    if isinstance(enc, Radix91Encoding):
        assert wire == reference_radix91(data)
        assert set(wire) <= set(RADIX91_ALPHABET)
        assert PRINTABLE.decode(wire) == wire  # a classic decoder sees it verbatim
    else:
        assert wire == reference_escape(enc, data)
        assert not set(wire) & (set(enc.reserved) - {enc.escape})
    assert 0x01 not in wire
    assert enc.decode(wire) == data


@given(enc=encodings, field=st.binary(max_size=400))
@example(enc=RADIX91, field=b"!" * 15 + b"\x7c")
@example(enc=ESCAPES[0], field=b"a\x18")
def test_decode_is_canonical_or_a_typed_error(
    enc: Radix91Encoding | EscapeEncoding, field: bytes
) -> None:
    # Every field either decodes to the one string that encodes back to it,
    # or raises MalformedDataError: never another exception, never two readings.
    try:
        data = enc.decode(field)
    except MalformedDataError as exc:
        hint = exc.error_hint
    else:
        assert enc.encode(data) == field
        return
    assert hint.startswith("Malformed dense data field")


@given(field=st.lists(st.sampled_from(RADIX91_ALPHABET), max_size=200).map(bytes))
def test_radix91_in_alphabet_fields(field: bytes) -> None:
    try:
        data = RADIX91.decode(field)
    except MalformedDataError:
        return
    assert RADIX91.encode(data) == field


@pytest.mark.parametrize(
    "field",
    [
        b"!",  # length 1 encodes nothing
        b"!" * 6,
        b"!" * 11,
        b"! ",  # space is outside the alphabet
        b"!#",
        b"}}",  # 90 * 91 + 90 >= 8192
        b'!"',  # 1 byte: the low 5 padding bits of the group are not zero
    ],
)
def test_radix91_malformed(field: bytes) -> None:
    with pytest.raises(MalformedDataError):
        RADIX91.decode(field)


@pytest.mark.parametrize(
    "field",
    [b"\x01", b"a\x18", b"\x18\x18", b"\x18B", b"\x11", b"\x18A\x13"],
)
def test_escape_malformed(field: bytes) -> None:
    with pytest.raises(MalformedDataError):
        EscapeEncoding(unsafe=XON_XOFF).decode(field)


def test_escape_rejects_a_reserved_set_whose_escapes_are_reserved() -> None:
    with pytest.raises(LocalProtocolError):
        EscapeEncoding(unsafe=b"A")  # 0x01 ^ 0x40 = 'A'
    with pytest.raises(LocalProtocolError):
        EscapeEncoding(escape=0x41)  # MARK's escaped form is the escape itself


@given(
    enc=encodings,
    data=long_payloads,
    capacity=st.integers(2, 300),
    count=st.integers(1, 40),
)
def test_fields_are_longest_fits_and_decode_alone(
    enc: Radix91Encoding | EscapeEncoding, data: bytes, capacity: int, count: int
) -> None:
    fields = enc.encode_fields(data, capacity, count)
    at = 0
    for field, used in fields:
        assert used >= 1
        assert len(field) <= capacity
        assert enc.decode(field) == data[at : at + used]
        if at + used < len(data):
            # Longest: one more byte would not have fitted.
            assert len(enc.encode(data[at : at + used + 1])) > capacity
        at += used
    assert len(fields) == count or at == len(data)
    assert (enc.encode_prefix(data, capacity) == fields[0]) if fields else (not data)


def test_capacity_too_small_is_a_local_error() -> None:
    for enc in DENSE:
        with pytest.raises(LocalProtocolError):
            enc.encode_prefix(b"x", 1)


def test_wire_ratios_of_random_bytes() -> None:
    data = bytes(range(256)) * 13
    assert len(RADIX91.encode(data)) / len(data) == 16 / 13
    assert len(ESCAPES[0].encode(data)) / len(data) == ESCAPES[0].random_ratio == 1 + 2 / 256
    assert ESCAPES[1].random_ratio == 1 + 6 / 256


def test_dense_fields_travel_in_kermit_packets() -> None:
    # The parser only needs the MARK out of the data field: both encodings qualify.
    data = bytes(range(256)) * 4
    parser = PacketParser(max_length=2000)
    for seq, enc in enumerate(DENSE):
        parser.receive_data(build_packet(Packet(seq=seq, type="D", data=enc.encode(data))))
        event = parser.next_event()
        assert isinstance(event, PacketReceived)
        assert enc.decode(event.packet.data) == data


def crc32_bitwise(data: bytes) -> int:
    crc = 0xFFFFFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ (0xEDB88320 if crc & 1 else 0)
    return crc ^ 0xFFFFFFFF


def test_crc32_check_value_and_characters() -> None:
    assert crc32_ieee(b"123456789") == 0xCBF43926
    assert crc32_ieee(b"6789", crc32_ieee(b"12345")) == 0xCBF43926
    # 0xCBF43926 = 11 001011 111101 000011 100100 100110
    assert crc32_chars(b"123456789") == bytes(
        (0b11 + 32, 0b001011 + 32, 0b111101 + 32, 0b000011 + 32, 0b100100 + 32, 0b100110 + 32)
    )
    assert len(crc32_chars(b"")) == CRC32_LENGTH


@given(st.binary(max_size=300))
def test_crc32_matches_crcmod_and_bitwise(data: bytes) -> None:
    expected = crcmod.predefined.mkCrcFun("crc-32")(data)
    assert crc32_ieee(data) == expected == crc32_bitwise(data)
    assert all(32 <= c <= 95 for c in crc32_chars(data))


@given(
    enc=encodings,
    data=long_payloads,
    capacity=st.integers(2, 200),
    damage=st.none() | st.tuples(st.integers(0, 10_000), st.integers(0, 255)),
)
def test_decode_fields_equals_decoding_one_by_one(
    enc: Radix91Encoding | EscapeEncoding,
    data: bytes,
    capacity: int,
    damage: tuple[int, int] | None,
) -> None:
    fields = [field for field, _ in enc.encode_fields(data, capacity, 10_000)]
    if damage is not None and fields:
        at, value = damage
        i = at % len(fields)
        if fields[i]:
            j = at % len(fields[i])
            fields[i] = fields[i][:j] + bytes((value,)) + fields[i][j + 1 :]
    try:
        one_by_one = b"".join(enc.decode(f) for f in fields)
    except MalformedDataError:
        with pytest.raises(MalformedDataError):
            enc.decode_fields(fields)
        return
    assert enc.decode_fields(fields) == one_by_one
    if damage is None:
        assert one_by_one == data


@pytest.mark.parametrize(
    ("enc", "fields"),
    [
        (EscapeEncoding(), [b"ab\x18", b"Acd"]),  # ESC ends a field, its 0x41 starts the next
        (EscapeEncoding(unsafe=XON_XOFF), [b"\x18", b"Q", b"x"]),
        (PRINTABLE, [b"ab#", b"Mcd"]),  # QCTL ends a field
        (EIGHT_BIT_CLEAN, [b"ab#", b"Mcd"]),
        (PRINTABLE, [b"ab&", b"a"]),  # QBIN
        (PRINTABLE, [b"x~", b"#a"]),  # a repeat count split from its REPT
        (PRINTABLE, [b"a" * 800 + b"#", b"M" + b"b" * 100]),  # the vectorised path
        (PRINTABLE, [b"b" * 300 + b"~(", b"c", b"a" * 500]),
    ],
)
def test_decode_fields_rejects_a_token_across_fields(
    enc: EscapeEncoding | Encoding, fields: list[bytes]
) -> None:
    """Found by fuzz_parser's decode_fields property (2026-11-29): the fields of
    one arrival were decoded as their concatenation, so a token cut at the end
    of one packet and completed by the next was accepted -- a malformed field
    (PROTOCOL.md 10.3; Kermit's prefixes) aborted the connection or not
    depending on whether the next packet arrived in the same read."""
    with pytest.raises(MalformedDataError):
        enc.decode(fields[0])
    with pytest.raises(MalformedDataError):
        enc.decode_fields(fields)


@pytest.mark.parametrize("enc", [PRINTABLE, EIGHT_BIT_CLEAN])
def test_prefix_decode_fields_vectorised_matches_one_by_one(enc: Encoding) -> None:
    data = bytes(range(256)) * 8 + b"\x00" * 300 + b"#&~" * 50
    fields = [f for f, _ in enc.encode_fields(data, 90, 10_000)]
    assert sum(map(len, fields)) > 768  # past _VECTOR_FROM
    assert enc.decode_fields(fields) == data == b"".join(map(enc.decode, fields))


@pytest.mark.parametrize("blocks", [1, 7, 255, 256, 600])
def test_radix91_small_and_large_paths_agree(blocks: int, monkeypatch: pytest.MonkeyPatch) -> None:
    data = bytes((i * 97 + i // 13) & 0xFF for i in range(13 * blocks)) + b"\xff\x00\x80"
    wires = set()
    for small in (0, 10**9):
        monkeypatch.setattr("serialsocket._dense._SMALL", small)
        monkeypatch.setattr("serialsocket._dense._SMALL_FIELD_BLOCKS", small)
        wire = RADIX91.encode(data)
        assert RADIX91.decode(wire) == data
        fields = RADIX91.encode_fields(data, 118, 10_000)
        assert RADIX91.decode_fields([f for f, _ in fields]) == data
        wires.add(wire)
    assert wires == {reference_radix91(data)}


@given(field=st.lists(st.sampled_from(RADIX91_ALPHABET), max_size=300).map(bytes))
def test_radix91_python_and_numpy_block_decoders_agree(field: bytes) -> None:
    import serialsocket._dense as dense

    def run(blocks: int) -> bytes | str:
        old = dense._SMALL_FIELD_BLOCKS
        dense._SMALL_FIELD_BLOCKS = blocks
        try:
            return RADIX91.decode(field)
        except MalformedDataError as exc:
            return str(exc)
        finally:
            dense._SMALL_FIELD_BLOCKS = old

    assert run(0) == run(10**9)
