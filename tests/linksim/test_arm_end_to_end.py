"""The seed-000 rock task end to end: client -> tcpstream -> serial socket over a
noisy Earth-Moon line -> tcpstream server -> SimulatedArm, on the virtual clock."""

from __future__ import annotations

import dataclasses
from functools import partial

import numpy as np
import pytest
import trio
import trio.testing

from linksim import DEFAULT_WORLD, LinkConfig, SimulatedArm, rock_task, serial_socket_pair
from linksim.arm import hand_frame
from tcpstream import (
    Command,
    CommandCode,
    CommandFailed,
    CommandResult,
    FailureReason,
    ServerConfig,
    connect_stream,
    serve_stream,
)

KEY = b"rock-task-end-to-end-key"

# The noisy-moon preset (2400 bit/s, 1.3 s each way, fades) with ten times
# its background byte-error rate, so the ARQ certainly has work to do in a
# session of only a few kilobytes.
NOISY_MOON = LinkConfig.preset("noisy-moon", seed=3)
LINE = LinkConfig.symmetric(dataclasses.replace(NOISY_MOON.a_to_b, byte_error_rate=1e-3), seed=3)


def test_rock_task_over_a_noisy_moon_serial_link() -> None:
    task = rock_task(DEFAULT_WORLD)
    arm = SimulatedArm(DEFAULT_WORLD)
    results: list[CommandResult] = []
    refused: list[CommandFailed] = []
    retransmissions: list[int] = []

    async def main() -> None:
        # 1.3 s each way at 2400 bit/s: a 216-byte packet takes ~1 s to serialise.
        config = ServerConfig(key=KEY, rtt_hint=6.0, telemetry_every=1250)
        async with (
            serial_socket_pair(LINE) as (client_end, server_end),
            trio.open_nursery() as nursery,
        ):
            nursery.start_soon(partial(serve_stream, arm, server_end, config=config))
            async with connect_stream(client_end, key=KEY, identity="operator") as client:
                # An unsafe move first: refused at the arm, reported across the link.
                try:
                    await client.move_to((0.55, 0.15, -0.40))
                except CommandFailed as exc:
                    refused.append(exc)
                for command in task.commands:
                    results.append(await client.send(command))
            for end in (client_end, server_end):
                retransmissions.append(end.statistics().link.retransmissions)
            nursery.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))

    # The refusal crossed the link with its reason and the seed-000 detail.
    assert [e.reason for e in refused] == [FailureReason.COLLISION]
    assert refused[0].aux[:2] == (6.0, 1.0)  # the hand, the table
    # Every task command completed; the arm's replies carry its state.
    assert len(results) == len(task.commands)
    weigh = results[[c.code for c in task.commands].index(CommandCode.WEIGH)]
    assert weigh.aux[0] == pytest.approx(task.expected_mass, abs=0.01)
    grasp = results[4].feedback
    assert (grasp.tactile_left, grasp.tactile_right) == (True, True)
    np.testing.assert_allclose(results[-1].feedback.joints, DEFAULT_WORLD.initial_joints)
    # The world at the far end: the rock in the bin, the hand home and open.
    rock = next(o for o in arm.world.objects if o.name == task.rock)
    np.testing.assert_allclose(rock.position[:2], task.bin_centre, atol=1e-9)
    assert rock.position[2] == pytest.approx(task.bin_top + 0.035)
    assert arm.grasped is None
    assert arm.state().finger_opening == pytest.approx(DEFAULT_WORLD.max_opening)
    # Exactly once: one execution per command although packets were lost and resent.
    assert sum(retransmissions) > 0, retransmissions
    stats = arm.statistics()
    assert (stats.commands, stats.completed, stats.failed) == (12, 11, 1)


def test_emergency_stop_over_the_link_halts_the_arm_mid_move() -> None:
    arm = SimulatedArm(DEFAULT_WORLD)
    goal = np.array(DEFAULT_WORLD.initial_joints) + np.array([-1.2, 0, 0, 0, 0, 0])
    outcome: list[CommandFailed] = []

    async def main() -> None:
        async with (
            serial_socket_pair("moon", seed=1) as (client_end, server_end),
            trio.open_nursery() as nursery,
        ):
            nursery.start_soon(partial(serve_stream, arm, server_end, rtt_hint=3.0))
            async with connect_stream(client_end) as client:
                # Slowly: the stop needs 1.3 s to reach the Moon, the news of
                # acceptance as long to come back.
                await client.change_speed(0.2)
                move = await client.submit(Command(CommandCode.MOVE_JOINTS, tuple(goal)))
                await move.accepted()
                await trio.sleep(0.5)  # the move is under way at the far end
                await client.emergency_stop()
                with pytest.raises(CommandFailed) as info:
                    await move.completed()
                outcome.append(info.value)
            nursery.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    assert outcome[0].reason is FailureReason.STOPPED
    # The 11.25 s move was stopped part way, the arm at rest and consistent.
    q = arm.joints
    home = np.array(DEFAULT_WORLD.initial_joints)
    assert goal[0] < q[0] < home[0]
    np.testing.assert_array_equal(q[1:], home[1:])
    np.testing.assert_allclose(arm.state().p, hand_frame(arm.model, q)[:3, 3])
    assert not arm.statistics().moving
    assert arm.state().error is FailureReason.STOPPED
