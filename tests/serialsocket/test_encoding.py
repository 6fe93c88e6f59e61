"""Prefix encoding: exact bytes from real Kermit captures, properties, and edge cases."""

from __future__ import annotations

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from serialsocket import LocalProtocolError, MalformedDataError
from serialsocket._encoding import MAX_TOKEN_LENGTH
from serialsocket.packets import EIGHT_BIT_CLEAN, PRINTABLE, Encoding

from .strategies import encodings, payloads

GKERMIT_PAYLOAD = b"Hello, Kermit!\r\n\x00\x01\x02\xff\xfe" + b" " + b"A" * 20 + b" ~#&\n"


def reference_encode(enc: Encoding, data: bytes) -> bytes:
    """Byte-at-a-time encoder written straight from reference/kermit.md section 3."""
    out = bytearray()
    i = 0
    specials = {c for c in (enc.qctl, enc.qbin, enc.rept) if c is not None}
    while i < len(data):
        b = data[i]
        run = 1
        while enc.rept is not None and i + run < len(data) and data[i + run] == b and run < 94:
            run += 1
        if run >= 3:
            assert enc.rept is not None
            out += bytes((enc.rept, run + 32))
            n = 1
        else:
            run = n = 1
        for _ in range(n):
            c = b
            if enc.qbin is not None and c & 0x80:
                out.append(enc.qbin)
                c &= 0x7F
            low = c & 0x7F
            if low < 32 or low == 127:
                out += bytes((enc.qctl, c ^ 64))
            elif low in specials:
                out += bytes((enc.qctl, c))
            else:
                out.append(c)
        i += run
    return bytes(out)


def test_gkermit_capture_without_8th_bit_prefixing() -> None:
    # The data field of the captured G-Kermit D packet (reference/kermit.md section 2).
    assert EIGHT_BIT_CLEAN.encode(GKERMIT_PAYLOAD) == (
        b"Hello, Kermit!#M#J#@#A#B#\xbf#\xfe ~4A #~##&#J"
    )


def test_printable_profile_exact_bytes() -> None:
    assert PRINTABLE.encode(GKERMIT_PAYLOAD) == b"Hello, Kermit!#M#J#@#A#B&#?&#~ ~4A #~###&#J"


@pytest.mark.parametrize(
    ("data", "wire"),
    [
        (b"A" * 20, b"~4A"),
        (b"AA", b"AA"),
        (b"AAA", b"~#A"),
        (b"A" * 94, b"~~A"),
        (b"A" * 95, b"~~AA"),
        (b"A" * 96, b"~~AAA"),
        (b"A" * 97, b"~~A~#A"),
        (b"#", b"##"),
        (b"&", b"#&"),
        (b"~", b"#~"),
        (b"\x7f", b"#?"),
        (b"\x80", b"&#@"),
        (b"\xa3", b"&##"),
        (b"\xff" * 3, b"~#&#?"),
        (b"\x00", b"#@"),
    ],
)
def test_tokens(data: bytes, wire: bytes) -> None:
    assert PRINTABLE.encode(data) == wire
    assert PRINTABLE.decode(wire) == data


def test_eight_bit_clean_prefixes_c1_and_ff_but_not_a0_to_fe() -> None:
    assert EIGHT_BIT_CLEAN.encode(b"\x80\x9f\xff\xa0\xc1") == b"#\xc0#\xdf#\xbf\xa0\xc1"
    # Bytes whose low 7 bits equal an active prefix are escaped (0xFE ~ '~').
    assert EIGHT_BIT_CLEAN.encode(b"\xfe\xa3") == b"#\xfe#\xa3"


@given(enc=encodings, data=payloads)
@example(enc=PRINTABLE, data=b"\xff" * 300)
@example(enc=PRINTABLE, data=b"#" * 400)
def test_round_trip_and_matches_reference(enc: Encoding, data: bytes) -> None:
    wire = enc.encode(data)
    assert wire == reference_encode(enc, data)
    assert enc.decode(wire) == data
    assert enc._decode_sequential(wire) == data


@given(data=payloads)
def test_printable_profile_output_is_printable(data: bytes) -> None:
    wire = PRINTABLE.encode(data)
    assert all(32 <= c <= 126 for c in wire)


@given(enc=encodings, data=payloads)
def test_no_profile_ever_emits_soh_or_cr(enc: Encoding, data: bytes) -> None:
    wire = enc.encode(data)
    assert 0x01 not in wire
    assert 0x0D not in wire


@given(enc=encodings, data=payloads, capacity=st.integers(MAX_TOKEN_LENGTH, 400))
def test_encode_prefix_fills_without_splitting_tokens(
    enc: Encoding, data: bytes, capacity: int
) -> None:
    field, used = enc.encode_prefix(data, capacity)
    assert len(field) <= capacity
    assert enc.decode(field) == data[:used]
    if data:
        assert used >= 1
    if used < len(data):
        # Full up to the last token: the next token would not have fitted.
        nxt, _ = enc.encode_prefix(data[used:], MAX_TOKEN_LENGTH)
        assert len(field) + len(nxt) > capacity or len(nxt) == 0 or field != b""


@given(
    enc=encodings,
    data=payloads,
    capacity=st.integers(MAX_TOKEN_LENGTH, 300),
    count=st.integers(1, 40),
)
def test_encode_fields_cuts_consecutive_fields(
    enc: Encoding, data: bytes, capacity: int, count: int
) -> None:
    fields = enc.encode_fields(data, capacity, count)
    assert len(fields) <= count
    total = sum(used for _, used in fields)
    assert b"".join(enc.decode(f) for f, _ in fields) == data[:total]
    assert all(len(f) <= capacity and used >= 1 for f, used in fields)
    if len(fields) < count:
        assert total == len(data)


def test_capacity_below_a_token_is_a_local_error() -> None:
    with pytest.raises(LocalProtocolError, match="capacity"):
        PRINTABLE.encode_prefix(b"x", MAX_TOKEN_LENGTH - 1)


@pytest.mark.parametrize(
    "field", [b"#", b"&", b"~", b"~#", b"AB&", b"~#&", b"~#&#", b"~ A", b"~\x7fA"]
)
def test_malformed_fields_raise_typed_errors(field: bytes) -> None:
    with pytest.raises(MalformedDataError) as info:
        PRINTABLE.decode(field)
    assert info.value.error_hint.startswith("Malformed data field")
    with pytest.raises(MalformedDataError):
        PRINTABLE._decode_sequential(field)


@given(st.binary(max_size=2000))
def test_decoding_arbitrary_bytes_either_works_or_raises_typed_error(field: bytes) -> None:
    for enc in (PRINTABLE, EIGHT_BIT_CLEAN):
        try:
            fast = enc.decode(field)
        except MalformedDataError:
            with pytest.raises(MalformedDataError):
                enc._decode_sequential(field)
        else:
            assert fast == enc._decode_sequential(field)


def test_vectorised_path_handles_long_prefix_chains_exactly() -> None:
    # 4000 '#' characters: 2000 literal '#', far past the fixed-point round limit.
    assert PRINTABLE.decode(b"#" * 4000) == b"#" * 2000
    assert PRINTABLE.decode(b"##" * 300 + b"#@" * 300) == b"#" * 300 + b"\x00" * 300


def test_decoder_accepts_what_real_peers_send() -> None:
    # Unprefixed controls (C-Kermit leaves TAB unprefixed) and raw 8-bit bytes.
    assert PRINTABLE.decode(b"a\tb") == b"a\tb"
    assert EIGHT_BIT_CLEAN.decode(b"\xe9t\xe9") == b"\xe9t\xe9"
    # Escaped non-control operands are literal (G-Kermit decode).
    assert PRINTABLE.decode(b"#a") == b"a"
    assert PRINTABLE.decode(b"#A") == b"\x01"


@pytest.mark.parametrize(
    "kwargs", [{"qctl": ord(" ")}, {"qbin": ord("#")}, {"rept": ord("A")}, {"qctl": 127}]
)
def test_illegal_prefixes_rejected(kwargs: dict[str, int]) -> None:
    with pytest.raises(LocalProtocolError):
        Encoding(**kwargs)
