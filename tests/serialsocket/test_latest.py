"""The latest-value lane (PROTOCOL.md section 12): the offer, values that
supersede each other, no repair of a superseded loss, the newest value
carried reliably, bounds and bad input."""

from __future__ import annotations

import random
import struct

import pytest
import trio
import trio.testing
from hypothesis import given, settings
from hypothesis import strategies as st

from serialsocket import Endpoint, EndpointConfig, LocalProtocolError, State
from serialsocket._latest import LATEST_MODULUS, LATEST_SPAN, LatestReceiver, LatestSender
from serialsocket._params import LANE_LATEST, InitParameters, negotiate
from serialsocket.packets import BlockCheck, Packet, build_packet

from .simlink import MOON_HINTS, SimLink, connected_pair

SLOW = MOON_HINTS


def _value(n: int) -> bytes:
    """A 56-byte value (a teleoperation sample's size) numbered ``n``."""
    return struct.pack("!Q", n) + bytes(48)


def _number(value: bytes) -> int:
    return int(struct.unpack_from("!Q", value)[0])


def _dropper(kind: str, which: set[int]):  # type: ignore[no-untyped-def]
    """Drop the packets of type ``kind`` whose 1-based count is in ``which``."""
    seen = 0

    def f(direction: str, pkt: bytes, now: float) -> list[bytes]:
        nonlocal seen
        if pkt[3:4] == kind.encode():
            seen += 1
            if seen in which:
                return []
        return [pkt]

    return f


def _stream_values(
    a: Endpoint, b: Endpoint, link: SimLink, count: int, every: float = 0.01
) -> list[tuple[float, int]]:
    """Offer values 1..count at ``every`` seconds (an operator sampling at
    100 Hz), then run until the last arrived; returns (arrival, number)."""
    got: list[tuple[float, int]] = []
    offered_at: dict[int, float] = {}

    def collect() -> None:
        while (v := b.read_latest()) is not None:
            got.append((link.now, _number(v)))

    for n in range(1, count + 1):
        offered_at[n] = link.now
        a.send_latest(_value(n), link.now)
        link.run_for(every)
        collect()

    def done() -> bool:
        collect()
        return bool(got) and got[-1][1] == count and a.latest_settled

    link.run_until(done, limit=600)
    return [(t - offered_at[n], n) for t, n in got]


def test_both_defaults_agree_to_the_lane() -> None:
    a, b, _ = connected_pair()
    assert a.latest
    assert b.latest
    assert a.statistics().latest


@pytest.mark.parametrize(
    ("off", "setting"),
    [("connector", "latest"), ("listener", "latest"), ("connector", "expedited")],
)
def test_either_side_off_means_no_lane_and_sending_says_so(off: str, setting: str) -> None:
    no = EndpointConfig(one_way_delay=1.3, line_rate=2400, **{setting: False})  # type: ignore[arg-type]
    a, b, link = connected_pair(
        no if off == "connector" else SLOW, no if off == "listener" else SLOW
    )
    assert not a.latest
    assert not b.latest
    with pytest.raises(LocalProtocolError, match="latest-value lane"):
        a.send_latest(b"x", link.now)


def test_the_offer_is_one_xlanes_character_and_off_keeps_todays_init() -> None:
    # (early_data=0: early data's bit is the other XLANES offer, PROTOCOL.md 13.)
    on = Endpoint(EndpointConfig(long_window=None, early_data=0))._mine.encode()
    off = Endpoint(EndpointConfig(long_window=None, latest=False, early_data=0))._mine.encode()
    assert on == off + b"!"  # tochar(1): XLANES after XCAPAS
    assert InitParameters.decode(on).lanes == LANE_LATEST
    assert InitParameters.decode(off).lanes is None
    # With long sequence numbers XLANES follows XWINDO's three characters.
    long_on = Endpoint(EndpointConfig())._mine.encode()
    assert (InitParameters.decode(long_on).lanes or 0) & LANE_LATEST
    assert InitParameters.decode(long_on).long_window is not None


def test_an_older_telelink_that_sends_no_xlanes_gets_no_lane() -> None:
    mine = Endpoint(EndpointConfig(long_window=None))._mine
    older = InitParameters.decode(
        Endpoint(EndpointConfig(long_window=None, latest=False, early_data=0))._mine.encode()
    )
    assert not negotiate(mine, older).latest
    assert mine.answer(older, None).lanes is None  # the answer carries no XLANES either
    assert negotiate(mine, mine).latest


def test_a_bad_xlanes_character_is_a_bad_init() -> None:
    field = Endpoint(EndpointConfig(long_window=None))._mine.encode()
    from serialsocket import RemoteProtocolError

    with pytest.raises(RemoteProtocolError, match="XLANES"):
        InitParameters.decode(field[:-1] + b"\x7f")


def _longest_l(lengths: list[int]):  # type: ignore[no-untyped-def]
    """A filter that notes the length of every ``L`` packet."""

    def f(direction: str, pkt: bytes, now: float) -> list[bytes]:
        if pkt[3:4] == b"L":
            lengths.append(len(pkt))
        return [pkt]

    return f


def _packet_time(lengths: list[int]) -> float:
    return max(lengths) * 10 / 2400


def test_values_at_100_hz_arrive_in_order_newest_last_at_the_line_s_pace() -> None:
    lengths: list[int] = []
    a, b, link = connected_pair(filters=[_longest_l(lengths)])
    ages = _stream_values(a, b, link, 600)  # 6 s of sampling
    numbers = [n for _, n in ages]
    assert numbers == sorted(set(numbers))  # in order, each once
    assert numbers[-1] == 600
    # The line carries a value every packet time: the others were coalesced
    # before they reached it; nothing was lost, so nothing was resent.
    stats = a.statistics()
    assert stats.latest_coalesced + stats.latest_sent == 600
    assert stats.latest_resent == 0
    assert len(numbers) == stats.latest_sent < 600 / 4
    # A value waits for at most the packet on the wire and its own: it never
    # queues behind older values.
    assert max(age for age, _ in ages) <= 1.3 + 2 * _packet_time(lengths) + 0.02


def test_a_lost_value_holds_up_nothing_and_is_never_resent() -> None:
    lengths: list[int] = []
    a, b, link = connected_pair(filters=[_longest_l(lengths), _dropper("L", {3, 4})])
    ages = _stream_values(a, b, link, 400)
    numbers = [n for _, n in ages]
    assert numbers == sorted(set(numbers))
    assert a.statistics().latest_resent == 0  # newer values replaced them on the line
    assert len(numbers) == a.statistics().latest_sent - 2
    assert max(age for age, _ in ages) <= 1.3 + 2 * _packet_time(lengths) + 0.02


def test_the_newest_value_is_resent_until_acknowledged() -> None:
    a, b, link = connected_pair(filters=[_dropper("L", {1, 2})])
    a.send_latest(_value(7), link.now)
    link.run_until(lambda: b.latest_readable and a.latest_settled, limit=600)
    assert b.read_latest() == _value(7)
    assert a.statistics().latest_resent == 2


def test_a_lost_acknowledgement_brings_a_copy_that_is_not_delivered_again() -> None:
    a, b, link = connected_pair(filters=[_dropper("M", {1})])
    a.send_latest(_value(1), link.now)
    link.run_until(lambda: a.latest_settled, limit=600)
    assert b.read_latest() == _value(1)
    link.run_for(30.0)
    assert b.read_latest() is None
    assert b.statistics().latest_received == 1
    assert b.statistics().duplicates_received == 1


def test_an_unread_value_is_replaced_by_a_newer_one() -> None:
    a, b, link = connected_pair()
    for n in (1, 2, 3):
        a.send_latest(_value(n), link.now)
        link.run_until(lambda: a.latest_settled, limit=600)
    assert b.read_latest() == _value(3)
    assert b.read_latest() is None
    assert b.statistics().latest_superseded == 2


def test_the_stream_goes_first_and_the_value_waits_for_next_to_nothing() -> None:
    order: list[tuple[float, bytes]] = []

    def note(direction: str, pkt: bytes, now: float) -> list[bytes]:
        if direction == "ab":
            order.append((now, pkt[3:4]))
        return [pkt]

    a, b, link = connected_pair(filters=[note])
    order.clear()
    a.send(b"COMMAND" * 10, link.now)
    a.send_latest(_value(1), link.now)
    link.run_until(lambda: b.latest_readable, limit=600)
    types = [t for _, t in order]
    assert types.index(b"D") < types.index(b"L")


def test_a_graceful_close_waits_for_the_newest_value() -> None:
    a, b, link = connected_pair(filters=[_dropper("M", {1})])
    a.send_latest(_value(9), link.now)
    a.close(link.now)
    b.close(link.now)
    with pytest.raises(LocalProtocolError, match="closing"):
        a.send_latest(_value(10), link.now)
    link.run_until(lambda: a.state in (State.LINGER, State.CLOSED), limit=600)
    assert a.latest_settled
    assert a.data_settled


def test_limits_are_typed_errors() -> None:
    a, _, link = connected_pair()
    with pytest.raises(ValueError, match=r"1\.\.1024"):
        a.send_latest(b"", link.now)
    with pytest.raises(ValueError, match="one packet"):
        a.send_latest(random.Random(1).randbytes(1000), link.now)  # > one packet


def test_bad_lane_packets_are_counted_and_dropped() -> None:
    _a, b, link = connected_pair()
    ignored = b.statistics().ignored_packets
    b.receive_data(build_packet(Packet(seq=1, type="L", data=b""), BlockCheck.CRC16), link.now)
    b.receive_data(build_packet(Packet(seq=1, type="L", data=b"~x"), BlockCheck.CRC16), link.now)
    b.receive_data(build_packet(Packet(seq=1, type="M", data=b"~"), BlockCheck.CRC16), link.now)
    assert b.read_latest() is None
    assert b.statistics().ignored_packets == ignored + 3
    no = EndpointConfig(one_way_delay=1.3, line_rate=2400, latest=False)
    _a, c, link = connected_pair(no, no)
    c.receive_data(build_packet(Packet(seq=1, type="L", data=b" x"), BlockCheck.CRC16), link.now)
    assert c.read_latest() is None
    assert c.statistics().ignored_packets == 1


def test_the_sender_never_lets_the_numbers_wrap_past_the_receiver() -> None:
    s = LatestSender()
    for n in range(LATEST_SPAN):
        s.offer(b"v")
        assert s.may_send_new
        assert s.take_new()[0] == n + 1
        s.sent(b"wire", 0.0, 1.0, 8.0)
    s.offer(b"newer")
    assert not s.may_send_new  # every number is possibly the receiver's last
    assert s.expired(1.0)
    assert s.resend_due  # the last value goes again instead
    assert not s.on_ack(7 % LATEST_MODULUS) or s.acked == 7
    assert s.may_send_new
    # An acknowledgement older than one already seen changes nothing.
    assert not s.on_ack(5)
    assert s.acked == 7


def test_the_receiver_takes_any_number_but_its_last() -> None:
    r = LatestReceiver()
    assert r.on_value(5, b"a")
    assert not r.on_value(5, b"a")
    assert r.on_value(4, b"b")  # a line never reorders: a different number is newer
    assert r.read() == b"b"
    assert r.duplicates == 1
    assert r.superseded == 1


@settings(max_examples=25, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**32 - 1),
    loss=st.sampled_from([0.0, 0.05, 0.3]),
    count=st.integers(1, 300),
)
def test_property_in_order_at_most_once_the_last_always_and_the_stream_intact(
    seed: int, loss: float, count: int
) -> None:
    rng = random.Random(seed)

    def lossy(direction: str, pkt: bytes, now: float) -> list[bytes]:
        r = rng.random()
        if r < loss:
            return []
        if r < loss * 1.5:
            return [pkt, pkt]  # a duplicate, as a resend would bring one
        return [pkt]

    cfg = EndpointConfig(one_way_delay=0.2, line_rate=9600)
    a, b, link = connected_pair(cfg, cfg, delay=0.2, rate=9600, filters=[lossy])
    data = rng.randbytes(2000)
    sent = a.send(data, link.now)
    got: list[int] = []
    stream = bytearray()
    offered = 0

    def done() -> bool:
        nonlocal sent, offered
        if offered < count:
            offered += 1
            a.send_latest(_value(offered), link.now)
        if sent < len(data):
            sent += a.send(data[sent:], link.now)
        while (v := b.read_latest()) is not None:
            got.append(_number(v))
        stream.extend(b.read(None, link.now))
        return offered == count and bool(got) and got[-1] == count and len(stream) == len(data)

    link.run_until(done, limit=3000)
    assert got == sorted(set(got))
    assert bytes(stream) == data


def test_the_socket_api_over_a_simulated_line() -> None:
    from linksim import serial_socket_pair
    from linksim.link import DirectionConfig, LinkConfig

    line = LinkConfig.symmetric(DirectionConfig(rate=2400, delay=1.3))

    async def main() -> None:
        with trio.fail_after(600):
            async with serial_socket_pair(line) as (client, server):
                assert client.latest
                assert server.latest
                for n in range(1, 51):
                    client.send_latest(_value(n))
                    await trio.sleep(0.01)
                last = 0
                while last < 50:
                    value = _number(await server.receive_latest())
                    assert value > last
                    last = value

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
