"""Seed 000-style task scripts: sequences of manipulator commands as plain data.

The rock task follows seed 000's terminal guidance: approach through "an
intermediate point removed from the target along the direction of the final
desired approach vector", let the wrist proximity sensors "center the hand
over it", grasp (the tactile switches and the finger opening verify the
size), weigh, carry the rock to a bin and let go, then return home.
"""

from __future__ import annotations

from dataclasses import dataclass

from tcpstream import Command, CommandCode

from ._world import WorldConfig

__all__ = ["RockTask", "rock_task"]

Vec3 = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class RockTask:
    """The rock task's commands and the outcome they should produce."""

    commands: tuple[Command, ...]
    rock: str
    expected_mass: float
    """kg: what WEIGH should report (up to the world's weighing noise)."""
    bin_centre: tuple[float, float]
    """(x, y) m: the rock should come to rest over this point ..."""
    bin_top: float
    """... on this surface (z, m)."""


def rock_task(
    world: WorldConfig,
    *,
    rock: str = "rock",
    bin_name: str = "bin",
    estimate_error: Vec3 = (0.02, -0.015, 0.0),
    approach_height: float = 0.12,
    carry_height: float = 0.25,
    squeeze_force: float = 20.0,
) -> RockTask:
    """The commands that move ``rock`` into the box ``bin_name`` and bring the arm home.

    The rock's position comes from the world with ``estimate_error`` (m)
    added, as a vision system would supply it; CENTER_FINGERS removes the
    horizontal part of the error.  The hand points down (A = -z) throughout:
    the task expects the world's initial pose to hold the hand that way (as
    :data:`~linksim.arm._world.DEFAULT_WORLD` does), since Level-2 paths keep the
    orientation.  Raises ``KeyError`` for an unknown rock or bin name.
    """
    target = next((o for o in world.objects if o.name == rock), None)
    box = next((o for o in world.obstacles if o.name == bin_name), None)
    if target is None:
        raise KeyError(f"no object named {rock!r} in the world")
    if box is None:
        raise KeyError(f"no obstacle named {bin_name!r} in the world")
    x, y, z = (c + e for c, e in zip(target.position, estimate_error, strict=True))
    bx = (box.minimum[0] + box.maximum[0]) / 2.0
    by = (box.minimum[1] + box.maximum[1]) / 2.0
    bin_top = box.maximum[2]
    drop_z = bin_top + target.size / 2.0 + 0.05
    commands = [
        Command(CommandCode.OPEN_FINGERS, (0.0,)),
        # Over the rock, then down to the intermediate point on its approach axis.
        Command(
            CommandCode.MOVE_PATH,
            (2.0, 0.0, x, y, z + carry_height, x, y, z + approach_height),
        ),
        Command(CommandCode.CENTER_FINGERS),
        # Straight down the approach vector onto the rock (seed 004 incremental move).
        Command(CommandCode.MOVE_CARTESIAN_DELTA, (0.0, 0.0, -approach_height)),
        Command(CommandCode.CLOSE_FINGERS),
        Command(CommandCode.SQUEEZE, (squeeze_force,)),
        Command(CommandCode.WEIGH),
        Command(CommandCode.MOVE_CARTESIAN_DELTA, (0.0, 0.0, carry_height - approach_height)),
        Command(
            CommandCode.MOVE_PATH,
            (2.0, 0.0, bx, by, drop_z + carry_height - approach_height, bx, by, drop_z),
        ),
        Command(CommandCode.OPEN_FINGERS, (0.0,)),
        Command(CommandCode.MOVE_JOINTS, world.initial_joints),
    ]
    return RockTask(tuple(commands), rock, target.mass, (bx, by), bin_top)
