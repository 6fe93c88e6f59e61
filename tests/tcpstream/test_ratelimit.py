"""The token bucket behind ServerConfig.max_packet_rate (tcpstream/_ratelimit.py)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tcpstream import ServerConfig
from tcpstream._config import MIN_PACKET_RATE
from tcpstream._ratelimit import TokenBucket


def test_starts_full_refills_at_the_rate_and_caps_at_the_burst() -> None:
    b = TokenBucket(rate=100.0, burst=10.0, now=0.0)
    assert b.available(0.0) == 10.0
    b.spend(10.0, 0.0)
    assert b.wait_for(1.0, 0.0) == pytest.approx(0.01)
    assert b.available(0.05) == pytest.approx(5.0)
    assert b.available(100.0) == 10.0  # never more than the burst


def test_debt_from_an_oversized_read_is_repaid_first() -> None:
    b = TokenBucket(rate=10.0, burst=4.0, now=0.0)
    b.spend(6.0, 0.0)  # the stream returned more than was allowed
    assert b.available(0.0) == -2.0
    assert b.wait_for(1.0, 0.0) == pytest.approx(0.3)


def test_a_clock_stepping_back_mints_nothing() -> None:
    b = TokenBucket(rate=10.0, burst=4.0, now=5.0)
    b.spend(4.0, 5.0)
    assert b.available(1.0) == 0.0
    assert b.available(5.1) == pytest.approx(1.0)


def test_wait_for_more_than_the_burst_waits_for_the_burst() -> None:
    b = TokenBucket(rate=1.0, burst=2.0, now=0.0)
    b.spend(2.0, 0.0)
    assert b.wait_for(50.0, 0.0) == pytest.approx(2.0)


@pytest.mark.parametrize(
    ("rate", "burst"), [(0.0, 1.0), (-1.0, 1.0), (math.inf, 1.0), (math.nan, 1.0), (1.0, 0.5)]
)
def test_nonsense_parameters_are_refused(rate: float, burst: float) -> None:
    with pytest.raises(ValueError, match="must be"):
        TokenBucket(rate, burst, 0.0)


@given(
    st.lists(
        st.tuples(st.floats(0.0, 0.5), st.floats(0.0, 50.0)),
        max_size=60,
    )
)
def test_what_is_spent_never_exceeds_burst_plus_rate_times_time(
    steps: list[tuple[float, float]],
) -> None:
    """A reader that only takes what ``available`` allows (as the pump does)
    gets at most burst + rate * elapsed, whatever the timing and sizes."""
    rate, burst = 20.0, 8.0
    b = TokenBucket(rate, burst, 0.0)
    now = spent = 0.0
    for dt, want in steps:
        now += dt
        take = min(want, max(0.0, b.available(now)))
        b.spend(take, now)
        spent += take
        assert spent <= burst + rate * now + 1e-9


@pytest.mark.parametrize("rate", [0.0, -5.0, math.nan, math.inf, 3.0, 15.9])
def test_server_config_refuses_a_rate_limit_an_honest_controller_cannot_live_with(
    rate: float,
) -> None:
    """Below four times an idle controller's heartbeat rate (16/s at the default
    0.25 s heartbeat) a throttled honest connection would fall behind for good."""
    with pytest.raises(ValueError, match="max_packet_rate"):
        ServerConfig(max_packet_rate=rate)


def test_server_config_rate_floor_follows_the_heartbeat() -> None:
    assert ServerConfig().packet_rate_floor() == 16.0
    slow = ServerConfig(rtt_hint=6.0)  # Earth-Moon serial: 3 s heartbeats
    assert slow.packet_rate_floor() == MIN_PACKET_RATE
    assert ServerConfig(rtt_hint=6.0, max_packet_rate=MIN_PACKET_RATE).max_packet_rate == 10.0
    assert ServerConfig(max_packet_rate=None).burst() == 66
    assert ServerConfig(queue_size=40).burst() == 82
