"""Hints are starting points, not truths (issue 20, part 1): with no line rate
and no delay given, or a delay 10x off, a connection on a 1.3-second,
2400 bit/s line with byte errors connects, stays up and delivers everything.

Before: no hints gave up connecting after 0.5 s ("no answer to connect"), and
a 2-second dead-link verdict and a 1-second backoff ceiling could never
outlast a 2.6-second round trip.  Virtual time, sans-I/O, seeded.
"""

from __future__ import annotations

import random

import pytest

from linksim.bench._transfer import simulate
from serialsocket import EndpointConfig
from serialsocket._config import (
    MIN_CONNECT_TIMEOUT,
    UNHINTED_CONNECT_TIMEOUT,
    UNMEASURED_DEAD_AFTER,
)
from serialsocket._rtt import RttEstimator
from serialsocket.packets import PRINTABLE

PAYLOAD = random.Random(20).randbytes(8192)


@pytest.mark.parametrize("hints", ["none", "wrong-delay-low", "wrong-delay-high"])
def test_a_moon_line_delivers_everything_without_the_right_hints(hints: str) -> None:
    m = simulate(
        PAYLOAD,
        rate=2400,
        delay=1.3,
        byte_error_rate=1e-4,
        burst=None,
        window=31,
        max_len=128,
        encoding=PRINTABLE,
        seed=1,
        time_cap=5000,
        hints=hints,
    )
    assert m.end == "complete"
    assert m.ok
    assert m.connect_seconds < 10  # one round trip and a few resent requests


def test_no_hints_still_delivers_at_twenty_seconds_one_way() -> None:
    m = simulate(
        PAYLOAD,
        rate=9600,
        delay=20.0,
        byte_error_rate=1e-4,
        burst=None,
        window=31,
        max_len=128,
        encoding=PRINTABLE,
        seed=2,
        time_cap=20000,
        hints="none",
    )
    assert m.end == "complete"
    assert m.ok


def test_the_derived_connect_timeout_is_minutes() -> None:
    # No delay hint: nothing says the peer is not at Mars (a 45-minute round trip).
    assert EndpointConfig().derived_connect_timeout() == UNHINTED_CONNECT_TIMEOUT >= 2700
    hinted = EndpointConfig(one_way_delay=0.05, line_rate=2400)
    assert hinted.derived_connect_timeout() == MIN_CONNECT_TIMEOUT >= 120
    assert EndpointConfig(connect_timeout=0.5).derived_connect_timeout() == 0.5


def test_before_a_sample_the_backoff_survives_progress() -> None:
    rtt = RttEstimator(floor=0.01, ceiling=30.0, initial=0.05)
    for _ in range(6):
        rtt.on_timeout()
    backed_off = rtt.timeout()
    assert backed_off == pytest.approx(0.05 * 64)
    rtt.on_progress()  # an ACK of a retransmitted packet: no sample (Karn)
    assert rtt.timeout() == backed_off  # was 0.05 again: everything resent forever
    rtt.sample(2.6)
    rtt.on_progress()
    assert rtt.backoff == 0


def test_a_seed_is_an_upper_bound_that_samples_pull_down() -> None:
    rtt = RttEstimator(floor=0.01, ceiling=300.0, initial=0.05)
    rtt.seed(10.0)
    assert rtt.srtt == 10.0
    rtt.seed(1.0)  # only the first seed counts
    assert rtt.srtt == 10.0
    for _ in range(40):
        rtt.sample(2.6)
    assert rtt.srtt == pytest.approx(2.6, rel=0.02)


def test_liveness_waits_for_a_measurement_then_follows_it() -> None:
    from serialsocket import Endpoint, State

    a, b = Endpoint(EndpointConfig()), Endpoint(EndpointConfig())
    b.listen()
    a.connect(0.0)
    # The request crosses a 1.3 s path; b answers; the answer crosses back.
    b.receive_data(a.data_to_send(0.0), 1.3)
    assert b.state is State.ESTABLISHED
    assert b._dead_after >= UNMEASURED_DEAD_AFTER  # nothing measured yet
    a.receive_data(b.data_to_send(1.3), 2.6)
    assert a.state is State.ESTABLISHED
    # a measured 2.6 s (its request went out once): two round trips of outage
    # plus two timeouts, far above the 2 s derived from no hints.
    assert a._dead_after >= 2 * 2.6 + 2 * 2.6
    a.send(b"x", 2.6)
    b.receive_data(a.data_to_send(2.6), 3.9)
    # b seeded its estimate from its answer to a's first packet: 2.6 s.
    assert b.statistics().smoothed_rtt == pytest.approx(2.6)


def test_no_hints_at_a_minute_one_way_is_not_judged_dead() -> None:
    """At 60 s one way the connector resends its init before the first answer
    can arrive, so the listener answers several copies.  It used to seed its
    round trip only after a single answer: unmeasured, its 60 s dead_after
    ended the link ("link dead", 14 B/s).  Now it starts from the upper
    bound its first answer gives, and the link stays up to the end."""
    m = simulate(
        random.Random(60).randbytes(200_000),
        rate=2400,
        delay=60.0,
        byte_error_rate=1e-4,
        burst=None,
        window=31,
        max_len=None,
        encoding=PRINTABLE,
        seed=1,
        time_cap=100_000,
        hints="none",
    )
    assert m.end == "complete"
    assert m.ok


def test_no_hints_at_300_bit_s_sends_no_storm_of_inits() -> None:
    """Resending the connection request 50 ms apart, doubling (the derived
    timeout with no hints) piled eight 96-character inits, 26 s of line, on a
    300 bit/s line before the first answer; the listener answered each, the
    data queued behind them timed out, and every resend deepened the queue:
    0.008 of the limit.  Unhinted, the first resend now waits RFC 6298's 1 s."""
    m = simulate(
        random.Random(300).randbytes(4000),
        rate=300,
        delay=1.3,
        byte_error_rate=0.0,
        burst=None,
        window=31,
        max_len=None,
        encoding=PRINTABLE,
        seed=1,
        time_cap=2000,
        hints="none",
    )
    assert m.end == "complete"
    assert m.ok
    assert m.retransmissions == 0
    # The line's limit is about 15 bytes a second for random binary, printable.
    assert m.delivered / m.seconds > 13.5


@pytest.mark.parametrize("delay", [40.0, 300.0, 1200.0])
def test_a_listener_without_hints_waits_for_a_hinted_connectors_first_data(
    delay: float,
) -> None:
    """The connector is told the delay, so it sends its init once; the
    listener, told nothing, hears nothing between its answer and the
    connector's first data, a round trip later.  Its unmeasured 60 s verdict
    ended the link first from 40 s one way (at 300 s, 60 s after answering,
    before the connector had the answer).  Now the connector's initial
    timeout in its init (TIMEOUT) bounds the listener's patience from below
    (PROTOCOL.md 5), and the transfer completes."""
    from serialsocket import Endpoint, State

    from .simlink import SimLink

    a = Endpoint(EndpointConfig(one_way_delay=delay, line_rate=2400))
    b = Endpoint(EndpointConfig())
    link = SimLink(a, b, delay=delay, rate=2400)
    b.listen()
    a.connect(0.0)
    data = random.Random(int(delay)).randbytes(3000)
    sent = 0
    got = bytearray()

    def settled() -> bool:
        nonlocal sent
        if a.state is State.ESTABLISHED and sent < len(data):
            sent += a.send(data[sent:], link.now)
        if b.state is State.ESTABLISHED:
            got.extend(b.read(None, link.now))
        return len(got) == len(data) or State.DEAD in (a.state, b.state)

    link.run_until(settled, limit=20 * delay)
    assert b.state is State.ESTABLISHED, b.events()
    assert bytes(got) == data
    assert a.statistics().timeouts == 0
