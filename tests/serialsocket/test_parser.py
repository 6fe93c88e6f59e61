"""The incremental parser: whole, byte at a time, trailing bytes, chunked, mutated."""

from __future__ import annotations

import random

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from serialsocket import LocalProtocolError
from serialsocket.packets import (
    PRINTABLE,
    BlockCheck,
    Packet,
    PacketParser,
    PacketReceived,
    PacketRejected,
    ParserEvent,
    RejectReason,
    build_packet,
    data_capacity,
)

from .strategies import chunked, payloads


def drain(parser: PacketParser) -> list[ParserEvent]:
    out = []
    while (ev := parser.next_event()) is not None:
        out.append(ev)
    return out


def feed_all(parser: PacketParser, *chunks: bytes) -> list[ParserEvent]:
    events: list[ParserEvent] = []
    for c in chunks:
        parser.receive_data(c)
        events += drain(parser)
    return events


def packets_of(events: list[ParserEvent]) -> list[Packet]:
    return [e.packet for e in events if isinstance(e, PacketReceived)]


def wire_for(
    payload: bytes, max_len: int = 128, check: BlockCheck = BlockCheck.CRC16
) -> tuple[list[Packet], bytes]:
    cap = data_capacity(max_len, check)
    pkts, view, seq = [], memoryview(payload), 0
    while True:
        field, used = PRINTABLE.encode_prefix(view, cap)
        pkts.append(Packet(seq=seq, type="D", data=field))
        view, seq = view[used:], (seq + 1) % 64
        if not view:
            break
    return pkts, b"".join(build_packet(p, check) for p in pkts)


ACK = b"\x01%#Y/R9\r"


def test_whole_one_byte_at_a_time_and_with_trailing_bytes() -> None:
    # h11's three ways: whole; byte by byte (nothing until complete); plus trailing data.
    p = PacketParser()
    assert packets_of(feed_all(p, ACK)) == [Packet(seq=3, type="Y")]
    p = PacketParser()
    for i, b in enumerate(ACK[:-1]):
        p.receive_data(bytes([b]))
        if i < len(ACK) - 2:
            assert p.next_event() is None
    assert packets_of(drain(p)) == [Packet(seq=3, type="Y")]
    p = PacketParser()
    events = feed_all(p, ACK + b"\x01%")
    assert packets_of(events) == [Packet(seq=3, type="Y")]
    assert p.buffered == 2


@given(payload=payloads, data=st.data(), max_len=st.sampled_from([20, 96, 128, 500, 2048]))
def test_chunking_never_changes_the_result(
    payload: bytes, data: st.DataObject, max_len: int
) -> None:
    pkts, wire = wire_for(payload, max_len)
    p = PacketParser(max_length=max_len)
    events = feed_all(p, *data.draw(chunked(wire)))
    assert packets_of(events) == pkts
    assert all(isinstance(e, PacketReceived) for e in events)
    assert b"".join(PRINTABLE.decode(pk.data) for pk in pkts) == payload
    assert p.buffered == 0


@given(
    payload=payloads,
    garbage=st.lists(st.binary(min_size=1, max_size=40).filter(lambda g: 1 not in g), max_size=5),
    data=st.data(),
)
def test_garbage_between_packets_is_reported_and_skipped(
    payload: bytes, garbage: list[bytes], data: st.DataObject
) -> None:
    pkts, _ = wire_for(payload)
    pieces: list[bytes] = []
    for i, pk in enumerate(pkts):
        if i < len(garbage):
            pieces.append(garbage[i])
        pieces.append(build_packet(pk))
    wire = b"".join(pieces)
    events = feed_all(PacketParser(), *data.draw(chunked(wire)))
    assert packets_of(events) == pkts
    rejected = [e for e in events if isinstance(e, PacketRejected)]
    assert all(e.reason is RejectReason.GARBAGE for e in rejected)


@given(payload=st.binary(min_size=1, max_size=300), data=st.data())
@example(payload=b"A", data=None)
def test_a_flipped_bit_anywhere_is_always_detected(
    payload: bytes, data: st.DataObject | None
) -> None:
    pkts, _ = wire_for(payload)
    wire = build_packet(pkts[0])
    if data is None:
        pos, bit = 1, 0
    else:
        pos = data.draw(st.integers(0, len(wire) - 2))  # not the EOL: it is not checked
        bit = data.draw(st.integers(0, 7))
    damaged = bytearray(wire)
    damaged[pos] ^= 1 << bit
    p = PacketParser()
    events = feed_all(p, bytes(damaged), ACK)
    # The damaged packet never comes out; the following good packet always does.
    assert packets_of(events) == [Packet(seq=3, type="Y")]


def test_crc_detects_every_single_and_double_bit_error_in_a_128_byte_packet() -> None:
    rng = random.Random(7)
    pkts, _ = wire_for(rng.randbytes(200))
    wire = build_packet(pkts[0])
    assert 128 - 2 <= len(wire) - 1 <= 128  # filled up to the last whole token
    nbits = 8 * (len(wire) - 1)
    for i in range(nbits):
        damaged = bytearray(wire)
        damaged[i // 8] ^= 1 << (i % 8)
        assert not packets_of(feed_all(PacketParser(), bytes(damaged))), i
    for _ in range(3000):
        i, j = rng.sample(range(nbits), 2)
        damaged = bytearray(wire)
        damaged[i // 8] ^= 1 << (i % 8)
        damaged[j // 8] ^= 1 << (j % 8)
        assert not packets_of(feed_all(PacketParser(), bytes(damaged)))


@given(payload=payloads, data=st.data())
def test_mutations_never_crash_and_good_packets_survive(
    payload: bytes, data: st.DataObject
) -> None:
    pkts, _ = wire_for(payload)
    wires = [bytearray(build_packet(pk)) for pk in pkts]
    damaged_idx = set()
    for _ in range(data.draw(st.integers(0, 4))):
        k = data.draw(st.integers(0, len(wires) - 1))
        op = data.draw(st.sampled_from(["flip", "drop", "insert", "truncate"]))
        w = wires[k]
        if not w:
            continue
        pos = data.draw(st.integers(0, len(w) - 1))
        if op == "flip":
            w[pos] ^= 1 << data.draw(st.integers(0, 7))
        elif op == "drop":
            del w[pos]
        elif op == "insert":
            w.insert(pos, data.draw(st.integers(0, 255)))
        else:
            del w[pos:]
        damaged_idx.add(k)
    events = feed_all(PacketParser(), *data.draw(chunked(b"".join(wires))), ACK)
    got = packets_of(events)
    intact = [pk for i, pk in enumerate(pkts) if i not in damaged_idx]
    # Every undamaged packet comes out, in order; the trailing ACK always does.
    it = iter(got)
    assert all(any(g == want for g in it) for want in intact)
    assert got[-1] == Packet(seq=3, type="Y")


def test_truncated_packet_is_rejected_as_soon_as_the_next_mark_arrives() -> None:
    pkts, _ = wire_for(random.Random(1).randbytes(100))
    wire = build_packet(pkts[0])
    assert len(wire) > 60
    p = PacketParser()
    p.receive_data(wire[:50])
    assert p.next_event() is None
    p.receive_data(ACK[:1])
    ev = p.next_event()
    assert isinstance(ev, PacketRejected)
    assert ev.reason is RejectReason.TRUNCATED
    assert ev.length == 50
    assert ev.seq == 0
    assert ev.type == "D"
    p.receive_data(ACK[1:])
    assert packets_of(drain(p)) == [Packet(seq=3, type="Y")]


def test_too_long_bad_length_and_bad_header() -> None:
    pkts, _ = wire_for(random.Random(2).randbytes(500), max_len=500)
    p = PacketParser(max_length=128)
    events = feed_all(p, build_packet(pkts[0]), ACK)
    assert [type(e) for e in events] == [PacketRejected, PacketReceived]
    assert isinstance(events[0], PacketRejected)
    assert events[0].reason is RejectReason.TOO_LONG
    events = feed_all(PacketParser(), b"\x01\x7f#Y/R9\r" + b"\x01!#Y" + ACK)
    reasons = [e.reason for e in events if isinstance(e, PacketRejected)]
    assert reasons == [RejectReason.BAD_LENGTH, RejectReason.BAD_LENGTH]
    assert packets_of(events) == [Packet(seq=3, type="Y")]
    ext = bytearray(build_packet(pkts[0]))
    ext[6] ^= 1  # HCHECK
    events = feed_all(PacketParser(max_length=600), bytes(ext), ACK)
    assert [e.reason for e in events if isinstance(e, PacketRejected)] == [RejectReason.BAD_HEADER]
    assert len(packets_of(events)) == 1


def test_nak_check_length_is_inferred_from_len() -> None:
    nak1 = build_packet(Packet(seq=5, type="N"), BlockCheck.SUM6)
    p = PacketParser(check=BlockCheck.CRC16)
    events = feed_all(p, nak1)
    assert isinstance(events[0], PacketReceived)
    assert events[0].check is BlockCheck.SUM6


def test_error_packet_with_type_1_check_accepted_while_crc_in_force() -> None:
    e = build_packet(Packet(seq=2, type="E", data=b"Too many retries"), BlockCheck.SUM6)
    events = feed_all(PacketParser(check=BlockCheck.CRC16), e)
    assert packets_of(events) == [Packet(seq=2, type="E", data=b"Too many retries")]


def test_init_packets_use_init_check() -> None:
    s = b"\x019 S~' @-#Y3~*!J*0+++B\"U1AH\r"
    assert len(packets_of(feed_all(PacketParser(), s))) == 1
    # With FORCE-3 agreed, a type-1 S packet no longer verifies.
    assert packets_of(feed_all(PacketParser(init_check=BlockCheck.CRC16), s)) == []


def test_buffer_is_bounded_by_max_length() -> None:
    p = PacketParser(max_length=128)
    rng = random.Random(3)
    high = 0
    for _ in range(2000):
        chunk = bytes(rng.choice([1, 32, 35, 126, rng.randrange(256)]) for _ in range(64))
        p.receive_data(chunk)
        drain(p)
        high = max(high, p.buffered)
    assert high <= 128
    stats = p.statistics()
    assert stats.garbage_bytes > 0
    assert stats.resyncs > 0


def test_filler_is_silent_and_counted() -> None:
    p = PacketParser()
    events = feed_all(p, b"\r\n\x00\x00" + ACK + b"\n")
    assert packets_of(events) == [Packet(seq=3, type="Y")]
    assert len(events) == 1
    assert p.statistics().filler_bytes == 6


def test_max_length_validation() -> None:
    with pytest.raises(LocalProtocolError):
        PacketParser(max_length=5)
    p = PacketParser()
    with pytest.raises(LocalProtocolError):
        p.max_length = 10_000


def test_reset_drops_partial_packet() -> None:
    p = PacketParser()
    p.receive_data(ACK[:4])
    p.reset()
    assert p.buffered == 0
    assert packets_of(feed_all(p, ACK)) == [Packet(seq=3, type="Y")]
