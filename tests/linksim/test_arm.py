"""SimulatedArm on the virtual clock: timing, refusals, incremental moves, paths, stops."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Awaitable, Callable

import numpy as np
import pytest
import trio
import trio.testing
from hypothesis import given, settings
from hypothesis import strategies as st

from linksim import DEFAULT_WORLD, SimulatedArm, WorldConfig
from linksim.arm import PUMA560, hand_frame
from linksim.arm._collision import first_collision
from linksim.arm._kinematics import (
    SINGULAR_THRESHOLDS,
    Singularity,
    frame_from_psa,
    inverse,
    singular_region,
)
from linksim.arm._trajectory import CHECKPOINTS, QUINTIC_PEAK_RATE
from tcpstream import Command, CommandCode, CommandFailed, Executor, FailureReason, Feedback
from tcpstream.commands import CommandFlags

HOME = np.array(DEFAULT_WORLD.initial_joints)
EMPTY = WorldConfig(initial_joints=DEFAULT_WORLD.initial_joints)
"""No obstacles, no objects: motions limited only by the arm."""


def run(fn: Callable[[], Awaitable[None]]) -> None:
    trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


async def refused(arm: SimulatedArm, command: Command) -> CommandFailed:
    with pytest.raises(CommandFailed) as info:
        await arm.execute(command)
    return info.value


def joints_of(fb: Feedback) -> np.ndarray:
    return np.array(fb.joints)


def test_the_arm_is_an_executor_at_125_hz_starting_at_home() -> None:
    arm = SimulatedArm()
    assert isinstance(arm, Executor)
    assert arm.control_rate_hz == 125.0
    fb = arm.state()
    np.testing.assert_array_equal(joints_of(fb), HOME)
    np.testing.assert_allclose(fb.a, (0.0, 0.0, -1.0), atol=1e-12)
    assert fb.finger_opening == 0.08
    assert fb.error is FailureReason.NONE
    assert (fb.tactile_left, fb.tactile_right) == (False, False)


def test_move_joints_takes_the_slowest_joints_time_on_the_virtual_clock() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        goal = HOME + np.array([0.8, -0.2, 0.1, 0.0, 0.3, 1.0])
        t0 = trio.current_time()
        result = await arm.execute(Command(CommandCode.MOVE_JOINTS, tuple(goal)))
        # Joint 1: 0.8 rad at 1 rad/s -> 15/8 * 0.8 s = 1.5 s = 187.5 -> 188 samples.
        assert trio.current_time() - t0 == pytest.approx(188 / 125)
        np.testing.assert_allclose(joints_of(result.feedback), goal, atol=1e-12)
        np.testing.assert_allclose(result.feedback.p, hand_frame(arm.model, goal)[:3, 3])
        assert arm.statistics().samples == 188

        # Change speed: the maximum-allowed-velocity vector is scaled.
        await arm.execute(Command(CommandCode.CHANGE_SPEED, (0.25,)))
        t0 = trio.current_time()
        await arm.execute(Command(CommandCode.MOVE_JOINT, (1.0, -0.8)))
        assert trio.current_time() - t0 == pytest.approx(
            math.ceil(QUINTIC_PEAK_RATE * 3.2 * 125) / 125
        )
        assert arm.state().joints[0] == pytest.approx(HOME[0])

    run(main)


def test_joint_limit_refusal_leaves_the_arm_still_and_sets_the_error_indicator() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        t0 = trio.current_time()
        err = await refused(arm, Command(CommandCode.MOVE_JOINT, (5.0, math.radians(-150))))
        assert err.reason is FailureReason.JOINT_LIMIT
        assert err.aux == pytest.approx(
            (5.0, HOME[4] - math.radians(150), math.radians(-100), math.radians(100))
        )
        assert trio.current_time() == t0
        assert err.feedback is not None
        assert err.feedback.error is FailureReason.JOINT_LIMIT
        np.testing.assert_array_equal(joints_of(err.feedback), HOME)
        assert arm.state().error is FailureReason.JOINT_LIMIT
        # The next command that succeeds clears the indicator.
        ok = await arm.execute(Command(CommandCode.STATUS))
        assert ok.feedback.error is FailureReason.NONE

    run(main)


def test_move_to_position_reaches_p_and_keeps_the_orientation_by_default() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        before = arm.state()
        result = await arm.execute(Command(CommandCode.MOVE_TO_POSITION, (0.5, 0.1, -0.1)))
        np.testing.assert_allclose(result.feedback.p, (0.5, 0.1, -0.1), atol=1e-9)
        np.testing.assert_allclose(result.feedback.s, before.s, atol=1e-9)
        np.testing.assert_allclose(result.feedback.a, before.a, atol=1e-9)
        # With a specified orientation: approach horizontally along +x.
        result = await arm.execute(
            Command(
                CommandCode.MOVE_TO_POSITION,
                (0.6, 0.0, 0.1, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0),
                CommandFlags.SPECIFIED_ORIENTATION,
            )
        )
        np.testing.assert_allclose(result.feedback.p, (0.6, 0.0, 0.1), atol=1e-9)
        np.testing.assert_allclose(result.feedback.a, (1.0, 0.0, 0.0), atol=1e-9)

    run(main)


def test_unreachable_and_singular_targets_are_refused_before_motion() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        err = await refused(arm, Command(CommandCode.MOVE_TO_POSITION, (1.5, 0.0, 0.0)))
        assert err.reason is FailureReason.UNREACHABLE
        assert "out of reach" in err.message
        # Hand pointing along the forearm: joint 5 at 0 (wrist singular).
        q = HOME.copy()
        q[4] = 0.01
        t = hand_frame(arm.model, q)
        args = (*t[:3, 3], *t[:3, 1], *t[:3, 2])
        err = await refused(
            arm, Command(CommandCode.MOVE_TO_POSITION, args, CommandFlags.SPECIFIED_ORIENTATION)
        )
        assert err.reason is FailureReason.SINGULAR
        assert err.aux == pytest.approx((3.0, 0.01, SINGULAR_THRESHOLDS[2], 0.0))
        np.testing.assert_array_equal(arm.joints, HOME)
        # Joint moves are how an operator gets there (seed 004: joint mode).
        await arm.execute(Command(CommandCode.MOVE_JOINTS, tuple(q)))
        np.testing.assert_allclose(arm.joints, q)

    run(main)


def test_transform_both_ways_without_moving() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        q = HOME + np.array([0.3, -0.2, 0.2, 0.4, 0.3, -0.5])
        fwd = await arm.execute(Command(CommandCode.TRANSFORM, tuple(q)))
        t = hand_frame(arm.model, q)
        np.testing.assert_allclose(fwd.feedback.p, t[:3, 3])
        np.testing.assert_allclose(fwd.feedback.s, t[:3, 1])
        np.testing.assert_allclose(fwd.feedback.a, t[:3, 2])
        back = await arm.execute(
            Command(
                CommandCode.TRANSFORM,
                (*fwd.feedback.p, *fwd.feedback.s, *fwd.feedback.a),
                CommandFlags.TO_JOINTS,
            )
        )
        np.testing.assert_allclose(joints_of(back.feedback), q, atol=1e-7)
        np.testing.assert_array_equal(arm.joints, HOME)
        assert trio.current_time() == 0.0

    run(main)


def test_collision_is_refused_with_the_link_obstacle_and_point() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        goal = HOME + np.array([1.2, 0.0, 0.0, 0.0, 0.0, 0.0])
        # An obstacle added at run time, on the hand's way round: a post at
        # 30 degrees of joint-1 travel.
        wall_q = HOME + np.array([0.6, 0.0, 0.0, 0.0, 0.0, 0.0])
        p = hand_frame(arm.model, wall_q)[:3, 3]
        box = (p[0] - 0.02, p[1] - 0.02, p[2] - 0.3, p[0] + 0.02, p[1] + 0.02, p[2] + 0.01)
        added = await arm.execute(Command(CommandCode.ADD_OBSTACLE, box))
        assert added.aux[:2] == (0.0, 1.0)
        err = await refused(arm, Command(CommandCode.MOVE_JOINTS, tuple(goal)))
        assert err.reason is FailureReason.COLLISION
        link, obstacle, point, _ = err.aux
        # The oracle: the first of the twenty points (u = i/20 of the quintic)
        # whose links touch the box, checked one checkpoint at a time.
        boxes = arm.world.obstacles + np.array([-1, 1, -1, 1, -1, 1]) * EMPTY.clearance
        expected = None
        for i in range(1, CHECKPOINTS + 1):
            u = i / CHECKPOINTS
            q = HOME + (goal - HOME) * u**3 * (10 - 15 * u + 6 * u * u)
            hit = first_collision(arm.model, q[None, :], boxes)
            if hit is not None:
                expected = (float(hit.link), float(hit.obstacle), float(i))
                break
        assert expected is not None
        assert (link, obstacle, point) == expected
        assert link == 6.0
        assert f"trajectory point {int(point)} of 20" in err.message
        assert "intermediate point" in err.message
        np.testing.assert_array_equal(arm.joints, HOME)
        assert arm.statistics().collisions_refused == 1
        # Going round in two steps, over the post, works.
        up = HOME + np.array([0.0, 0.0, 0.25, 0.0, -0.25, 0.0])
        await arm.execute(Command(CommandCode.MOVE_JOINTS, tuple(up)))
        await arm.execute(Command(CommandCode.MOVE_JOINT, (1.0, 1.2)))

    run(main)


def test_index_mode_and_small_incremental_moves() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        before = arm.state()
        result = await arm.execute(Command(CommandCode.MOVE_CARTESIAN_DELTA, (0.0,) * 6))
        assert result.feedback == before
        assert trio.current_time() == 0.0
        result = await arm.execute(Command(CommandCode.MOVE_CARTESIAN_DELTA, (0.01, -0.02, 0.005)))
        np.testing.assert_allclose(
            np.array(result.feedback.p) - before.p, (0.01, -0.02, 0.005), atol=1e-9
        )
        np.testing.assert_allclose(result.feedback.a, before.a, atol=1e-9)
        # A rotation about the base z axis turns S and keeps A (pointing down).
        result = await arm.execute(
            Command(CommandCode.MOVE_CARTESIAN_DELTA, (0, 0, 0, 0, 0, math.radians(10)))
        )
        c, s = math.cos(math.radians(10)), math.sin(math.radians(10))
        sx, sy, sz = before.s
        np.testing.assert_allclose(
            result.feedback.s, (c * sx - s * sy, s * sx + c * sy, sz), atol=1e-9
        )

    run(main)


def test_incremental_moves_bounce_off_a_singular_region_without_pose_change() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        # Tilt the hand until the wrist is 0.08 rad from singular, then try
        # to tilt it 0.06 rad further (into the 0.05 rad region).
        q = HOME.copy()
        q[4] = -0.08
        await arm.execute(Command(CommandCode.MOVE_JOINTS, tuple(q)))
        t = hand_frame(arm.model, q)
        # Joint 5 turns about the hand's -S ... find the rotation axis numerically.
        q2 = q.copy()
        q2[4] = -0.02
        t2 = hand_frame(arm.model, q2)
        rot = t2[:3, :3] @ t[:3, :3].T
        angle = math.acos((np.trace(rot) - 1) / 2)
        axis = np.array([rot[2, 1] - rot[1, 2], rot[0, 2] - rot[2, 0], rot[1, 0] - rot[0, 1]])
        axis /= 2 * math.sin(angle)
        delta = (*(t2[:3, 3] - t[:3, 3]), *(axis * angle))
        err = await refused(arm, Command(CommandCode.MOVE_CARTESIAN_DELTA, delta))
        assert err.reason is FailureReason.SINGULAR
        assert err.aux[0] == float(Singularity.WRIST)
        assert err.aux[1] == pytest.approx(0.02, abs=1e-6)
        assert "POSE_CHANGE" in err.message
        np.testing.assert_array_equal(arm.joints, q)
        # With the pose-change button the arm goes in.
        await arm.execute(
            Command(CommandCode.MOVE_CARTESIAN_DELTA, delta, CommandFlags.POSE_CHANGE)
        )
        region = singular_region(arm.model, arm.joints)
        assert region is not None
        assert region[0] is Singularity.WRIST
        np.testing.assert_allclose(hand_frame(arm.model, arm.joints), t2, atol=1e-9)

    run(main)


def test_via_point_path_runs_level_2_and_ends_on_the_last_point() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        start = np.array(arm.state().p)
        vias = (0.5, 0.1, -0.05, 0.55, 0.2, -0.2, 0.45, -0.1, -0.1)
        before_a = arm.state().a
        t0 = trio.current_time()
        result = await arm.execute(Command(CommandCode.MOVE_PATH, (3.0, 0.0, *vias)))
        duration, corrections, _, _ = result.aux
        assert trio.current_time() - t0 == pytest.approx(duration)
        assert corrections == 4.0  # one per straight segment, the end's zero-length one included
        np.testing.assert_allclose(result.feedback.p, vias[6:9], atol=1e-9)
        np.testing.assert_allclose(result.feedback.a, before_a, atol=1e-9)
        # The path's length at 0.25 m/s, plus one blend (start-up and stop).
        lengths = np.linalg.norm(
            np.diff(np.vstack([start, np.reshape(vias, (3, 3))]), axis=0), axis=1
        )
        assert duration >= lengths.sum() / 0.25
        assert duration <= lengths.sum() / 0.25 + 0.2 + 4 / 125

    run(main)


def test_path_through_an_obstacle_is_refused_at_its_checkpoint() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        await arm.execute(Command(CommandCode.ADD_OBSTACLE, (0.55, -0.5, -0.6, 0.6, 0.5, 0.03)))
        err = await refused(arm, Command(CommandCode.MOVE_PATH, (1.0, 0.0, 0.7, 0.0, 0.0)))
        assert err.reason is FailureReason.COLLISION
        link, obstacle, point, _ = err.aux
        assert (link, obstacle) == (6.0, 0.0)
        assert 1 <= point <= 20
        np.testing.assert_array_equal(arm.joints, HOME)

    run(main)


def test_emergency_stop_by_cancellation_halts_within_one_sample() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        goal = HOME + np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        with trio.move_on_after(0.5) as scope:
            await arm.execute(Command(CommandCode.MOVE_JOINTS, tuple(goal)))
        assert scope.cancelled_caught
        arm.halt(FailureReason.STOPPED)
        q = arm.joints
        # 62 samples of 1/125 s were played before the cancel at 0.5 s.
        u = 62 / math.ceil(QUINTIC_PEAK_RATE * 125)
        np.testing.assert_allclose(q[0], HOME[0] + u**3 * (10 - 15 * u + 6 * u * u), atol=1e-12)
        fb = arm.state()
        assert fb.error is FailureReason.STOPPED
        np.testing.assert_allclose(fb.p, hand_frame(arm.model, q)[:3, 3])
        await trio.sleep(1.0)
        np.testing.assert_array_equal(arm.joints, q)  # at rest
        assert not arm.statistics().moving
        # The arm takes new commands from where it stopped.
        await arm.execute(Command(CommandCode.MOVE_JOINTS, tuple(goal)))
        np.testing.assert_allclose(arm.joints, goal)

    run(main)


def test_halt_during_a_move_fails_it_with_stopped_at_once() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        goal = HOME + np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        failures: list[CommandFailed] = []
        stop_time = 0.3  # sample 37.5: between two samples

        async def mover() -> None:
            try:
                await arm.execute(Command(CommandCode.MOVE_JOINTS, tuple(goal)))
            except CommandFailed as exc:
                failures.append(exc)
                assert trio.current_time() == pytest.approx(stop_time)

        async with trio.open_nursery() as nursery:
            nursery.start_soon(mover)
            await trio.sleep(stop_time)
            arm.halt(FailureReason.DEADMAN)
            arm.halt(FailureReason.DEADMAN)  # idempotent
        assert [f.reason for f in failures] == [FailureReason.DEADMAN]
        assert "halted after sample 37 of" in failures[0].message
        assert failures[0].feedback is not None
        assert failures[0].feedback.error is FailureReason.DEADMAN
        assert arm.statistics().samples == 37

    run(main)


def test_telemetry_every_tenth_sample_of_motion() -> None:
    async def main() -> None:
        seen: list[tuple[float, Feedback]] = []
        arm = SimulatedArm(EMPTY, telemetry=lambda fb: seen.append((trio.current_time(), fb)))
        await arm.execute(Command(CommandCode.MOVE_JOINT, (6.0, 1.0)))  # 0.9375 s -> 118 samples
        assert len(seen) == 11
        assert [t for t, _ in seen] == pytest.approx([(10 * i) / 125 for i in range(1, 12)])
        assert seen[-1][1].joints[5] < HOME[5] + 1.0

    run(main)


def test_session_commands_are_harmless_no_ops_and_reinitialize_goes_home() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        await arm.execute(Command(CommandCode.CHANGE_SPEED, (0.5,)))
        await arm.execute(Command(CommandCode.MOVE_JOINT, (2.0, -0.3)))
        for code in (CommandCode.EMERGENCY_STOP, CommandCode.TERMINATE):
            before = arm.state()
            result = await arm.execute(Command(code))
            assert result.feedback == before
        await arm.execute(Command(CommandCode.REINITIALIZE))
        np.testing.assert_allclose(arm.joints, HOME)
        assert arm.statistics().speed == 1.0

    run(main)


def test_bad_arguments_are_refused_by_the_executor_too() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        err = await refused(arm, Command(CommandCode.CHANGE_SPEED, (1.5,)))
        assert (err.reason, err.aux[0]) == (FailureReason.BAD_ARGUMENT, 0.0)
        err = await refused(arm, Command(CommandCode.MOVE_JOINTS, (math.nan,)))
        assert err.reason is FailureReason.BAD_ARGUMENT
        err = await refused(arm, Command(CommandCode.OPEN_FINGERS, (0.5,)))
        assert err.reason is FailureReason.BAD_ARGUMENT
        assert arm.statistics().failed == 3

    run(main)


def test_ik_solution_for_the_task_poses_is_the_elbow_up_hand_down_branch() -> None:
    arm = SimulatedArm()
    target = frame_from_psa(
        np.array([0.55, 0.15, -0.315]), np.array([0, 1.0, 0]), np.array([0, 0, -1.0])
    )
    q = inverse(arm.model, target, HOME)
    assert q[2] < -math.pi  # elbow up, as at home
    assert singular_region(arm.model, q) is None


def test_halt_of_an_arm_at_rest_leaves_the_error_indicator_alone() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        arm.halt(FailureReason.STOPPED)  # e.g. the server shutting down
        assert arm.state().error is FailureReason.NONE
        assert arm.statistics().halts == 1

    run(main)


@settings(max_examples=40)
@given(st.tuples(*(st.floats(lo, hi) for lo, hi in zip(PUMA560.lower, PUMA560.upper, strict=True))))
def test_any_reachable_pose_is_reached_exactly_in_the_planned_time(q: tuple[float, ...]) -> None:
    """Property: in an empty world every non-singular pose the arm can hold, it reaches."""
    arm = SimulatedArm(EMPTY)
    target = hand_frame(arm.model, np.array(q))
    if singular_region(arm.model, np.array(q)) is not None:
        return
    args = (*target[:3, 3], *target[:3, 1], *target[:3, 2])

    async def main() -> None:
        result = await arm.execute(
            Command(CommandCode.MOVE_TO_POSITION, args, CommandFlags.SPECIFIED_ORIENTATION)
        )
        np.testing.assert_allclose(hand_frame(arm.model, arm.joints), target, atol=1e-7)
        np.testing.assert_allclose(result.feedback.p, target[:3, 3], atol=1e-7)
        # Seed 000's timing: the slowest joint at its maximum velocity.
        vmax = np.array(EMPTY.max_joint_velocity)
        slowest = QUINTIC_PEAK_RATE * np.max(np.abs(arm.joints - HOME) / vmax)
        assert trio.current_time() == pytest.approx(math.ceil(slowest * 125 - 1e-9) / 125)

    run(main)


def test_path_to_an_unreachable_via_point_names_the_point() -> None:
    async def main() -> None:
        arm = SimulatedArm(EMPTY)
        path = (2.0, 0.0, 0.5, 0.0, 0.0, 1.5, 0.0, -0.3)
        err = await refused(arm, Command(CommandCode.MOVE_PATH, path))
        assert err.reason is FailureReason.UNREACHABLE
        assert err.message.startswith("via point 2: the hand pose is out of reach")
        assert err.aux[0] == pytest.approx(float(np.linalg.norm([1.5, 0.0, -0.1])))
        np.testing.assert_array_equal(arm.joints, HOME)

    run(main)


command_strategy = st.one_of(
    st.builds(
        lambda j, d: Command(CommandCode.MOVE_JOINT, (float(j), d)),
        st.integers(1, 6),
        st.floats(-3.0, 3.0),
    ),
    st.builds(lambda f: Command(CommandCode.CHANGE_SPEED, (f,)), st.floats(0.2, 1.0)),
    st.builds(
        lambda d: Command(CommandCode.MOVE_CARTESIAN_DELTA, d),
        st.tuples(*(st.floats(-0.2, 0.2),) * 6),
    ),
    st.builds(
        lambda p: Command(CommandCode.MOVE_TO_POSITION, p),
        st.tuples(st.floats(0.1, 1.0), st.floats(-0.5, 0.5), st.floats(-0.5, 0.3)),
    ),
    st.builds(
        lambda p: Command(CommandCode.MOVE_PATH, (1.0, 0.0, *p)),
        st.tuples(st.floats(0.2, 0.9), st.floats(-0.4, 0.4), st.floats(-0.4, 0.2)),
    ),
    st.sampled_from(
        [
            Command(CommandCode.CLOSE_FINGERS),
            Command(CommandCode.OPEN_FINGERS),
            Command(CommandCode.REINITIALIZE),
            Command(CommandCode.ADD_OBSTACLE, (0.45, -0.05, -0.4, 0.55, 0.05, -0.2)),
        ]
    ),
)


@settings(max_examples=25)
@given(st.lists(st.tuples(command_strategy, st.booleans()), min_size=1, max_size=8))
def test_random_command_sequences_keep_the_arm_consistent(
    script: list[tuple[Command, bool]],
) -> None:
    """Fuzz: whatever the commands and stops, every sample is within the limits and
    the feedback matches the joints; refusals leave the arm where it was."""
    samples: list[Feedback] = []
    config = dataclasses.replace(DEFAULT_WORLD, telemetry_every=1)
    arm = SimulatedArm(config, telemetry=samples.append)
    lo, hi = np.array(PUMA560.lower), np.array(PUMA560.upper)

    async def main() -> None:
        for command, stop_early in script:
            before = arm.joints
            failure: CommandFailed | None = None
            with trio.move_on_after(0.3 if stop_early else math.inf) as scope:
                try:
                    await arm.execute(command)
                except CommandFailed as exc:
                    failure = exc
            if failure is not None:
                assert failure.feedback is not None
                assert failure.feedback.error is failure.reason
                # A refusal happens at planning time: nothing moved.
                np.testing.assert_array_equal(arm.joints, before)
            if scope.cancelled_caught:
                arm.halt(FailureReason.STOPPED)
                assert arm.state().error is FailureReason.STOPPED
            assert not arm.statistics().moving
            fb = arm.state()
            np.testing.assert_allclose(fb.p, hand_frame(arm.model, arm.joints)[:3, 3], atol=1e-12)

    run(main)
    for fb in samples:
        q = np.array(fb.joints)
        assert np.all(q >= lo - 1e-9)
        assert np.all(q <= hi + 1e-9)
        np.testing.assert_allclose(fb.p, hand_frame(PUMA560, q)[:3, 3], atol=1e-12)
