"""The exactly-once memory on its own: classification, bounds, eviction."""

from __future__ import annotations

import pytest

from tcpstream import CommandCode, FailureReason
from tcpstream._memory import Lookup, RequestMemory, StoredFailure
from tcpstream.connection import ControllerIdentity

A = ControllerIdentity("a", 1)
B = ControllerIdentity("b", 1)


def done(reason: FailureReason = FailureReason.STOPPED) -> StoredFailure:
    return StoredFailure(CommandCode.STATUS, reason, "x", (0.0, 0.0, 0.0, 0.0))


def test_new_in_flight_done_expired() -> None:
    memory = RequestMemory(size=3)
    assert memory.lookup(A, 1) == (Lookup.NEW, None)
    memory.start(A, 1)
    assert memory.lookup(A, 1) == (Lookup.IN_FLIGHT, None)
    memory.finish(A, 1, done())
    assert memory.lookup(A, 1) == (Lookup.DONE, done())
    for rid in (2, 3, 4):
        memory.start(A, rid)
        memory.finish(A, rid, done())
    # Only the last three finished ids are remembered; 1 is now forgotten but
    # below the highest id: EXPIRED, never NEW (it may have run).
    assert memory.lookup(A, 1) == (Lookup.EXPIRED, None)
    assert memory.lookup(A, 2)[0] is Lookup.DONE
    assert memory.highest(A) == 4
    assert memory.lookup(A, 5) == (Lookup.NEW, None)


def test_identities_are_separate_and_restarts_are_new_identities() -> None:
    memory = RequestMemory()
    memory.start(A, 1)
    assert memory.lookup(B, 1) == (Lookup.NEW, None)
    restarted = ControllerIdentity("a", 2)  # same name, new incarnation
    assert memory.lookup(restarted, 1) == (Lookup.NEW, None)


def test_start_refuses_an_old_id() -> None:
    memory = RequestMemory()
    memory.start(A, 5)
    with pytest.raises(ValueError, match="not new"):
        memory.start(A, 5)
    with pytest.raises(ValueError, match="not new"):
        memory.start(A, 3)


def test_least_recently_used_identity_is_forgotten_but_never_one_in_flight() -> None:
    memory = RequestMemory(identities=2)
    memory.start(A, 1)  # A has work in flight
    memory.start(B, 1)
    memory.finish(B, 1, done())
    c = ControllerIdentity("c", 1)
    memory.lookup(c, 1)  # a third identity: B (idle) is forgotten, not A
    assert memory.highest(A) == 1
    assert memory.highest(B) == 0
    assert memory.in_flight(A) == 1


def test_bounds_are_validated() -> None:
    with pytest.raises(ValueError, match=">= 1"):
        RequestMemory(size=0)


def test_an_id_overtaken_by_a_stop_is_known_never_taken_unless_it_may_have_been_evicted() -> None:
    """The overtaken-stop rule (PROTOCOL.md 15) answers STOPPED, "not run",
    only for ids the arm knows it never took in: not for one at or below an
    evicted reply, which may have run."""
    memory = RequestMemory(size=2)
    for rid in (1, 2, 3):
        memory.start(A, rid)
        memory.finish(A, rid, done())
    memory.start(A, 9)  # an emergency stop that overtook 4..8
    memory.note_stop(A, 9)
    assert memory.stopped_at(A) == 9
    assert memory.lookup(A, 5) == (Lookup.EXPIRED, None)
    assert not memory.may_have_run(A, 5)  # 5 never reached the arm
    assert memory.may_have_run(A, 1)  # 1 finished and was forgotten
    assert memory.may_have_run(ControllerIdentity("unknown", 1), 5)
