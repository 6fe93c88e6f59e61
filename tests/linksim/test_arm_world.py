"""World configuration (dataclass and TOML), grasping, weighing, centring, releasing."""

from __future__ import annotations

import dataclasses
import math
import pathlib
from collections.abc import Awaitable, Callable

import numpy as np
import pytest
import trio
import trio.testing

from linksim import DEFAULT_WORLD, ConfigError, SimulatedArm, WorldConfig
from linksim.arm import ObjectSpec, ObstacleSpec
from linksim.arm._world import MAX_OBSTACLES
from tcpstream import Command, CommandCode, CommandFailed, FailureReason

HOME = DEFAULT_WORLD.initial_joints

TOML = """
initial_joints = [0.0, 1.5707963267948966, -3.490658503988659, 0.0, -1.2217304763960306, 0.0]
speed = 0.5
weigh_noise = 0.01
seed = 3

[[obstacles]]
name = "table"
min = [0.25, -0.75, -0.672]
max = [0.95, 0.75, -0.35]

[[objects]]
name = "rock"
position = [0.55, 0.15, -0.315]
size = 0.07
mass = 0.85
"""


def run(fn: Callable[[], Awaitable[None]]) -> None:
    trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


def test_toml_world_loads_from_text_and_file(tmp_path: pathlib.Path) -> None:
    config = WorldConfig.from_toml(TOML)
    assert config.speed == 0.5
    assert config.obstacles == (ObstacleSpec("table", (0.25, -0.75, -0.672), (0.95, 0.75, -0.35)),)
    assert config.objects == (ObjectSpec("rock", (0.55, 0.15, -0.315), 0.07, 0.85),)
    assert config.initial_joints == pytest.approx(HOME)
    path = tmp_path / "world.toml"
    path.write_text(TOML)
    assert WorldConfig.from_toml(path) == config


def test_to_toml_round_trips() -> None:
    assert WorldConfig.from_toml(DEFAULT_WORLD.to_toml()) == DEFAULT_WORLD
    odd = WorldConfig(
        objects=(ObjectSpec('a "quoted"\\ name\nwith a newline', (0, 0, 0), 0.1, 1.0),),
        initial_joints=HOME,
        max_joint_velocity=(0.5, 0.5, 0.5, 1.0, 1e-3, 1.0),
    )
    assert WorldConfig.from_toml(odd.to_toml()) == odd


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("speed = 0", "speed must be a finite number > 0 and <= 1.0"),
        ("initial_joints = [0, 0]", "initial_joints must be six finite angles"),
        ("colour = 'red'", "unknown world setting(s): colour"),
        ("[[obstacles]]\nname = 'x'\nmin = [0, 0, 0]\nmax = [1, 0, 1]", "obstacle 'x': max y"),
        ("[[obstacles]]\nmin = [0, 0, 0]", "obstacles[0] needs min and max"),
        ("[[objects]]\nname = 'r'\nposition = [0, 0, 0]\nsize = 0.1", "objects[0] needs exactly"),
        ("[[objects]]\nname='r'\nposition=[0,0]\nsize=0.1\nmass=1", "position must be three"),
        ("[[objects]]\nname='r'\nposition=[0,0,0]\nsize=0.1\nmass=-1", "object 'r' mass"),
        ("telemetry_every = 0", "telemetry_every must be an integer 1..10000"),
        ("initial_opening = 0.2", "initial_opening must be in [0, max_opening=0.08]"),
        ("speed = ", "world TOML does not parse"),
    ],
)
def test_bad_world_settings_name_the_field(text: str, message: str) -> None:
    with pytest.raises(ConfigError) as info:
        WorldConfig.from_toml(text)
    assert message in str(info.value)


def test_initial_pose_outside_limits_or_inside_an_obstacle_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="initial_joints: joint 5"):
        SimulatedArm(WorldConfig(initial_joints=(0, 0, 0, 0, 2.0, 0)))
    box = ObstacleSpec("crate", (0.3, -0.3, -0.2), (0.5, 0.0, 0.2))
    with pytest.raises(ConfigError, match="inside obstacle 'crate'"):
        SimulatedArm(WorldConfig(initial_joints=HOME, obstacles=(box,)))


def test_the_obstacle_array_is_bounded() -> None:
    async def main() -> None:
        arm = SimulatedArm(WorldConfig(initial_joints=HOME))
        for _ in range(MAX_OBSTACLES):
            await arm.execute(Command(CommandCode.ADD_OBSTACLE, (5, 5, 5, 6, 6, 6)))
        with pytest.raises(CommandFailed) as info:
            await arm.execute(Command(CommandCode.ADD_OBSTACLE, (5, 5, 5, 6, 6, 6)))
        assert info.value.reason is FailureReason.BAD_ARGUMENT
        assert "full" in info.value.message

    run(main)


def test_close_on_nothing_shuts_the_fingers_and_leaves_the_switches_open() -> None:
    async def main() -> None:
        arm = SimulatedArm(WorldConfig(initial_joints=HOME))
        t0 = trio.current_time()
        result = await arm.execute(Command(CommandCode.CLOSE_FINGERS))
        # 0.08 m at 0.05 m/s on the quintic: 15/8 * 1.6 s = 3 s.
        assert trio.current_time() - t0 == pytest.approx(3.0)
        assert result.feedback.finger_opening == pytest.approx(0.0)
        assert not result.feedback.tactile_left
        for code in (CommandCode.WEIGH, CommandCode.SQUEEZE):
            with pytest.raises(CommandFailed) as info:
                await arm.execute(Command(code, (10.0,)))
            assert info.value.reason is FailureReason.NOT_GRASPING
            assert "close them first" in info.value.message

    run(main)


def test_center_close_squeeze_weigh_move_and_release() -> None:
    async def main() -> None:
        config = WorldConfig(
            initial_joints=HOME,
            objects=(ObjectSpec("rock", (0.42, -0.16, -0.05), 0.06, 0.85),),
            weigh_noise=0.01,
            seed=11,
        )
        arm = SimulatedArm(config)
        # The rock is 0.11 m below the fingertips: closing grasps nothing.
        empty = await arm.execute(Command(CommandCode.CLOSE_FINGERS))
        assert empty.feedback.finger_opening == pytest.approx(0.0)
        await arm.execute(Command(CommandCode.OPEN_FINGERS, (0.0,)))
        centred = await arm.execute(Command(CommandCode.CENTER_FINGERS))
        assert centred.aux[0] == 0.0
        assert centred.aux[1] == pytest.approx(
            math.hypot(0.42 - 0.39882, -0.16 + 0.15005), abs=1e-4
        )
        p = np.array(centred.feedback.p)
        np.testing.assert_allclose(p[:2], (0.42, -0.16), atol=1e-9)
        # Down the approach vector onto the rock.
        await arm.execute(Command(CommandCode.MOVE_CARTESIAN_DELTA, (0, 0, -0.05 - p[2])))
        closed = await arm.execute(Command(CommandCode.CLOSE_FINGERS))
        assert closed.feedback.finger_opening == pytest.approx(0.06)
        assert (closed.feedback.tactile_left, closed.feedback.tactile_right) == (True, True)
        assert arm.grasped == "rock"
        squeezed = await arm.execute(Command(CommandCode.SQUEEZE, (25.0,)))
        assert squeezed.aux[0] == 25.0
        assert arm.grip_force == 25.0
        with pytest.raises(CommandFailed) as info:
            await arm.execute(Command(CommandCode.SQUEEZE, (500.0,)))
        assert info.value.reason is FailureReason.BAD_ARGUMENT
        weights = [(await arm.execute(Command(CommandCode.WEIGH))).aux for _ in range(40)]
        masses = np.array([w[0] for w in weights])
        assert weights[0][1] == 0.01
        assert abs(masses.mean() - 0.85) < 4 * 0.01 / math.sqrt(40)
        assert 0.002 < masses.std() < 0.02
        # The rock moves with the hand ...
        await arm.execute(Command(CommandCode.MOVE_CARTESIAN_DELTA, (0.1, 0.1, 0.2)))
        rock = arm.world.objects[0]
        np.testing.assert_allclose(rock.position, np.array(arm.state().p), atol=1e-9)
        # ... and falls to the floor when released (nothing else below it).
        opened = await arm.execute(Command(CommandCode.OPEN_FINGERS, (0.0,)))
        assert not opened.feedback.tactile_left
        assert arm.statistics().grasping is None
        np.testing.assert_allclose(rock.position[:2], (0.52, -0.06), atol=1e-9)
        assert rock.position[2] == pytest.approx(config.floor_z + 0.03)

    run(main)


def test_weighing_is_reproducible_from_the_seed() -> None:
    async def weigh_once() -> float:
        config = WorldConfig(
            initial_joints=HOME,
            objects=(ObjectSpec("rock", (0.39882, -0.15005, 0.065), 0.06, 0.85),),
            weigh_noise=0.05,
            seed=5,
        )
        arm = SimulatedArm(config)
        await arm.execute(Command(CommandCode.CLOSE_FINGERS))
        return (await arm.execute(Command(CommandCode.WEIGH))).aux[0]

    results: list[float] = []

    async def main() -> None:
        results.append(await weigh_once())
        results.append(await weigh_once())

    run(main)
    assert results[0] == results[1] != 0.85


def test_center_fingers_fails_with_nothing_in_range() -> None:
    async def main() -> None:
        config = WorldConfig(
            initial_joints=HOME, objects=(ObjectSpec("far", (0.4, -0.15, -0.3), 0.06, 1.0),)
        )
        arm = SimulatedArm(config)
        with pytest.raises(CommandFailed) as info:
            await arm.execute(Command(CommandCode.CENTER_FINGERS))
        assert info.value.reason is FailureReason.NO_OBJECT
        assert "intermediate point" in info.value.message
        assert trio.current_time() == 0.0

    run(main)


def test_object_wider_than_the_opening_is_not_grasped() -> None:
    async def main() -> None:
        config = WorldConfig(
            initial_joints=HOME,
            initial_opening=0.04,
            objects=(ObjectSpec("boulder", (0.39882, -0.15005, 0.065), 0.06, 9.0),),
        )
        arm = SimulatedArm(config)
        result = await arm.execute(Command(CommandCode.CLOSE_FINGERS))
        assert result.feedback.finger_opening == pytest.approx(0.0)
        assert arm.grasped is None

    run(main)


def test_narrowing_the_opening_stops_on_an_object_between_the_fingers() -> None:
    async def main() -> None:
        config = WorldConfig(
            initial_joints=HOME,
            objects=(ObjectSpec("rock", (0.39882, -0.15005, 0.065), 0.06, 0.85),),
        )
        arm = SimulatedArm(config)
        wider = await arm.execute(Command(CommandCode.OPEN_FINGERS, (0.07,)))
        assert wider.feedback.finger_opening == pytest.approx(0.07)
        assert arm.statistics().grasping is None
        gripped = await arm.execute(Command(CommandCode.OPEN_FINGERS, (0.03,)))
        assert gripped.feedback.finger_opening == pytest.approx(0.06)
        assert gripped.feedback.tactile_left
        assert arm.grasped == "rock"
        # Closing again on the held rock changes nothing and takes no time.
        t0 = trio.current_time()
        again = await arm.execute(Command(CommandCode.CLOSE_FINGERS))
        assert again.feedback == gripped.feedback
        assert trio.current_time() == t0

    run(main)


def test_a_held_object_is_collision_checked_with_the_hand() -> None:
    table = ObstacleSpec("table", (0.25, -0.75, -0.672), (0.95, 0.75, -0.35))
    kerb = ObstacleSpec("kerb", (0.60, -0.3, -0.35), (0.62, 0.5, -0.33))
    config = WorldConfig(
        initial_joints=HOME,
        obstacles=(table, kerb),
        objects=(ObjectSpec("rock", (0.55, 0.15, -0.315), 0.07, 0.85),),
    )
    across = Command(CommandCode.MOVE_PATH, (1.0, 0.0, 0.70, 0.15, -0.315))

    async def main() -> None:
        empty_handed = SimulatedArm(dataclasses.replace(config, objects=()))
        await empty_handed.execute(Command(CommandCode.MOVE_TO_POSITION, (0.55, 0.15, -0.315)))
        # The fingertips clear the 2 cm kerb by 5 mm (with the links' 1 cm clearance) ...
        await empty_handed.execute(across)

        arm = SimulatedArm(config)
        await arm.execute(Command(CommandCode.MOVE_TO_POSITION, (0.55, 0.15, -0.315)))
        await arm.execute(Command(CommandCode.CLOSE_FINGERS))
        assert arm.grasped == "rock"
        # ... the rock hanging 3.5 cm below them does not; lifting it off the
        # table it rested on is no collision.
        with pytest.raises(CommandFailed) as info:
            await arm.execute(across)
        assert info.value.reason is FailureReason.COLLISION
        assert info.value.aux[:2] == (6.0, 1.0)
        await arm.execute(Command(CommandCode.MOVE_CARTESIAN_DELTA, (0.0, 0.0, 0.05)))
        await arm.execute(Command(CommandCode.MOVE_PATH, (1.0, 0.0, 0.70, 0.15, -0.265)))

    run(main)
