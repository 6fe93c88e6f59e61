"""The first flight (PROTOCOL.md section 14): a connector with more queued than
its request carries sends data packets right behind the request, before any
answer; a listener that can read them takes them, and every byte is delivered
exactly once, in order, whether it takes them or not and whatever is lost,
repeated or restarted on the way."""

from __future__ import annotations

import dataclasses
import random

import pytest

from serialsocket import (
    ConnectionAborted,
    Endpoint,
    EndpointConfig,
    RemoteProtocolError,
    State,
)
from serialsocket._params import LANE_FLIGHT, Flight, InitParameters
from serialsocket.packets import EIGHT_BIT_CLEAN, PRINTABLE, BlockCheck, Packet, build_packet

from .simlink import MOON_HINTS, QueuedRun, SimLink, drop_nth
from .test_rate_estimation import _simulate

DELAY = 1.3
DATA = random.Random(14).randbytes(5000)
FLY = dataclasses.replace(MOON_HINTS, first_flight=True)
UNHINTED = EndpointConfig(first_flight=True)
NO_FLIGHT = dataclasses.replace(MOON_HINTS, takes_first_flight=False)


class _Run(QueuedRun):
    """A :class:`QueuedRun` whose ends fly by default and check what arrived."""

    def __init__(
        self,
        data: bytes,
        cfg_a: EndpointConfig = FLY,
        cfg_b: EndpointConfig = FLY,
        filters: list | None = None,  # type: ignore[type-arg]
        *,
        delay: float = DELAY,
    ) -> None:
        super().__init__(data, cfg_a, cfg_b, filters, delay=delay)
        self.first: float | None = None

    def done(self) -> float:
        """Run until ``b`` has read everything, exactly; when it had."""
        got, self.first = self.read_all()
        assert got == self.data
        return self.link.now


_drop = drop_nth


@pytest.mark.parametrize("cfg", [FLY, UNHINTED], ids=["hinted", "unhinted"])
def test_the_bulk_leaves_behind_the_request_and_saves_the_round_trip(
    cfg: EndpointConfig,
) -> None:
    flying = _Run(DATA, cfg, cfg)
    done = flying.done()
    assert flying.first is not None
    # The first packet arrives one way after it left, right behind the
    # request: not after the handshake's round trip and one more way.
    assert flying.first < 2 * DELAY
    sa, sb = flying.a.statistics(), flying.b.statistics()
    assert sa.flight_packets > 0
    assert sa.flight_refused == 0
    assert sb.flight_received >= sa.flight_packets
    assert sa.early_sent == 0  # the flight carries the first bytes instead
    grounded = _Run(DATA, dataclasses.replace(cfg, first_flight=False), cfg)
    # The line carried data during the handshake's round trip (2.6 s).
    assert done < grounded.done() - 1.5


def test_a_listener_that_takes_no_flight_gets_every_byte_once() -> None:
    run = _Run(DATA, FLY, NO_FLIGHT)
    run.done()
    sa, sb = run.a.statistics(), run.b.statistics()
    assert sa.flight_packets > 0
    assert sa.flight_refused == sa.flight_packets
    # Its packets came before the window (k + 1 on): old, never delivered.
    assert sb.flight_received >= sa.flight_packets
    assert sb.bytes_delivered == len(DATA)


def test_a_flight_the_agreement_cannot_read_is_not_taken() -> None:
    # The connector's line is 8-bit, the listener's printable: the flight is
    # cut in the escape code, the agreement is the radix-91 packing.
    eight = dataclasses.replace(FLY, encoding=EIGHT_BIT_CLEAN, dense=True)
    printable = dataclasses.replace(FLY, encoding=PRINTABLE, dense=True)
    run = _Run(DATA, eight, printable)
    run.done()
    sa = run.a.statistics()
    assert sa.flight_packets > 0
    assert sa.flight_refused == sa.flight_packets
    assert run.b.statistics().bytes_delivered == len(DATA)


def test_a_listener_that_accepts_by_hand_takes_no_flight() -> None:
    manual = dataclasses.replace(FLY, auto_accept=False)
    run = _Run(DATA, FLY, manual)
    run.link.run_until(lambda: run.b.events() != [])
    run.b.accept(run.link.now)
    run.done()
    sa = run.a.statistics()
    assert sa.flight_refused == sa.flight_packets > 0


def test_a_lost_request_loses_no_byte() -> None:
    # The flight reaches a listener that never heard the request: dropped.
    run = _Run(DATA, UNHINTED, UNHINTED, [_drop(b"I", {1}, "ab")])
    run.done()
    assert run.a.statistics().flight_packets > 0


def test_a_lost_answer_is_repeated_and_nothing_is_delivered_twice() -> None:
    # The request is resent after flight data arrived: a resend (the same
    # bytes), answered again, not a restarted peer.
    run = _Run(DATA, UNHINTED, UNHINTED, [_drop(b"Y", {1}, "ba")])
    run.done()
    sa, sb = run.a.statistics(), run.b.statistics()
    assert sa.flight_packets > 0
    assert sa.flight_refused == 0
    assert sb.bytes_delivered == len(DATA)
    assert run.b.state is State.ESTABLISHED


def test_a_restarted_connector_is_told_from_a_resent_request() -> None:
    # A connector sends its request and part of its flight, then dies; a new
    # one on the same line sends the same request but for its nonce, and a
    # flight numbered from 1 again.  Taken as a resend, its packets would be
    # read as duplicates of the old flight's and the old stream continued.
    old, b = Endpoint(UNHINTED), Endpoint(UNHINTED)
    cut = False

    def after_death(d: str, pkt: bytes, now: float) -> list[bytes]:
        return [] if cut and d == "ab" and link.a is old else [pkt]

    link = SimLink(old, b, delay=DELAY, rate=2400, filters=[after_death])
    b.listen()
    old.send(b"old stream " * 400, 0.0)
    old.connect(0.0)
    link.run_until(lambda: b.statistics().flight_received >= 2)
    cut = True
    new = Endpoint(UNHINTED)
    link.a = new
    new.send(b"new stream " * 400, link.now)
    new.connect(link.now)
    events: list[object] = []
    for _ in range(10_000):
        if not link.step():
            break
        events += b.events()
        if any(isinstance(e, ConnectionAborted) for e in events):
            break
    aborted = [e for e in events if isinstance(e, ConnectionAborted)]
    assert aborted, events
    assert "restarted" in aborted[0].reason
    assert b"new" not in b.read()  # nothing of the new stream joined the old


def test_a_simultaneous_open_takes_no_flight_and_loses_none() -> None:
    a, b = Endpoint(UNHINTED), Endpoint(UNHINTED)
    link = SimLink(a, b, delay=DELAY, rate=2400)
    mine, theirs = random.Random(1).randbytes(3000), random.Random(2).randbytes(3000)
    a.send(mine, 0.0)
    b.send(theirs, 0.0)
    a.connect(0.0)
    b.connect(0.0)
    got_a, got_b = bytearray(), bytearray()

    def done() -> bool:
        got_a.extend(a.read())
        got_b.extend(b.read())
        return len(got_a) >= 3000 and len(got_b) >= 3000

    link.run_until(done, limit=600)
    assert (bytes(got_a), bytes(got_b)) == (theirs, mine)
    for ep in (a, b):
        st = ep.statistics()
        assert st.flight_refused == st.flight_packets > 0


def test_a_flight_queued_at_an_unknown_rate_does_not_time_out_while_waiting() -> None:
    # No hints, 384-character packets on a 2400 bit/s line: three flight
    # packets are 4.8 s of line, handed at once, answered after 0.4 s.
    # Timed from the answer's round trip, they timed out while still queued
    # and the resends joined the queue: a storm (PROTOCOL.md 14, "Timers").
    fixed = EndpointConfig(max_packet_length=384, first_flight=True)
    run = _Run(random.Random(3).randbytes(8192), fixed, fixed, delay=0.0)
    run.done()
    sa = run.a.statistics()
    assert sa.flight_packets > 0
    assert (sa.timeouts, sa.retransmissions) == (0, 0)


def test_packets_behind_a_flight_not_taken_do_not_time_out_while_it_drains() -> None:
    # Not taken, the flight's packets still hold the line ahead of what is
    # sent after the answer; at an unknown rate that must be allowed for.
    fixed = EndpointConfig(max_packet_length=384, first_flight=True)
    grounded = dataclasses.replace(fixed, takes_first_flight=False)
    run = _Run(random.Random(3).randbytes(8192), fixed, grounded, delay=0.0)
    run.done()
    sa = run.a.statistics()
    assert sa.flight_refused == sa.flight_packets > 0
    assert sa.timeouts == 0


@pytest.mark.parametrize(("rate", "size"), [(300, 6000), (1200, 20000)])
def test_a_rate_hint_ten_times_high_does_not_storm_behind_a_flight(rate: int, size: int) -> None:
    # Told ten times the line: the flight leaves paced at the hint.  The rate
    # estimator must see its packets (the first delivery point is the
    # request, as it is the answer without a flight) to correct the hint; a
    # flight it did not see left 300 bit/s in a storm of 353 timeouts.
    m = _simulate(
        "wrong-rate-high",
        payload=random.Random(3).randbytes(size),
        rate=rate,
        byte_error_rate=0.0,
        time_cap=3000,
        seed=1,
        first_flight=True,
    )
    assert m.end == "complete"
    assert m.ok
    assert m.timeouts <= 2


def _offer() -> InitParameters:
    return InitParameters.mine(
        max_packet_length=1024,
        window=31,
        check=BlockCheck.CRC16,
        encoding=None,
        timeout_hint=1.0,
        features=16,
        lanes=1,
    )


def test_the_announcement_round_trips_through_the_init() -> None:
    flight = Flight(packets=7, length=256, nonce=4095)
    decoded = InitParameters.decode(_offer().with_flight(flight).encode())
    assert decoded.flight == flight
    assert decoded.lanes is not None
    assert decoded.lanes & LANE_FLIGHT
    both = InitParameters.decode(_offer().with_early(b"hi").with_flight(flight).encode())
    assert (both.early, both.flight) == (b"hi", flight)
    # Characters after it are a later version's fields.
    assert InitParameters.decode(_offer().with_flight(flight).encode() + b"xyz").flight == flight


@pytest.mark.parametrize(
    "flight",
    [Flight(0, 256, 1), Flight(32, 256, 1), Flight(4, 11, 1)],
    ids=["no-packets", "too-many", "too-short"],
)
def test_a_bad_announcement_is_refused_with_a_reason(flight: Flight) -> None:
    with pytest.raises(RemoteProtocolError, match="XFLIGHT"):
        InitParameters.decode(_offer().with_flight(flight).encode())
    truncated = _offer().with_flight(Flight(4, 256, 1)).encode()[:-2]
    with pytest.raises(RemoteProtocolError, match="XFLIGHT"):
        InitParameters.decode(truncated)


def test_a_listener_refuses_a_request_whose_announcement_is_malformed() -> None:
    b = Endpoint(UNHINTED)
    b.listen()
    bad = _offer().with_flight(Flight(4, 256, 1)).encode()[:-2]
    b.receive_data(build_packet(Packet(seq=0, type="I", data=bad), BlockCheck.CRC16), 0.0)
    assert b"XFLIGHT" in b.data_to_send(0.0)  # its E says what was wrong
    assert b.state is State.LISTEN
