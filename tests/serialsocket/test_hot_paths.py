"""The per-packet fast paths against the plain ones they stand for.

Batched decoding: ``Receiver.take_fields`` defers the fields an ``Encoding`` can vouch for
(``Encoding.plain_whole``) and ``Receiver.flush`` decodes them together at
the end of a read; the window each ACK advertises, the classification of
every packet and the bytes delivered must be exactly those of the reference
path, which decodes each arrival on the spot (any codec that is not exactly
``Encoding`` takes it: a subclass here).  Packets built without a
``Packet`` (``_crc16_packet``) equal ``build_packet``'s; a ``RateMark``
built through its slots equals the dataclass's own.
"""

from __future__ import annotations

import dataclasses

import pytest
from hypothesis import given
from hypothesis import strategies as st

from serialsocket import Endpoint, EndpointConfig, MalformedDataError
from serialsocket._encoding import _reference_decode
from serialsocket._packet import _crc16_packet
from serialsocket._rate import RateEstimator, RateMark
from serialsocket._receiver import Receiver
from serialsocket._wire import CR
from serialsocket.packets import PRINTABLE, BlockCheck, Encoding, Packet, build_packet

from .strategies import encodings, payloads
from .test_codec_fast import outcome, prefix_soup, reference_build


class _AtOnce(Encoding):
    """The same profile, decoded at once (the receiver defers only ``Encoding``)."""

    __slots__ = ()


def _no_runs(data: bytes) -> bool:
    return not any(data[i] == data[i + 1] == data[i + 2] for i in range(len(data) - 2))


@given(enc=encodings, data=st.data())
def test_plain_whole_is_sound(enc: Encoding, data: st.DataObject) -> None:
    # Whatever it accepts decodes without error to at most its own length.
    field = data.draw(prefix_soup(enc))
    if enc.plain_whole(field):
        decoded = outcome(_reference_decode, enc, field)
        assert isinstance(decoded, bytes)
        assert len(decoded) <= len(field)


@pytest.mark.parametrize(
    ("field", "whole"),
    [
        (b"", True),
        (b"ab", True),
        (b"##", True),  # '#'
        (b"&##", True),  # 0xA3
        (b"#&", True),  # '&'
        (b"&#&", True),  # 0xA6
        (b"#~", True),  # '~' quoted: not a repeat
        (b"&#~", True),  # 0xFE
        (b"x&#~y", True),
        (b"##~", False),  # a repeat prefix after the token '##'
        (b"~", False),
        (b"~#a", False),  # a real repeat token
        (b"#", False),  # dangling
        (b"&#", False),
        (b"a###", False),
        (b"a" + b"#" * 10, False),  # too long a chain to read (an even one is whole)
    ],
)
def test_plain_whole_on_the_chains(field: bytes, whole: bool) -> None:
    assert PRINTABLE.plain_whole(field) is whole


@given(enc=encodings, data=payloads, capacity=st.integers(5, 200))
def test_plain_whole_takes_every_field_without_a_run(
    enc: Encoding, data: bytes, capacity: int
) -> None:
    # The fast path must be the common one: an encoder's field with no repeat
    # token is always accepted (binary data: a quoted REPT is not a repeat).
    for field, _ in enc.encode_fields(data, capacity, 1000):
        if enc.rept is None or _no_runs(enc.decode(field)):
            assert enc.plain_whole(field)


@given(
    enc=encodings,
    data=st.data(),
    buffer=st.integers(0, 1200),
    window=st.integers(1, 31),
    capacity=st.integers(5, 200),
)
def test_deferred_decoding_matches_decoding_at_once(
    enc: Encoding, data: st.DataObject, buffer: int, window: int, capacity: int
) -> None:
    at_once = _AtOnce(qctl=enc.qctl, qbin=enc.qbin, rept=enc.rept)
    batched = Receiver(receive_buffer=buffer, window=window, capacity=capacity)
    reference = Receiver(receive_buffer=buffer, window=window, capacity=capacity)
    seq = 1
    for _ in range(data.draw(st.integers(1, 6), label="reads")):
        payload = data.draw(payloads, label="payload")
        fields = [f for f, _ in enc.encode_fields(payload, capacity, 1000)]
        if data.draw(st.booleans(), label="a malformed field"):
            fields.insert(data.draw(st.integers(0, len(fields))), b"#")
        for field in fields:
            # A packet lost now and then: later ones wait in the reorder buffer.
            skip = data.draw(st.integers(0, 9), label="gap") == 0
            # (Asking for the window may decode what waits: not after every packet.)
            ask = data.draw(st.booleans(), label="ask for the window")
            got = []
            for receiver, codec in ((batched, enc), (reference, at_once)):
                arrival = receiver.on_packet((seq + skip) % 64, field, False, 0.0, 1.0)
                try:
                    receiver.take_fields(arrival, codec)
                    failed = False
                except MalformedDataError:
                    failed = True
                got.append(
                    (
                        arrival.classification,
                        arrival.ack,
                        arrival.nak,
                        failed,
                        receiver.window_to_advertise() if ask else None,
                        receiver.expected,
                    )
                )
            assert got[0] == got[1]
            if got[0][3]:
                return  # both refused the same field
            if got[0][0] == "new" and not skip:
                seq = batched.expected
        batched.flush()  # the end of a read
        assert batched.pending == []
        assert batched.pending_chars == 0
        assert batched.readable == reference.readable
        assert batched.delivered_total == reference.delivered_total
        n = data.draw(st.integers(0, len(reference.readable)), label="the application reads")
        assert batched.read(n) == reference.read(n)


@given(
    seq=st.integers(0, 63),
    ptype=st.sampled_from(["D", "Y", "N", "Z"]),
    field=st.binary(max_size=600).map(PRINTABLE.encode),
)
def test_crc16_packet_matches_the_reference_build(seq: int, ptype: str, field: bytes) -> None:
    # (build_packet with CR and no padding takes _crc16_packet itself: the
    # reference is the one-field-at-a-time definition.)
    packet = Packet(seq=seq, type=ptype, data=field)
    expected = reference_build(packet, BlockCheck.CRC16, CR, b"")
    assert _crc16_packet(seq, ord(ptype), field) == expected
    assert build_packet(packet) == expected


def test_rate_mark_built_through_its_slots_has_every_field() -> None:
    rate = RateEstimator(hint=None)
    assert rate.mark(1.0) is None  # before the connection
    rate.hand(100)
    rate.start(2.0, base_rtt=0.5)
    rate.hand(40)
    mark = rate.mark(3.0)
    assert mark == RateMark(
        handed_end=140,
        point_time=2.0,
        point_handed=100,
        point_queued=False,
        point_sent=1.5,
        sent_at=3.0,
        epoch=0,
    )
    # A field added to RateMark must be set by mark() too (an unset slot raises).
    for f in dataclasses.fields(RateMark):
        getattr(mark, f.name)


def test_input_held_tells_a_partial_packet_from_a_whole_one() -> None:
    # The driver wakes nobody when a read only extended a packet still
    # arriving: input_held grew by every byte fed.
    ep = Endpoint(EndpointConfig())
    ep.listen()
    wire = build_packet(Packet(seq=0, type="D", data=b"ab"))
    ep.receive_data(wire[:4], 0.0)
    assert ep.input_held == 4
    ep.receive_data(wire[4:-2], 0.0)  # all but the last check character and the CR
    assert ep.input_held == len(wire) - 2
    ep.receive_data(wire[-2:], 0.0)  # the packet is whole, the CR skipped as filler
    assert ep.input_held == 0
    assert ep.statistics().packets_received == 1
