"""The soak, short (issue 11): ``make soak`` runs 24 simulated hours; this runs three minutes.

Three simulated minutes of noisy-moon with a 30 s and a 300 s outage (one
every 72 s), command traffic and bulk data both ways, on the virtual clock.
The same :func:`linksim.bench.check_soak` verdict as the full soak: every bulk
byte verified in order, no command executed twice, one deadman stop in each
outage longer than the deadman and no other halt but the shutdown's, no error.
"""

from __future__ import annotations

import pytest

from linksim.bench import _soak


@pytest.fixture(scope="module")
def report() -> _soak.SoakReport:
    return _soak.run_soak(0.05, seed=3, outage_every=0.02)


@pytest.mark.soak
def test_short_soak_passes_the_full_soak_verdict(report: _soak.SoakReport) -> None:
    assert _soak.check(report) == []


@pytest.mark.soak
def test_short_soak_moved_data_and_commands_through_both_outages(
    report: _soak.SoakReport,
) -> None:
    assert report.outages == [(72.0, 102.0), (144.0, 444.0)]
    assert report.error is None
    for direction in ("a_to_b", "b_to_a"):
        assert report.bulk_sent[direction] > 8 * 1024
        assert report.bulk_verified[direction] == report.bulk_sent[direction]
    assert report.commands_completed >= 5
    assert report.executions == report.commands_completed
    assert report.executed_twice == 0
    assert report.reconnects >= 2  # the session came back after each long outage
    deadman_stops = [t for t, _ in report.halts if any(s <= t <= e for s, e in report.outages)]
    assert len(deadman_stops) == 2
    # The only other halt is the server's own when the soak shuts it down.
    assert [why for t, why in report.halts if t not in deadman_stops] == ["STOPPED"]


def test_check_flags_what_it_must() -> None:
    """The verdict can fail: each kind of damage is reported."""
    bad = _soak.SoakReport(hours=1.0, seed=0)
    bad.bulk_sent = {"a_to_b": 100}
    bad.bulk_verified = {"a_to_b": 90}
    bad.executed_twice = 1
    bad.outages = [(10.0, 100.0)]
    bad.deadman = 20.0
    bad.memory_samples = [1_000_000, 1_000_000 + 2 * _soak.MEMORY_SLACK]
    problems = _soak.check(bad)
    assert len(problems) == 4, problems
    # Halts are all accounted for: a deadman stop on a healthy line, or any
    # halt but the shutdown's STOPPED, is a problem of its own.
    bad.halts = [(15.0, "DEADMAN"), (500.0, "DEADMAN"), (600.0, "COLLISION"), (3600.0, "STOPPED")]
    problems = _soak.check(bad)
    assert len(problems) == 5, problems  # the outage now has its one stop
    assert any("deadman stop at 500 s outside" in p for p in problems)
    assert any("unexpected halt COLLISION at 600 s" in p for p in problems)


def test_outage_schedule_cycles_lengths() -> None:
    schedule = _soak._schedule(24.0, 3.0)
    assert [o.start for o in schedule] == [3.0 * 3600 * k for k in range(1, 8)]
    assert [o.end - o.start for o in schedule] == [30.0, 300.0, 5.0, 900.0, 30.0, 300.0, 5.0]
