"""Early data (PROTOCOL.md section 13): the first bytes of the stream ride in
the connection request and arrive one one-way delay after connecting; every
byte is delivered exactly once whether the listener takes them or not, and
whatever is lost or repeated on the way."""

from __future__ import annotations

import random

import pytest
import trio
import trio.testing
from hypothesis import given
from hypothesis import strategies as st

from serialsocket import Endpoint, EndpointConfig, RemoteProtocolError, State
from serialsocket._params import EARLY_INIT_LIMIT, LANE_EARLY, InitParameters
from serialsocket.packets import BlockCheck

from .simlink import MOON_HINTS, QueuedRun, SimLink, drop_nth

DELAY = 1.3


def _start(
    data: bytes,
    cfg_a: EndpointConfig = MOON_HINTS,
    cfg_b: EndpointConfig = MOON_HINTS,
    filters: list | None = None,  # type: ignore[type-arg]
) -> tuple[Endpoint, Endpoint, QueuedRun]:
    run = QueuedRun(data, cfg_a, cfg_b, filters, delay=DELAY)
    return run.a, run.b, run


def _read_all(a: Endpoint, b: Endpoint, run: QueuedRun, n: int) -> tuple[bytes, float | None]:
    """Run until ``b`` has read ``n`` bytes; the bytes and when the first came."""
    return run.read_all(n)


_drop = drop_nth


def test_the_first_bytes_arrive_one_way_after_connecting() -> None:
    a, b, run = _start(b"MOVE 1 2 3")
    got, first = _read_all(a, b, run, 10)
    assert got == b"MOVE 1 2 3"
    assert first is not None
    # One way plus the init's transmit time (under 70 characters at 2400 bit/s),
    # not the three one-way delays of connecting first.
    assert first < DELAY + 0.3
    run.link.run_until(lambda: a.state is State.ESTABLISHED)
    sa, sb = a.statistics(), b.statistics()
    assert (sa.early_sent, sa.early_delivered, sb.early_received) == (10, 10, 0 + 10)
    assert sa.bytes_queued == 0
    assert sa.send_next == 1  # nothing went as a data packet


def test_without_early_data_the_first_byte_takes_three_one_way_delays() -> None:
    cfg = EndpointConfig(one_way_delay=1.3, line_rate=2400, early_data=0)
    a, b, run = _start(b"MOVE 1 2 3", cfg, cfg)
    got, first = _read_all(a, b, run, 10)
    assert got == b"MOVE 1 2 3"
    assert first is not None
    assert first > 3 * DELAY
    assert a.statistics().early_sent == 0


def test_the_rest_of_the_stream_follows_in_order() -> None:
    data = random.Random(3).randbytes(5000)
    a, b, run = _start(data)
    got, _ = _read_all(a, b, run, len(data))
    assert got == data
    sa = a.statistics()
    assert 0 < sa.early_sent <= 256
    assert sa.early_delivered == sa.early_sent
    assert sa.bytes_acknowledged == 0 or sa.bytes_acknowledged <= len(data)


def test_a_lost_answer_is_repeated_and_nothing_is_delivered_twice() -> None:
    a, b, run = _start(b"once only", filters=[_drop(b"Y", {1}, "ba")])
    got, _ = _read_all(a, b, run, 9)
    run.link.run_until(lambda: a.state is State.ESTABLISHED)
    run.link.run_for(10.0)
    assert got + b.read() == b"once only"
    assert a.statistics().early_delivered == 9
    assert b.statistics().early_received == 9


def test_a_lost_request_is_resent_with_the_same_bytes() -> None:
    a, b, run = _start(b"resent", filters=[_drop(b"I", {1}, "ab")])
    got, first = _read_all(a, b, run, 6)
    assert got == b"resent"
    assert first is not None
    assert first > DELAY + 0.3
    run.link.run_for(10.0)
    assert b.read() == b""


def test_a_listener_that_takes_none_gets_them_as_data() -> None:
    no = EndpointConfig(one_way_delay=1.3, line_rate=2400, early_data=0)
    a, b, run = _start(b"as ordinary data", MOON_HINTS, no)
    got, first = _read_all(a, b, run, 16)
    assert got == b"as ordinary data"
    assert first is not None
    assert first > 3 * DELAY
    run.link.run_for(10.0)
    assert b.read() == b""
    sa = a.statistics()
    assert (sa.early_sent, sa.early_delivered) == (16, 0)
    assert b.statistics().early_received == 0


def test_a_refused_request_delivers_nothing_and_an_accepted_one_delivers_once() -> None:
    manual = EndpointConfig(one_way_delay=1.3, line_rate=2400, auto_accept=False)
    a, b, run = _start(b"not for you", MOON_HINTS, manual)
    run.link.run_until(lambda: b.events() != [] or run.link.now > 5)
    b.refuse("busy", run.link.now)
    run.link.run_until(lambda: a.state in (State.FAILED, State.CLOSED) or run.link.now > 60)
    assert b.read() == b""
    a, b, run = _start(b"welcome", MOON_HINTS, manual)
    run.link.run_until(lambda: any(True for _ in b.events()) or run.link.now > 5)
    b.accept(run.link.now)
    got, _ = _read_all(a, b, run, 7)
    assert got == b"welcome"
    run.link.run_for(10.0)
    assert b.read() == b""


def test_a_simultaneous_open_takes_no_early_data_and_loses_none() -> None:
    a, b = Endpoint(MOON_HINTS), Endpoint(MOON_HINTS)
    link = SimLink(a, b, delay=DELAY, rate=2400)
    a.send(b"from a", 0.0)
    b.send(b"from b", 0.0)
    a.connect(0.0)
    b.connect(0.0)
    link.run_until(lambda: a.readable >= 6 and b.readable >= 6)
    link.run_for(10.0)
    assert (a.read(), b.read()) == (b"from b", b"from a")
    assert a.statistics().early_received == b.statistics().early_received == 0


def test_the_request_is_bounded_and_a_small_listener_still_reads_it() -> None:
    data = bytes(range(128, 160)) * 64  # 8-bit controls: three characters each
    small = EndpointConfig(one_way_delay=1.3, line_rate=2400, max_packet_length=38)
    lengths: list[int] = []

    def note(d: str, pkt: bytes, now: float) -> list[bytes]:
        if d == "ab" and pkt[3:4] == b"I":
            lengths.append(len(pkt.rstrip(b"\r")))
        return [pkt]

    big = EndpointConfig(one_way_delay=1.3, line_rate=2400, early_data=512)
    a, b, run = _start(data, big, small, filters=[note])
    got, _ = _read_all(a, b, run, len(data))
    assert got == data
    assert lengths
    assert max(lengths) <= EARLY_INIT_LIMIT
    assert 0 < a.statistics().early_sent < 512  # the init's limit took fewer bytes


def test_a_malformed_early_field_is_refused_with_a_reason() -> None:
    mine = InitParameters.mine(
        max_packet_length=128,
        window=31,
        check=BlockCheck.CRC16,
        encoding=None,
        timeout_hint=1.0,
        features=16,
        lanes=LANE_EARLY,
    ).with_early(b"abc")
    good = mine.encode()
    for bad in (good[:-1], good + b"x", good[:-1] + b"#"):
        with pytest.raises(RemoteProtocolError, match="XEARLY"):
            InitParameters.decode(bad)


@given(st.binary(max_size=300))
def test_early_data_round_trips_through_the_init(data: bytes) -> None:
    mine = InitParameters.mine(
        max_packet_length=128,
        window=31,
        check=BlockCheck.CRC16,
        encoding=None,
        timeout_hint=1.0,
        long_window=1000,
        features=16,
        lanes=LANE_EARLY | 1,
    )
    decoded = InitParameters.decode(mine.with_early(data).encode())
    assert decoded.early == (data or None)
    assert bool((decoded.lanes or 0) & LANE_EARLY) == bool(data)
    assert decoded.long_window == 1000


def test_early_data_is_bounded_by_configuration() -> None:
    with pytest.raises(Exception, match="early_data"):
        EndpointConfig(early_data=-1)
    with pytest.raises(Exception, match="early_data"):
        EndpointConfig(early_data=100_000)


def test_the_trio_socket_sends_early_data_at_the_moon() -> None:
    from linksim import LinkConfig, endpoint_config_for
    from linksim.link import ImpairedLink
    from serialsocket import SerialSocket, accept, connect

    link_cfg = LinkConfig.preset("moon")
    cfg = endpoint_config_for(link_cfg)
    one_way = link_cfg.a_to_b.delay

    async def main() -> None:
        line = ImpairedLink(link_cfg)
        with trio.fail_after(600):
            async with trio.open_nursery() as nursery:
                got: list[tuple[float, bytes]] = []

                async def serve() -> None:
                    server: SerialSocket = await accept(line.b, cfg, nursery=nursery)
                    while len(b"".join(g for _, g in got)) < 18:
                        got.append((trio.current_time(), await server.receive_some()))
                    assert server.endpoint.statistics().early_received == 8

                nursery.start_soon(serve)
                client = await connect(line.a, cfg, nursery=nursery, early_data=b"STOP ARM")
                connected_at = trio.current_time()
                assert client.endpoint.statistics().early_delivered == 8
                await client.send_all(b" then more")
                while len(b"".join(g for _, g in got)) < 18:
                    await trio.sleep(0.1)
                assert b"".join(g for _, g in got) == b"STOP ARM then more"
                # The first bytes arrived one way after connect (plus the
                # init's few milliseconds at 9600 bit/s), before the client
                # even knew it was connected (two one-way delays).
                first_at, first = got[0]
                assert first == b"STOP ARM"
                assert first_at < one_way + 0.2 < connected_at
                nursery.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))


def test_too_much_early_data_is_a_value_error_before_anything_is_sent() -> None:
    from serialsocket import connect

    async def main() -> None:
        a, _b = trio.testing.memory_stream_pair()
        with pytest.raises(ValueError, match="early_data"):
            await connect(a, EndpointConfig(send_buffer=100), early_data=bytes(101))

    trio.run(main)
