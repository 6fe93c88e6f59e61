"""The expedited lane (PROTOCOL.md section 11): the offer, overtaking queued
data, exactly-once delivery under loss, fragmentation, bounds and bad input."""

from __future__ import annotations

import random

import pytest
import trio
from hypothesis import given, settings
from hypothesis import strategies as st

from serialsocket import Endpoint, EndpointConfig, LocalProtocolError, State
from serialsocket._expedited import EXPEDITED_INBOX, EXPEDITED_QUEUE, EXPEDITED_WINDOW
from serialsocket._params import FEATURE_EXPEDITED, InitParameters
from serialsocket.packets import BlockCheck, Packet, PacketParser, PacketReceived, build_packet

from .simlink import MOON_HINTS, SimLink, connected_pair

SLOW = MOON_HINTS


def _collect(ep: Endpoint, into: list[tuple[float, bytes]], link: SimLink) -> None:
    while (m := ep.read_expedited()) is not None:
        into.append((link.now, m))


def test_both_defaults_agree_to_the_lane() -> None:
    a, b, _ = connected_pair()
    assert a.expedited
    assert b.expedited
    assert a.statistics().expedited


@pytest.mark.parametrize("off", ["connector", "listener"])
def test_either_side_off_means_no_lane_and_sending_says_so(off: str) -> None:
    no = EndpointConfig(one_way_delay=1.3, line_rate=2400, expedited=False)
    a, b, link = connected_pair(
        no if off == "connector" else SLOW, no if off == "listener" else SLOW
    )
    assert not a.expedited
    assert not b.expedited
    with pytest.raises(LocalProtocolError, match="expedited"):
        a.send_expedited(b"stop", link.now)


def test_the_offer_is_bit_16_and_off_keeps_the_classic_init() -> None:
    on = InitParameters.decode(Endpoint(EndpointConfig(long_window=None))._mine.encode())
    assert on.features == FEATURE_EXPEDITED
    classic = EndpointConfig(long_window=None, expedited=False)
    assert len(Endpoint(classic)._mine.encode()) == 26
    assert InitParameters.decode(Endpoint(classic)._mine.encode()).features is None


def test_a_message_overtakes_a_round_trip_of_queued_data() -> None:
    a, b, link = connected_pair()
    data = random.Random(1).randbytes(4000)
    sent = a.send(data, link.now)
    link.run_for(3.0)
    sent_at = link.now
    a.send_expedited(b"EMERGENCY STOP", link.now)
    got: list[tuple[float, bytes]] = []
    stream = bytearray()

    def arrived() -> bool:
        _collect(b, got, link)
        stream.extend(b.read(None, link.now))
        return bool(got)

    link.run_until(arrived)
    assert got[0][1] == b"EMERGENCY STOP"
    # One way, plus what the UART held (the pacer keeps that short), plus
    # the message's own line time: never the queued data's 17 s.
    assert got[0][0] - sent_at < 1.3 + 2 * 129 * 10 / 2400
    assert len(stream) < len(data) / 2  # the stream was far from done

    def rest() -> bool:
        nonlocal sent
        sent += a.send(data[sent:], link.now)
        stream.extend(b.read(None, link.now))
        return len(stream) == len(data)

    link.run_until(rest)
    assert bytes(stream) == data  # and the stream itself is untouched


def _dropper(kind: str, every: int) -> object:
    count = {"n": 0}

    def f(direction: str, pkt: bytes, now: float) -> list[bytes]:
        if pkt[3:4] == kind.encode():
            count["n"] += 1
            if count["n"] % every == 1:
                return []
        return [pkt]

    return f


@pytest.mark.parametrize(("kind", "every"), [("U", 2), ("V", 2), ("U", 3), ("V", 3)])
def test_lost_fragments_and_lost_acks_deliver_each_message_once_in_order(
    kind: str, every: int
) -> None:
    rng = random.Random(every)
    a, b, link = connected_pair(filters=[_dropper(kind, every)])
    messages = [rng.randbytes(rng.randrange(1, 300)) for _ in range(12)]
    for m in messages:
        a.send_expedited(m, link.now)
        link.run_for(0.05)
    got: list[tuple[float, bytes]] = []

    def done() -> bool:
        _collect(b, got, link)
        return len(got) >= len(messages) and a.expedited_settled

    link.run_until(done, limit=600)
    link.run_for(30.0)  # resends of lost ACKs arrive as duplicates: never delivered again
    _collect(b, got, link)
    assert [m for _, m in got] == messages


def test_a_lost_ack_brings_a_duplicate_that_is_acknowledged_not_delivered() -> None:
    a, b, link = connected_pair(filters=[_dropper("V", 1000)])  # only the first V is lost
    a.send_expedited(b"once", link.now)
    got: list[tuple[float, bytes]] = []
    link.run_until(lambda: _collect(b, got, link) or a.expedited_settled, limit=600)
    link.run_for(30.0)
    _collect(b, got, link)
    assert [m for _, m in got] == [b"once"]
    assert b.statistics().duplicates_received == 1
    assert a.statistics().retransmissions == 1


def test_a_long_message_is_cut_into_fragments_and_rejoined() -> None:
    a, b, link = connected_pair()
    message = random.Random(7).randbytes(1024)
    a.send_expedited(message, link.now)
    got: list[tuple[float, bytes]] = []
    link.run_until(lambda: _collect(b, got, link) or bool(got))
    assert got[0][1] == message
    assert a.statistics().packets_sent > 10


def test_limits_are_typed_errors() -> None:
    a, _b, link = connected_pair(
        EndpointConfig(one_way_delay=1.3, line_rate=2400, max_packet_length=40),
        EndpointConfig(one_way_delay=1.3, line_rate=2400, max_packet_length=40),
    )
    with pytest.raises(ValueError, match=r"1\.\.1024"):
        a.send_expedited(b"", link.now)
    with pytest.raises(ValueError, match=r"1\.\.1024"):
        a.send_expedited(bytes(1025), link.now)
    with pytest.raises(ValueError, match="packets"):
        a.send_expedited(random.Random(2).randbytes(1000), link.now)  # > 31 short packets
    a.send_expedited(random.Random(3).randbytes(216), link.now)  # always fits


def test_a_sender_that_is_never_acknowledged_is_bounded() -> None:
    a, _, link = connected_pair(filters=[lambda d, p, t: [] if p[3:4] == b"V" else [p]])
    big = bytes(range(256)) * 3
    accepted = 0
    with pytest.raises(LocalProtocolError, match="wait"):  # noqa: PT012 (the loop is the point)
        for _ in range(EXPEDITED_WINDOW + EXPEDITED_QUEUE + 1):
            a.send_expedited(big, link.now)
            accepted += 1
    assert accepted >= EXPEDITED_QUEUE


def test_an_unread_inbox_holds_back_new_fragments_and_loses_nothing() -> None:
    a, b, link = connected_pair()
    messages = [bytes([i]) * 10 for i in range(EXPEDITED_INBOX + 4)]
    for m in messages[:EXPEDITED_QUEUE]:
        a.send_expedited(m, link.now)
    link.run_for(20.0)
    for m in messages[EXPEDITED_QUEUE:]:
        a.send_expedited(m, link.now)
    link.run_for(20.0)
    assert b.expedited_readable == EXPEDITED_INBOX
    assert b.statistics().expedited_refused > 0
    got: list[tuple[float, bytes]] = []

    def done() -> bool:
        _collect(b, got, link)
        return len(got) == len(messages)

    link.run_until(done, limit=600)
    assert [m for _, m in got] == messages


def test_fragments_that_disagree_on_their_count_abort_the_connection() -> None:
    a, b, link = connected_pair()
    check = a.parameters.check if a.parameters else BlockCheck.CRC16
    # Fragment 1 says two more follow, fragment 2 says none do.
    for seq, more in ((1, 2), (2, 0)):
        b.receive_data(
            build_packet(Packet(seq=seq, type="U", data=bytes((32 + more,)) + b"x"), check),
            link.now,
        )
    b.receive_data(
        build_packet(Packet(seq=3, type="U", data=bytes((32 + 0,)) + b"y"), check), link.now
    )
    assert b.state is State.FAILED
    wire = b.data_to_send(link.now)
    assert b"Malformed expedited message" in wire


def test_a_fragment_count_out_of_range_is_ignored() -> None:
    a, b, link = connected_pair()
    check = a.parameters.check if a.parameters else BlockCheck.CRC16
    before = b.statistics().ignored_packets
    b.receive_data(build_packet(Packet(seq=1, type="U", data=b"~x"), check), link.now)
    assert b.statistics().ignored_packets == before + 1
    assert b.state is State.ESTABLISHED
    assert b.read_expedited() is None


def test_without_the_lane_a_U_packet_is_just_an_unknown_type() -> None:
    no = EndpointConfig(one_way_delay=1.3, line_rate=2400, expedited=False)
    _a, b, link = connected_pair(no, no)
    b.receive_data(build_packet(Packet(seq=1, type="U", data=b" x"), BlockCheck.CRC16), link.now)
    assert b.read_expedited() is None
    assert b.statistics().ignored_packets == 1


def test_a_graceful_close_waits_for_the_lane() -> None:
    a, b, link = connected_pair(
        filters=[_dropper("V", 1)]
    )  # the first ACK is lost: a resend is needed
    a.send_expedited(b"last words", link.now)
    a.close(link.now)
    b.close(link.now)
    link.run_until(lambda: a.state is State.LINGER or a.state is State.CLOSED, limit=600)
    assert a.expedited_settled
    assert a.data_settled


def test_the_lane_packets_parse_as_ordinary_kermit_packets() -> None:
    a, _, link = connected_pair()
    a.send_expedited(b"hi", link.now)
    parser = PacketParser(max_length=128, check=BlockCheck.CRC16)
    parser.receive_data(a.data_to_send(link.now))
    event = parser.next_event()
    assert isinstance(event, PacketReceived)
    pkt = event.packet
    assert pkt.type == "U"
    assert pkt.seq == 1
    assert pkt.data[:1] == b" "


def test_the_socket_api_over_a_simulated_line() -> None:
    from linksim import serial_socket_pair
    from linksim.link import DirectionConfig, LinkConfig

    line = LinkConfig.symmetric(DirectionConfig(rate=2400, delay=1.3))

    async def main() -> None:
        with trio.fail_after(600):
            async with serial_socket_pair(line) as (client, server):
                assert client.expedited
                assert server.expedited
                await client.send_all(bytes(3000))
                await client.send_expedited(b"stop")
                t0 = trio.current_time()
                assert await server.receive_expedited() == b"stop"
                assert trio.current_time() - t0 < 3.0
                got = 0
                while got < 3000:
                    got += len(await server.receive_some())

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))


@settings(max_examples=25, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**32 - 1),
    loss=st.sampled_from([0.0, 0.05, 0.2]),
    sizes=st.lists(st.integers(1, 400), min_size=1, max_size=10),
)
def test_property_every_message_once_in_order_and_the_stream_intact(
    seed: int, loss: float, sizes: list[int]
) -> None:
    rng = random.Random(seed)

    def lossy(direction: str, pkt: bytes, now: float) -> list[bytes]:
        r = rng.random()
        if r < loss:
            return []
        if r < loss * 1.5:
            return [pkt, pkt]  # a duplicate as a resend would bring it
        return [pkt]

    a, b, link = connected_pair(
        EndpointConfig(one_way_delay=0.2, line_rate=9600),
        EndpointConfig(one_way_delay=0.2, line_rate=9600),
        delay=0.2,
        rate=9600,
        filters=[lossy],
    )
    messages = [rng.randbytes(n) for n in sizes]
    data = rng.randbytes(3000)
    sent = a.send(data, link.now)
    got: list[tuple[float, bytes]] = []
    stream = bytearray()
    pending = list(messages)

    def done() -> bool:
        nonlocal sent
        while pending:
            try:
                a.send_expedited(pending[0], link.now)
            except LocalProtocolError:
                break  # the lane is full: wait for acknowledgements
            pending.pop(0)
        if sent < len(data):
            sent += a.send(data[sent:], link.now)
        _collect(b, got, link)
        stream.extend(b.read(None, link.now))
        return not pending and len(got) == len(messages) and len(stream) == len(data)

    link.run_until(done, limit=3600)
    link.run_for(20.0)
    _collect(b, got, link)
    assert [m for _, m in got] == messages
    assert bytes(stream) == data
