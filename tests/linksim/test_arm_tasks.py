"""The seed-000 rock task, executed directly on the simulated arm (virtual clock)."""

from __future__ import annotations

import numpy as np
import pytest
import trio
import trio.testing

from linksim import DEFAULT_WORLD, SimulatedArm, rock_task
from linksim.arm import hand_frame
from linksim.arm._kinematics import frame_from_psa, inverse
from tcpstream import Command, CommandCode, CommandFailed, CommandResult, FailureReason


def test_rock_task_moves_the_rock_into_the_bin_and_comes_home() -> None:
    task = rock_task(DEFAULT_WORLD)
    assert [c.code for c in task.commands] == [
        CommandCode.OPEN_FINGERS,
        CommandCode.MOVE_PATH,
        CommandCode.CENTER_FINGERS,
        CommandCode.MOVE_CARTESIAN_DELTA,
        CommandCode.CLOSE_FINGERS,
        CommandCode.SQUEEZE,
        CommandCode.WEIGH,
        CommandCode.MOVE_CARTESIAN_DELTA,
        CommandCode.MOVE_PATH,
        CommandCode.OPEN_FINGERS,
        CommandCode.MOVE_JOINTS,
    ]
    results: list[CommandResult] = []
    arm = SimulatedArm(DEFAULT_WORLD)

    async def main() -> None:
        for command in task.commands:
            results.append(await arm.execute(command))

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    by_code = dict(zip([c.code for c in task.commands], results, strict=False))
    # Centring removed the 2.5 cm horizontal error of the rock's estimate.
    centre = results[2]
    assert centre.aux[1] == pytest.approx(np.hypot(0.02, 0.015), abs=1e-9)
    np.testing.assert_allclose(centre.feedback.p[:2], (0.55, 0.15), atol=1e-9)
    # Grasped with both switches, the opening equal to the rock's size.
    closed = results[4].feedback
    assert (closed.tactile_left, closed.tactile_right) == (True, True)
    assert closed.finger_opening == pytest.approx(0.07)
    assert by_code[CommandCode.WEIGH].aux[0] == pytest.approx(task.expected_mass, abs=0.01)
    # The rock rests in the bin, the arm is home with open fingers.
    rock = next(o for o in arm.world.objects if o.name == task.rock)
    np.testing.assert_allclose(rock.position[:2], task.bin_centre, atol=1e-9)
    assert rock.position[2] == pytest.approx(task.bin_top + 0.035)
    np.testing.assert_allclose(arm.joints, DEFAULT_WORLD.initial_joints, atol=1e-12)
    final = arm.state()
    assert final.finger_opening == pytest.approx(DEFAULT_WORLD.max_opening)
    assert final.error is FailureReason.NONE
    assert arm.grasped is None
    stats = arm.statistics()
    assert (stats.completed, stats.failed, stats.collisions_refused) == (11, 0, 0)
    # About nine seconds of arm time, none of it on the wall clock.
    assert 8.0 < stats.motion_seconds < 10.0


def test_rock_task_rejects_unknown_names() -> None:
    with pytest.raises(KeyError, match="no object named 'gem'"):
        rock_task(DEFAULT_WORLD, rock="gem")
    with pytest.raises(KeyError, match="no obstacle named 'crate'"):
        rock_task(DEFAULT_WORLD, bin_name="crate")


def test_an_added_obstacle_is_refused_then_passed_over_an_intermediate_point() -> None:
    """Seed 000: the planner names the collision; the operator inserts a safe point."""

    async def main() -> None:
        arm = SimulatedArm(DEFAULT_WORLD)
        grasp = (0.55, 0.15, -0.315)
        drop = (0.38, -0.65, -0.315)
        await arm.execute(Command(CommandCode.MOVE_TO_POSITION, grasp))
        # A boulder reported by the vision system, where the hand would be
        # halfway through the direct move, reaching 2 cm above the hand.
        here = arm.state()
        frame = frame_from_psa(np.array(drop), np.array(here.s), np.array(here.a))
        goal = inverse(arm.model, frame, arm.joints)
        mid = hand_frame(arm.model, (arm.joints + goal) / 2)[:3, 3]
        boulder = (mid[0] - 0.05, mid[1] - 0.05, -0.35, mid[0] + 0.05, mid[1] + 0.05, mid[2] + 0.02)
        added = await arm.execute(Command(CommandCode.ADD_OBSTACLE, boulder))
        assert added.aux[0] == 4.0  # after ground, table, bin and rack
        with pytest.raises(CommandFailed) as info:
            await arm.execute(Command(CommandCode.MOVE_TO_POSITION, drop))
        assert info.value.reason is FailureReason.COLLISION
        link, obstacle, point, _ = info.value.aux
        assert (link, obstacle) == (6.0, 4.0)
        assert 1 <= point <= 10  # the boulder is at the halfway point (10 of 20)
        # Up, across, down: three moves that clear it.
        await arm.execute(Command(CommandCode.MOVE_CARTESIAN_DELTA, (0.0, 0.0, 0.25)))
        await arm.execute(Command(CommandCode.MOVE_TO_POSITION, (drop[0], drop[1], drop[2] + 0.25)))
        result = await arm.execute(Command(CommandCode.MOVE_CARTESIAN_DELTA, (0.0, 0.0, -0.25)))
        np.testing.assert_allclose(result.feedback.p, drop, atol=1e-9)

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))


def test_the_planner_previews_the_approach_without_trio() -> None:
    """A local predictive model calls the same planner the arm runs (no clock needed)."""
    from linksim.arm._planner import plan_cartesian_path
    from linksim.arm._world import World

    task = rock_task(DEFAULT_WORLD)
    approach = task.commands[1]
    arm = SimulatedArm(DEFAULT_WORLD)
    vias = np.array(approach.args[2:8]).reshape(2, 3)
    plan = plan_cartesian_path(
        arm.model,
        World(DEFAULT_WORLD),
        arm.joints,
        hand_frame(arm.model, arm.joints),
        vias,
        blend_time=DEFAULT_WORLD.blend_time,
        hand_speed=DEFAULT_WORLD.cartesian_speed,
        speed=1.0,
        rate_hz=125.0,
    )
    np.testing.assert_allclose(hand_frame(arm.model, plan.joints[-1])[:3, 3], vias[-1], atol=1e-9)

    async def main() -> None:
        await arm.execute(task.commands[0])
        result = await arm.execute(approach)
        assert result.aux[0] == plan.duration
        np.testing.assert_array_equal(arm.joints, plan.joints[-1])

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
