"""The BlockingClient's controller watchdog, over real loopback TCP with real threads.

The arm's server runs in this test's trio thread; the controller (a
BlockingClient, which runs its own trio thread) runs in a worker thread.  A
"hung" controller is a worker blocked on a :class:`threading.Event` that the
test sets once it has seen what the arm did.  Every wait is bounded (GUARD);
no test asserts how fast anything was, only what happened.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any

import pytest
import trio

from tcpstream import (
    BlockingClient,
    CommandCode,
    FailureReason,
    Server,
    ServerConfig,
    ServerStatistics,
    SessionClosed,
    WatchdogExpired,
    commands,
)

from .fakearm import FakeArm
from .harness import KEY

GUARD = 30.0
"""Seconds of wall time before a hung test fails instead of hanging."""

WATCHDOG = 0.5
"""Small enough to keep the tests short, large next to a thread hand-off."""

CONFIG = ServerConfig(key=KEY, dead_time=60.0)
"""A deadman far beyond any wait here: a halt seen in time is the BYE's, not the deadman's."""


def _port(listeners: list[Any]) -> int:
    port: int = listeners[0].socket.getsockname()[1]
    return port


async def _poll(predicate: Callable[[], bool]) -> None:
    """Wait until ``predicate()`` (bounded by the caller's GUARD scope)."""
    while not predicate():
        await trio.sleep(0.02)


def _with_arm(
    arm: FakeArm,
    controller: Callable[[int], None],
    check: Callable[[Server], Any] | None = None,
) -> tuple[list[FailureReason], ServerStatistics]:
    """Serve ``arm`` on loopback; run ``controller(port)`` in a thread to its end.

    ``check(server)``, if given, runs in the server's trio thread alongside the
    controller (an async function: it may wait for the arm to react).  Returns
    the arm's halts and the server's statistics once the controller is done --
    before the server shuts down, which halts the arm (STOPPED) itself.
    """
    failure: list[BaseException] = []
    after: list[tuple[list[FailureReason], ServerStatistics]] = []

    def guarded(port: int) -> None:
        try:
            controller(port)
        except BaseException as exc:
            failure.append(exc)
            raise

    async def main() -> None:
        with trio.fail_after(GUARD):
            async with Server(arm, CONFIG) as server, trio.open_nursery() as nursery:
                listeners = await trio.open_tcp_listeners(0, host="127.0.0.1")
                await nursery.start(server.serve_listeners, listeners)
                port = _port(listeners)
                async with trio.open_nursery() as both:
                    both.start_soon(trio.to_thread.run_sync, guarded, port)
                    if check is not None:
                        await check(server)
                after.append((list(arm.halts), server.statistics()))
                nursery.cancel_scope.cancel()

    try:
        trio.run(main)
    except BaseException:
        if failure:  # the controller's own assertion, not the group around it
            raise failure[0] from None
        raise
    return after[0]


def _client(port: int, watchdog: float | None = WATCHDOG) -> BlockingClient:
    return BlockingClient.tcp("127.0.0.1", port, key=KEY, timeout=GUARD, watchdog=watchdog)


def test_a_hung_controller_loses_the_session_and_the_arm_halts(
    caplog: pytest.LogCaptureFixture,
) -> None:
    arm = FakeArm(move_time=GUARD * 2)  # would still be moving at the end of the test
    checked = threading.Event()  # the "hang": the controller blocks until the test looked
    seen: dict[str, Any] = {}

    def controller(port: int) -> None:
        with _client(port) as c:
            # A timed-out wait leaves the move running at the arm: outstanding work.
            # (Waiting inside the call gives the arm ample time to start it.)
            with pytest.raises(TimeoutError, match="may still run"):
                c.send(commands.move_joint(1, 0.1), timeout=WATCHDOG)
            assert checked.wait(GUARD), "the arm never halted"
            with pytest.raises(WatchdogExpired) as raised:
                c.status()
            message = str(raised.value)
            assert f"after {WATCHDOG:g} s without a call" in message
            assert "must reconnect" in message
            assert isinstance(raised.value, SessionClosed)  # caught by existing handlers
            for call in (c.kick, c.emergency_stop, lambda: c.latest_telemetry):
                with pytest.raises(WatchdogExpired):
                    call()
        # close() (the with block's exit) after expiry raised nothing.

    async def check(server: Server) -> None:
        # The release is immediate; the cancelled move ends at the executor
        # task's next turn: wait for both before looking.
        await _poll(
            lambda: (
                bool(arm.halts)
                and server.statistics().controller is None
                and server.statistics().running is None
            )
        )
        seen["stats"] = server.statistics()
        seen["halts"] = list(arm.halts)
        checked.set()

    with caplog.at_level(logging.WARNING, logger="tcpstream._blocking"):
        _with_arm(arm, controller, check)

    stats = seen["stats"]
    assert stats.controller is None  # control released: the controller left
    assert not stats.controller_connected
    assert stats.deadman_trips == 0  # the BYE halted it, not the deadman
    assert stats.emergency_stops == 0
    assert stats.running is None
    assert arm.count(CommandCode.MOVE_JOINT) == 1
    assert arm.finished == []  # the move was cut short
    assert seen["halts"]
    assert set(seen["halts"]) == {FailureReason.STOPPED}  # the BYE's halt, not a deadman's
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert any("controller watchdog expired" in m and "reconnect" in m for m in warnings)


def test_an_idle_expiry_releases_the_arm_without_halting_it() -> None:
    arm = FakeArm(move_time=0.01)
    checked = threading.Event()

    def controller(port: int) -> None:
        with _client(port) as c:
            c.move_joints([0.25] * 6)
            assert checked.wait(GUARD), "the controller was never released"
            with pytest.raises(WatchdogExpired):
                c.status()

    async def check(server: Server) -> None:
        await _poll(lambda: arm.finished != [] and server.statistics().controller is None)
        checked.set()

    halts, stats = _with_arm(arm, controller, check)
    assert halts == []  # nothing was outstanding: nothing to stop
    assert stats.controller is None
    assert stats.deadman_trips == 0
    assert arm.count(CommandCode.STATUS) == 0


def test_time_inside_a_long_call_counts_as_alive() -> None:
    arm = FakeArm(move_time=WATCHDOG * 3)

    def controller(port: int) -> None:
        with _client(port) as c:
            assert c.move_joints([0.5] * 6).feedback.joints == (0.5,) * 6  # 3 watchdogs long
            assert c.status().feedback.joints == (0.5,) * 6  # the clock restarted at its end

    halts, stats = _with_arm(arm, controller)
    assert halts == []
    assert stats.commands_failed == 0
    assert [c.code for c in arm.finished] == [CommandCode.MOVE_JOINTS, CommandCode.STATUS]


def test_kick_keeps_an_idle_controller_alive() -> None:
    arm = FakeArm(move_time=0.01)

    def controller(port: int) -> None:
        with _client(port) as c:
            c.status()
            idle_until = time.monotonic() + WATCHDOG * 4
            while time.monotonic() < idle_until:  # nothing to command, still alive
                c.kick()
                time.sleep(WATCHDOG / 8)
            assert c.status().feedback.p == (0.5, 0.0, 0.4)

    halts, _ = _with_arm(arm, controller)
    assert halts == []
    assert arm.count(CommandCode.STATUS) == 2


def test_without_a_watchdog_an_idle_controller_keeps_the_session(
    caplog: pytest.LogCaptureFixture,
) -> None:
    arm = FakeArm(move_time=0.01)

    def controller(port: int) -> None:
        with _client(port, watchdog=None) as c:
            assert c.watchdog is None
            c.status()
            time.sleep(WATCHDOG * 3)  # idle far past what a watchdog would allow
            c.kick()  # accepted, and a no-op
            assert c.move_joints([0.25] * 6).feedback.joints == (0.25,) * 6

    with caplog.at_level(logging.WARNING, logger="tcpstream._blocking"):
        halts, _ = _with_arm(arm, controller)
    assert halts == []
    assert arm.count(CommandCode.MOVE_JOINTS) == 1
    assert not [r for r in caplog.records if "watchdog" in r.getMessage()]


@pytest.mark.parametrize("bad", [0, 0.0, -1.0, math.nan, math.inf, -math.inf, True])
def test_bad_watchdog_values_are_refused(bad: float) -> None:
    with pytest.raises(ValueError, match="watchdog"):
        BlockingClient.tcp("127.0.0.1", 9, watchdog=bad)
    with pytest.raises(ValueError, match="watchdog"):
        BlockingClient(lambda: None, watchdog=bad)  # type: ignore[arg-type,return-value]


def test_good_watchdog_values_are_kept() -> None:
    assert BlockingClient.tcp("127.0.0.1", 9, watchdog=0.5).watchdog == 0.5
    assert BlockingClient.tcp("127.0.0.1", 9, watchdog=2).watchdog == 2
    assert BlockingClient.tcp("127.0.0.1", 9).watchdog is None
