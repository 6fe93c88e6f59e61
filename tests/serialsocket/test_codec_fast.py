"""The fast codec paths against the plain reference definitions, for every profile.

``serialsocket._encoding`` keeps the one-token-at-a-time definitions
(``_reference_encode``, ``_reference_encode_prefix``, ``_reference_decode``);
the vectorised encoder, the regular-expression decoder for short fields and
the numpy decoder for long ones must agree with them byte for byte (and on
which inputs are malformed).  Each decoder path is called directly, so both
are covered whatever the length threshold between them.
"""

from __future__ import annotations

import itertools

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from serialsocket import MalformedDataError
from serialsocket._encoding import (
    MAX_TOKEN_LENGTH,
    _reference_decode,
    _reference_encode,
    _reference_encode_prefix,
)
from serialsocket.packets import (
    EIGHT_BIT_CLEAN,
    PRINTABLE,
    BlockCheck,
    Encoding,
    Packet,
    PacketParser,
    ParserEvent,
    ParserStatistics,
    build_packet,
    check_chars,
)

from .strategies import payloads

ALL_PROFILES = [
    Encoding(qctl=qctl, qbin=qbin, rept=rept)
    for qctl, qbin, rept in itertools.product(
        [ord("#"), ord("!"), ord("`")], [None, ord("&"), ord(">")], [None, ord("~"), ord("%")]
    )
]
"""Every combination of the prefix options: QBIN on/off, REPT on/off, three QCTLs."""

profiles = st.sampled_from(ALL_PROFILES)


def long_payloads() -> st.SearchStrategy[bytes]:
    """Payloads long enough for the vectorised paths, with runs sprinkled in."""
    piece = st.one_of(
        st.binary(min_size=1, max_size=400),
        st.tuples(st.integers(0, 255), st.integers(1, 200)).map(lambda t: bytes([t[0]]) * t[1]),
    )
    return st.lists(piece, min_size=1, max_size=12).map(b"".join)


def prefix_soup(enc: Encoding) -> st.SearchStrategy[bytes]:
    """Arbitrary fields dense in this profile's prefix characters: every chain,
    dangling ends and bad repeat counts included."""
    chars = [c for c in (enc.qctl, enc.qbin, enc.rept) if c is not None]
    alphabet = st.sampled_from([*chars, *chars, 0x20, 0x21, 0x3F, 0x40, 0x5F, 0x7E, 0xA3, 0xFF])
    return st.lists(st.one_of(alphabet, st.integers(0, 255)), max_size=3000).map(bytes)


def outcome(fn: object, *args: object) -> bytes | type[Exception]:
    assert callable(fn)
    try:
        result = fn(*args)
    except MalformedDataError:
        return MalformedDataError
    assert isinstance(result, bytes)
    return result


@given(enc=profiles, data=st.one_of(payloads, long_payloads()))
@example(enc=PRINTABLE, data=bytes(range(256)) * 40)
@example(enc=PRINTABLE, data=b"\x00" * 5000)
@example(enc=EIGHT_BIT_CLEAN, data=b"ab" * 3000 + b"ccc")
def test_encode_matches_reference(enc: Encoding, data: bytes) -> None:
    wire = enc.encode(data)
    assert wire == _reference_encode(enc, data)
    assert enc._decode_split(wire) == data
    if wire:
        assert enc._decode_vector(wire) == data
    assert enc.decode(wire) == data


@given(enc=profiles, data=st.data())
def test_decoders_agree_with_reference_on_arbitrary_fields(
    enc: Encoding, data: st.DataObject
) -> None:
    field = data.draw(prefix_soup(enc))
    expected = outcome(_reference_decode, enc, field)
    assert outcome(enc._decode_split, field) == expected
    if field:
        assert outcome(enc._decode_vector, field) == expected
    assert outcome(enc.decode, field) == expected


@given(enc=profiles, data=payloads, capacity=st.integers(MAX_TOKEN_LENGTH, 300))
def test_encode_prefix_matches_reference(enc: Encoding, data: bytes, capacity: int) -> None:
    assert enc.encode_prefix(data, capacity) == _reference_encode_prefix(enc, data, capacity)


@given(
    enc=profiles,
    data=st.one_of(payloads, long_payloads()),
    capacity=st.integers(MAX_TOKEN_LENGTH, 200),
    count=st.integers(1, 40),
)
def test_encode_fields_matches_reference(
    enc: Encoding, data: bytes, capacity: int, count: int
) -> None:
    expected = []
    rest = data
    while rest and len(expected) < count:
        field, used = _reference_encode_prefix(enc, rest, capacity)
        expected.append((field, used))
        rest = rest[used:]
    assert enc.encode_fields(data, capacity, count) == expected


@pytest.mark.parametrize("enc", ALL_PROFILES, ids=repr)
def test_encode_prefix_never_cuts_a_run_at_its_slice(enc: Encoding) -> None:
    """Found by fuzz_parser's encode_fields property (2026-11-29): encode_prefix
    tokenised a slice of ``capacity`` bytes, so a run crossing the slice's end
    counted as two single tokens that fit where the run's repeat token did not,
    and a field depended on how many fields were cut with it."""
    for data, capacity in ((b"abcd" + b"\0" * 5, 6), (b"xy" * 40 + b"\x81" * 200, 90)):
        expected = _reference_encode_prefix(enc, data, capacity)
        assert enc.encode_prefix(data, capacity) == expected
        assert enc.encode_fields(data, capacity, 1)[0] == enc.encode_fields(data, capacity, 2)[0]


@pytest.mark.parametrize("enc", ALL_PROFILES, ids=repr)
def test_encode_fields_never_cuts_a_run_at_its_slice(enc: Encoding) -> None:
    """The same in encode_fields, found by fuzz_parser (2026-12-05): its slice
    ended two bytes into a run of seven 0xFF, which it read as two single
    tokens, and a field that had room for one of them but not for the run's
    repeat token took it, where encode_prefix (reading the whole run) took
    neither: the field depended on how far the slice reached."""
    data = b"r" * 30 + b"\0" * 7 + b"[" + b"r" * 36 + b"\xff" * 7 + b"\x04rrrrr\x00\x91\xfe\x01"
    for count in range(1, 6):
        expected = []
        rest = data
        while rest and len(expected) < count:
            field, used = _reference_encode_prefix(enc, rest, 7)
            expected.append((field, used))
            rest = rest[used:]
        assert enc.encode_fields(data, 7, count) == expected, count


@pytest.mark.parametrize("enc", ALL_PROFILES, ids=repr)
def test_every_byte_value_and_run_boundary(enc: Encoding) -> None:
    # Each byte value alone, in runs of 1..3 and around the 94-byte repeat limit.
    for n in (1, 2, 3, 4, 93, 94, 95, 96, 97, 188, 189):
        data = b"".join(bytes([b]) * n + b"x" for b in range(256))
        wire = enc.encode(data)
        assert wire == _reference_encode(enc, data)
        assert enc._decode_vector(wire) == data
        assert enc._decode_split(wire) == data


@pytest.mark.parametrize(
    ("field", "expected"),
    [
        (b"~#&", MalformedDataError),  # dangling after a repeat count and QBIN
        (b"~##", MalformedDataError),  # REPT count '#' then a lone QCTL
        (b"&#", MalformedDataError),  # QBIN QCTL at the end
        (b"x~", MalformedDataError),
        (b"~\x1fA", MalformedDataError),  # count below 1
        (b"~\x7fA", MalformedDataError),  # count above 94
        (b"&&", b"\xa6"),  # QBIN then a literal QBIN (G-Kermit decode)
        (b"~#~", b"~~~"),  # after a count, REPT is literal
        (b"&~", b"\xfe"),
        (b"~!#@", b"\x00"),  # a count of 1 is legal
    ],
)
def test_corner_fields(field: bytes, expected: bytes | type[Exception]) -> None:
    assert outcome(_reference_decode, PRINTABLE, field) == expected
    assert outcome(PRINTABLE._decode_split, field) == expected
    assert outcome(PRINTABLE._decode_vector, field) == expected
    # The same corner embedded at the end of a long valid field.
    long = PRINTABLE.encode(bytes(range(256)) * 12) + field
    full = outcome(_reference_decode, PRINTABLE, long)
    assert outcome(PRINTABLE.decode, long) == full
    assert outcome(PRINTABLE._decode_split, long) == full


packet_specs = st.lists(
    st.one_of(
        st.tuples(
            st.integers(0, 63),
            st.sampled_from(["D", "Y", "N", "S", "I", "E", "Z", "q"]),
            st.binary(max_size=300).map(PRINTABLE.encode),
            st.sampled_from(list(BlockCheck)),
        ),
        st.binary(max_size=12),  # line noise between packets
    ),
    max_size=20,
)


@given(specs=packet_specs, data=st.data())
def test_parser_fast_path_gives_the_events_of_the_general_path(
    specs: list[tuple[int, str, bytes, BlockCheck] | bytes], data: st.DataObject
) -> None:
    wire = bytearray()
    for spec in specs:
        if isinstance(spec, bytes):
            wire += spec
        else:
            seq, ptype, field, check = spec
            wire += build_packet(Packet(seq=seq, type=ptype, data=field), check)
    if wire and data.draw(st.booleans()):
        # One flipped bit somewhere: damage must be reported the same way too.
        at = data.draw(st.integers(0, len(wire) - 1))
        wire[at] ^= 1 << data.draw(st.integers(0, 7))
    max_len = data.draw(st.sampled_from([96, 200, 400]))

    def run(fast: bool) -> tuple[list[ParserEvent], ParserStatistics, int]:
        parser = PacketParser(max_length=max_len)
        if not fast:
            parser._next_fast = lambda *args: None  # type: ignore[method-assign]
        events = []
        for chunk in (bytes(wire[i : i + 50]) for i in range(0, len(wire), 50)):
            parser.receive_data(chunk)
            while (ev := parser.next_event()) is not None:
                events.append(ev)
        return events, parser.statistics(), parser.buffered

    assert run(fast=True) == run(fast=False)


@given(enc=profiles, data=st.one_of(payloads, long_payloads()), capacity=st.integers(5, 200))
def test_decode_fields_equals_decoding_one_by_one(
    enc: Encoding, data: bytes, capacity: int
) -> None:
    fields = [field for field, _ in enc.encode_fields(data, capacity, 10_000)]
    assert enc.decode_fields(fields) == b"".join(enc.decode(f) for f in fields) == data


def reference_build(packet: Packet, check: BlockCheck, eol: int | None, padding: bytes) -> bytes:
    """build_packet from reference/kermit.md section 1, one field at a time."""
    field = len(packet.data) + int(check)
    if field + 2 <= 94:
        covered = bytes((field + 2 + 32, packet.seq + 32, ord(packet.type)))
    else:
        hdr = bytes((32, packet.seq + 32, ord(packet.type), field // 95 + 32, field % 95 + 32))
        covered = hdr + check_chars(BlockCheck.SUM6, hdr)
    covered += packet.data
    tail = b"" if eol is None else bytes((eol,))
    return padding + b"\x01" + covered + check_chars(check, covered) + tail


@given(
    specs=st.lists(
        st.tuples(
            st.integers(0, 63),
            st.sampled_from(["D", "Y", "N", "q", "S"]),
            st.sampled_from([0, 1, 85, 86, 87, 88, 89, 90, 91, 117, 118, 500]),
            st.sampled_from(list(BlockCheck)),
            st.sampled_from([None, 13, 10]),
            st.sampled_from([b"", b"\x00\x00"]),
        ),
        max_size=30,
    ),
    data=st.data(),
)
def test_build_packet_matches_reference_across_its_header_cache(
    specs: list[tuple[int, str, int, BlockCheck, int | None, bytes]], data: st.DataObject
) -> None:
    # Repeated (seq, type, length) triples with different data exercise the
    # cached header and its CRC; the normal/extended boundary sits at 89-91.
    for seq, ptype, length, check, eol, padding in specs * 2:
        field = data.draw(st.binary(min_size=length, max_size=length).map(PRINTABLE.encode))
        field = field[:length].replace(b"\x01", b"A")
        packet = Packet(seq=seq, type=ptype, data=field)
        wire = build_packet(packet, check, eol=eol, padding=padding)
        assert wire == reference_build(packet, check, eol, padding)
