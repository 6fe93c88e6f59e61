"""The predictive model: prediction equals the remote's final state, corrections converge.

Whole-chain runs use ``linksim console --virtual``'s runner (arm server,
impaired link, client and console in one process on trio's virtual clock);
the remote arm's world can differ from the model's to make divergence.
"""

from __future__ import annotations

import dataclasses
import io
import math
import pathlib

import pytest

from linksim import (
    DEFAULT_WORLD,
    ConsoleOptions,
    DemoOptions,
    DirectionConfig,
    LinkConfig,
    WorldConfig,
    rock_task,
    run_console,
)
from linksim.control import Predictor, preview, read_log
from linksim.demo import ConsoleResult
from tcpstream import Command, CommandCode

TASK = rock_task(DEFAULT_WORLD).commands
MOON = LinkConfig.symmetric(DirectionConfig(delay=1.3))


def console_run(
    link: LinkConfig, arm_world: WorldConfig | None = None, log: pathlib.Path | None = None
) -> ConsoleResult:
    demo = DemoOptions(link=link, virtual=True, live=False)
    options = ConsoleOptions(
        demo, out=io.StringIO(), arm_world=arm_world, log=None if log is None else str(log)
    )
    return run_console(options)


def test_prediction_equals_the_remote_final_state_on_a_clean_link(tmp_path: pathlib.Path) -> None:
    result = console_run(MOON, log=tmp_path / "run.jsonl")
    assert result.ok, result.error
    session = result.session
    assert session is not None
    assert session.run is not None
    p = session.predictor
    final = session.run.final_feedback
    assert final is not None
    assert p.predicted == final
    assert p.confirmed == final
    assert p.in_flight == ()
    # Every completion matched the model exactly; telemetry lay on the predicted path.
    completions = [d for d in p.records if d.source == "completion"]
    assert [d.index for d in completions] == list(range(1, len(TASK) + 1))
    assert all(d.joint_error == 0.0 and d.position_error == 0.0 for d in completions)
    assert p.flagged == 0
    assert session.telemetry_samples > 100
    assert p.max_joint_error < math.radians(0.5)
    # While commands were in flight the predicted end state was already the final one.
    predicted = [s for s in read_log(tmp_path / "run.jsonl").states if s["source"] == "predicted"]
    assert len(predicted) == len(TASK)
    for record in predicted:
        assert record["joints_rad"] == pytest.approx(final.joints, abs=1e-6)


def test_prediction_converges_on_a_lossy_link() -> None:
    result = console_run(LinkConfig.preset("noisy-moon"))
    assert result.ok, result.error
    assert result.link["retransmissions"] >= 1  # the line did lose something
    session = result.session
    assert session is not None
    assert session.run is not None
    p = session.predictor
    assert p.predicted == session.run.final_feedback
    assert p.flagged == 0
    assert p.comparisons >= len(TASK)


def test_a_misplaced_object_is_flagged_and_the_model_recovers() -> None:
    # The rock is 3 cm further out than the model believes: centring the
    # fingers (#3) moves the hand 3 cm more at the arm than in the model.
    rock = dataclasses.replace(DEFAULT_WORLD.objects[0], position=(0.58, 0.15, -0.315))
    arm_world = dataclasses.replace(DEFAULT_WORLD, objects=(rock, *DEFAULT_WORLD.objects[1:]))
    result = console_run(MOON, arm_world=arm_world)
    assert result.ok, result.error
    session = result.session
    assert session is not None
    assert session.run is not None
    p = session.predictor
    flagged = [d for d in p.records if d.flagged]
    # Command 3's completion is flagged; a telemetry sample taken while the
    # hand went the extra 3 cm may be flagged before it (whether one is sent
    # in that stretch depends on when the line is free), and nothing else.
    assert [(d.source, d.index) for d in flagged if d.source == "completion"] == [("completion", 3)]
    assert all(d.source == "telemetry" and d.t <= flagged[-1].t for d in flagged[:-1])
    assert flagged[-1].position_error == pytest.approx(0.03, abs=1e-6)
    # Corrected to the arm's report, the model predicts every later command exactly.
    later = [d for d in p.records if d.source == "completion" and d.index and d.index > 3]
    assert len(later) == len(TASK) - 3
    assert all(d.joint_error == 0.0 for d in later)
    assert p.predicted == session.run.final_feedback


def test_predictor_fed_by_hand() -> None:
    p = Predictor(DEFAULT_WORLD)
    for i, command in enumerate(TASK[:3], start=1):
        p.sent(i, command)
    plan = preview(TASK[:3])
    assert p.predicted == plan.final
    assert p.in_flight == (1, 2, 3)
    # Command 1 completes as predicted.
    d1 = p.completed(1, 10.0, feedback=plan.outcomes[0].feedback)
    assert d1 is not None
    assert not d1.flagged
    # Command 2 ends 2 degrees off on joint 1: flagged, and the base moves there.
    off = plan.outcomes[1].feedback
    moved = dataclasses.replace(off, joints=(off.joints[0] + math.radians(2), *off.joints[1:]))
    d2 = p.completed(2, 11.0, feedback=moved)
    assert d2 is not None
    assert d2.flagged
    assert d2.joint_error == pytest.approx(math.radians(2))
    assert p.base.world.initial_joints == moved.joints
    assert p.confirmed == moved
    # An outcome the model did not predict is flagged with both verdicts.
    d3 = p.completed(3, 12.0, failure="NO_OBJECT")
    assert d3 is not None
    assert d3.outcome == "model predicted completion, arm reported NO_OBJECT"
    assert d3.flagged
    # A refused command did not move the arm: the base stays at command 2's report.
    assert p.base.world.initial_joints == moved.joints
    assert p.predicted == dataclasses.replace(p.predicted, joints=moved.joints)
    assert p.completed(99, 13.0) is None
    assert (p.comparisons, p.flagged) == (3, 2)


def test_a_skipped_command_is_not_a_divergence() -> None:
    p = Predictor(DEFAULT_WORLD)
    p.sent(1, Command(CommandCode.SQUEEZE, (10.0,)))
    p.sent(2, Command(CommandCode.WEIGH))
    assert p.plan is not None
    assert [o.reason.name for o in p.plan.outcomes] == ["NOT_GRASPING", "SKIPPED"]
    d = p.completed(1, 1.0, failure="NOT_GRASPING")
    assert d is not None
    assert not d.flagged
    assert p.completed(2, 2.0, failure="SKIPPED") is None
    assert p.comparisons == 1


def test_a_missing_object_is_an_unpredicted_refusal_and_the_arm_stays_put() -> None:
    # The arm's table has no rock (someone already moved it): centring fails there.
    arm_world = dataclasses.replace(DEFAULT_WORLD, objects=DEFAULT_WORLD.objects[1:])
    result = console_run(MOON, arm_world=arm_world)
    assert not result.ok
    assert result.error is not None
    assert "refused command #3 (center fingers)" in result.error
    session = result.session
    assert session is not None
    assert session.run is not None
    p = session.predictor
    refusal = next(d for d in p.records if d.source == "completion" and d.index == 3)
    assert refusal.outcome == "model predicted completion, arm reported NO_OBJECT"
    # The prediction stays where the arm stopped: after command 2's path.
    after_path = session.run.records[1].result
    assert after_path is not None
    predicted = p.predicted
    assert predicted is not None
    assert predicted.joints == after_path.feedback.joints
    assert p.in_flight == ()
