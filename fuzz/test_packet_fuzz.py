"""Property fuzzing of the packet layer (``make fuzz`` runs it with the deep profile).

The same properties run in ``make test`` with the derandomized CI profile; here
hypothesis explores fresh inputs on every run.
"""

from __future__ import annotations

from collections.abc import Callable

from hypothesis import given
from hypothesis import strategies as st

from serialsocket import MalformedDataError
from serialsocket.packets import (
    EIGHT_BIT_CLEAN,
    PRINTABLE,
    XON_XOFF,
    BlockCheck,
    EscapeEncoding,
    Packet,
    PacketParser,
    PacketReceived,
    Radix91Encoding,
    build_packet,
    data_capacity,
)

DENSE = (EscapeEncoding(), EscapeEncoding(unsafe=XON_XOFF), Radix91Encoding())
"""The dense encodings two telelink ends negotiate (PROTOCOL.md section 10)."""


def _canonical(enc: EscapeEncoding | Radix91Encoding, data: bytes) -> None:
    """A dense decoder is strict: what it accepts is the encoding of what it
    returns, ``decode_fields`` agrees with ``decode``, and it raises nothing
    but MalformedDataError."""
    try:
        plain = enc.decode(data)
    except MalformedDataError:
        return
    assert enc.encode(plain) == data
    assert enc.decode_fields([data, data]) == plain + plain


def _outcome(fn: Callable[[bytes], bytes], data: bytes) -> bytes | str:
    """The decoded bytes, or the error type's name: both decoders must agree."""
    try:
        return fn(data)
    except MalformedDataError as exc:
        return type(exc).__name__


@given(
    st.lists(st.binary(max_size=300), max_size=20),
    st.integers(12, 9031),
    st.sampled_from(list(BlockCheck)),
)
def test_parser_survives_any_byte_stream(
    chunks: list[bytes], max_len: int, check: BlockCheck
) -> None:
    parser = PacketParser(max_length=max_len, check=check)
    for chunk in chunks:
        parser.receive_data(chunk)
        while (ev := parser.next_event()) is not None:
            if isinstance(ev, PacketReceived):
                # Anything accepted re-serialises to a packet the parser accepts again.
                again = PacketParser(max_length=max(max_len, ev.length))
                again.receive_data(build_packet(ev.packet, ev.check))
                assert isinstance(again.next_event(), PacketReceived)
                for enc in (PRINTABLE, EIGHT_BIT_CLEAN):
                    assert _outcome(enc.decode, ev.packet.data) == _outcome(
                        enc._decode_sequential, ev.packet.data
                    )
                for dense in DENSE:
                    _canonical(dense, ev.packet.data)
        assert parser.buffered <= max(max_len, len(chunk))


@given(st.binary(max_size=400), st.sampled_from(DENSE))
def test_dense_decoders_are_strict_on_any_field(field: bytes, enc: EscapeEncoding) -> None:
    _canonical(enc, field)


@given(
    st.binary(min_size=1, max_size=3000),
    st.sampled_from(DENSE),
    st.sampled_from([BlockCheck.CRC16, BlockCheck.CRC32]),
    st.integers(37, 1200),
    st.lists(st.tuples(st.integers(0, 1 << 16), st.integers(0, 255)), max_size=8),
    st.lists(st.integers(0, 1 << 16), max_size=3),
)
def test_damaged_and_truncated_dense_packets_are_counted_drops(
    payload: bytes,
    enc: EscapeEncoding,
    check: BlockCheck,
    max_len: int,
    hits: list[tuple[int, int]],
    cuts: list[int],
) -> None:
    """Dense data packets, bytes changed and packets cut short on the line: the
    parser rejects what the check catches (never an exception), a packet it
    accepts that was sent decodes, and anything else (a forgery the check let
    through) decodes or fails with MalformedDataError only."""
    fields = enc.encode_fields(payload, data_capacity(max_len, check), 1 << 20)
    packets = [
        build_packet(Packet(seq=i % 64, type="D", data=f), check) for i, (f, _) in enumerate(fields)
    ]
    wire = bytearray(b"".join(packets))
    for at, value in hits:
        wire[at % len(wire)] = value
    for at in sorted(cuts, reverse=True):
        at %= len(wire)
        del wire[at : at + 1 + at % 40]
    parser = PacketParser(max_length=max_len, check=check)
    parser.receive_data(bytes(wire))
    fields_seen = {f for f, _ in fields}
    while (ev := parser.next_event()) is not None:
        if isinstance(ev, PacketReceived):
            if ev.packet.data in fields_seen:
                assert enc.decode(ev.packet.data)
            else:  # a forgery the check let through: decoding fails cleanly or succeeds
                _canonical(enc, ev.packet.data)
