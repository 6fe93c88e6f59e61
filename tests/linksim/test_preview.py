"""Plan preview refuses exactly what the remote arm refuses: the same scenarios run both ways.

The remote run goes through the whole command chain (tcpstream server and
client over an in-memory line with 0.2 s of delay) on a virtual clock; the
preview never touches a link.  Reason, aux words, message and the state
after every command must agree exactly.
"""

from __future__ import annotations

import dataclasses

import pytest
import trio
import trio.testing

from linksim import (
    DEFAULT_WORLD,
    DirectionConfig,
    LinkConfig,
    SimulatedArm,
    WorldConfig,
    open_impaired_link,
    rock_task,
)
from linksim.control import ModelState, preview
from tcpstream import (
    Command,
    CommandCode,
    CommandFailed,
    FailureReason,
    Feedback,
    Server,
    ServerConfig,
    connect_stream,
)

C = CommandCode
Outcome = tuple[FailureReason, tuple[float, ...], str, Feedback]

SCENARIOS: dict[str, list[Command]] = {
    "joint limit": [Command(C.OPEN_FINGERS, (0.05,)), Command(C.MOVE_JOINT, (1, 3.0))],
    "unreachable": [Command(C.MOVE_TO_POSITION, (2.0, 0.0, 0.0))],
    "not grasping": [Command(C.SQUEEZE, (10.0,))],
    "no object": [Command(C.MOVE_JOINT, (1, 0.3)), Command(C.CENTER_FINGERS)],
    "collision (table, incremental)": [Command(C.MOVE_CARTESIAN_DELTA, (0.2, 0.0, -0.5))],
    "collision (table, path)": [Command(C.MOVE_PATH, (1, 0, 0.6, 0.0, -0.5))],
    "collision with an added obstacle": [
        Command(C.ADD_OBSTACLE, (0.3, -0.3, -0.3, 0.5, 0.3, -0.1)),
        Command(C.MOVE_PATH, (1, 0, 0.45, 0.0, -0.2)),
    ],
    "bad argument at the arm": [Command(C.OPEN_FINGERS, (0.5,))],
    "rock task": list(rock_task(DEFAULT_WORLD).commands),
    "reinitialize after moves": [
        Command(C.CHANGE_SPEED, (0.5,)),
        Command(C.MOVE_JOINT, (1, 0.4)),
        Command(C.REINITIALIZE),
    ],
}


EXPECTED: dict[str, tuple[int, str] | None] = {
    "joint limit": (2, "JOINT_LIMIT"),
    "unreachable": (1, "UNREACHABLE"),
    "not grasping": (1, "NOT_GRASPING"),
    "no object": (2, "NO_OBJECT"),
    "collision (table, incremental)": (1, "COLLISION"),
    "collision (table, path)": (1, "COLLISION"),
    "collision with an added obstacle": (2, "COLLISION"),
    "bad argument at the arm": (1, "BAD_ARGUMENT"),
    "rock task": None,
    "reinitialize after moves": None,
}


def remote(commands: list[Command], world: WorldConfig = DEFAULT_WORLD) -> list[Outcome]:
    """Each command's outcome at a remote arm, sent one at a time, up to the first failure."""
    out: list[Outcome] = []

    async def main() -> None:
        arm = SimulatedArm(world)
        line = LinkConfig.symmetric(DirectionConfig(delay=0.2))
        async with (
            open_impaired_link(line) as (ctl, arm_side),
            Server(arm, ServerConfig(rtt_hint=0.5)) as server,
            trio.open_nursery() as nursery,
        ):
            nursery.start_soon(server.serve_stream, arm_side)
            async with connect_stream(ctl, identity="preview-test", incarnation=1) as client:
                for command in commands:
                    try:
                        result = await client.send(command)
                    except CommandFailed as exc:
                        out.append((exc.reason, exc.aux, exc.message, arm.state()))
                        break
                    out.append((FailureReason.NONE, result.aux, "", result.feedback))
            nursery.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    return out


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_preview_refuses_exactly_what_the_arm_refuses(name: str) -> None:
    commands = SCENARIOS[name]
    report = preview(commands)
    arm = remote(commands)
    assert len(arm) >= 1
    refusal = report.first_refusal
    assert EXPECTED[name] == (None if refusal is None else (refusal.index, refusal.reason.name))
    for predicted, (reason, aux, message, feedback) in zip(report.outcomes, arm, strict=False):
        assert predicted.reason is reason, predicted.message
        assert predicted.message == message
        if reason is not FailureReason.NONE or predicted.command.code is not C.WEIGH:
            assert predicted.aux == aux  # WEIGH's aux is a noisy reading
        assert predicted.feedback.joints == feedback.joints
        assert predicted.feedback.finger_opening == feedback.finger_opening
        assert predicted.feedback.p == feedback.p
    # Behind a refusal the arm would skip everything (the failure barrier).
    refused = [o for o in report.outcomes if not o.ok]
    if arm[-1][0] is FailureReason.NONE:
        assert report.ok
        assert len(arm) == len(commands)
        assert report.final == dataclasses.replace(arm[-1][3], error=report.final.error)
    else:
        assert refused[0].index == len(arm)
        assert all(o.reason is FailureReason.SKIPPED for o in refused[1:])
        assert len(refused) == len(commands) - len(arm) + 1


def test_the_rock_task_preview_reports_duration_and_final_state() -> None:
    report = preview(rock_task(DEFAULT_WORLD).commands)
    assert report.ok
    assert report.first_refusal is None
    assert report.grasped is None
    assert report.final.joints == pytest.approx(DEFAULT_WORLD.initial_joints, abs=1e-9)
    # Durations are whole control samples (125 Hz) and add up to the total.
    assert sum(o.duration for o in report.outcomes) == pytest.approx(report.duration)
    for o in report.outcomes:
        assert round(o.duration * 125, 6) == round(o.duration * 125)
    assert report.duration == pytest.approx(9.128)
    # Motion commands carry their predicted path: one sample per 10 control samples.
    path = report.outcomes[1].path
    assert len(path) == 26
    assert path[0][0] > 0


def test_preview_continues_from_a_model_state_holding_the_rock() -> None:
    task = rock_task(DEFAULT_WORLD).commands
    first = preview(task[:5])
    assert first.grasped == "rock"
    assert first.end_state.grasped == "rock"
    rest = preview(task[5:], first.end_state)
    whole = preview(task)
    assert rest.ok
    assert rest.final.joints == pytest.approx(whole.final.joints, abs=1e-12)
    assert [o.reason for o in rest.outcomes] == [o.reason for o in whole.outcomes[5:]]


def test_preview_of_a_rebased_state_believes_the_reported_grasp() -> None:
    task = rock_task(DEFAULT_WORLD).commands
    held = preview(task[:5]).final
    # A belief that never saw the grasp: the reported tactile switches put the rock in the hand.
    state = ModelState.initial(DEFAULT_WORLD).rebased(held)
    assert state.grasped == "rock"
    assert preview([Command(C.WEIGH)], state).ok
