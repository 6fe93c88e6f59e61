"""Motion planning for the simulated arm: a complete plan, or the reason it is refused.

Seed 000: "The entire path of each link and hence of the arm is thus
planned.  The path is checked at planning time for potential collisions
with obstacles."  Every function here returns a plan that is safe to play
sample by sample, or raises :class:`~tcpstream.CommandFailed` with the
reason, a message telling the operator what to do, and the reason's aux
words -- before anything moves.

Pure numpy and no clock: :class:`~linksim.arm._arm.SimulatedArm` plays the
plans on trio time, and a local predictive model (the operator console's
preview) can call the same functions to see what a command would do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tcpstream import CommandFailed, FailureReason

from ._collision import Load, first_collision
from ._kinematics import (
    SINGULAR_THRESHOLDS,
    ArmModel,
    Array,
    branch,
    check_limits,
    inverse,
    inverse_candidates,
    rotation_about,
    singular_region,
)
from ._trajectory import (
    CHECKPOINTS,
    JointMove,
    checkpoint_samples,
    integrate_path,
    plan_joint_move,
    plan_path,
)
from ._world import World

__all__ = [
    "MAX_PATH_SECONDS",
    "PATH_RETIMES",
    "PathPlan",
    "plan_cartesian_path",
    "plan_move",
    "refuse_collision",
    "refuse_singular",
    "solve_increment",
    "solve_pose",
]

MAX_PATH_SECONDS = 300.0
"""Longest Level-2 path planned in one command: the whole path is solved
(inverse kinematics per sample) before it moves, so its length bounds memory
and planning time (300 s = 37 500 samples at 125 Hz)."""

PATH_RETIMES = 3
"""How often a path is slowed down when a joint would exceed its allowed velocity."""


def _failed(
    reason: FailureReason, message: str, aux: tuple[float, float, float, float] = (0, 0, 0, 0)
) -> CommandFailed:
    return CommandFailed(reason, message, aux=aux)


def refuse_collision(
    model: ArmModel, world: World, checkpoints: Array, load: Load | None = None
) -> None:
    """Raise COLLISION (aux: link, obstacle row, trajectory point, 0) for the first hit."""
    hit = first_collision(model, checkpoints, world.obstacles, world.config.clearance, load)
    if hit is not None:
        name = world.obstacle_names[hit.obstacle]
        raise _failed(
            FailureReason.COLLISION,
            f"link {hit.link} would hit obstacle {hit.obstacle} ({name}) at trajectory "
            f"point {hit.point} of {CHECKPOINTS}; insert a safe intermediate point and "
            "move in steps",
            aux=(float(hit.link), float(hit.obstacle), float(hit.point), 0.0),
        )


def refuse_singular(model: ArmModel, q: Array, point: int = 0) -> None:
    """Raise SINGULAR (aux: region 1..3, margin, threshold, trajectory point or 0)."""
    region = singular_region(model, q)
    if region is not None:
        kind, margin = region
        limit = SINGULAR_THRESHOLDS[kind - 1]
        where = f" at trajectory point {point}" if point else ""
        raise _failed(
            FailureReason.SINGULAR,
            f"the pose{where} is in the {kind.name.lower()} singular region "
            f"(margin {margin:.3f} < {limit}); choose a pose away from it or move the "
            "joints directly",
            aux=(float(kind), margin, limit, float(point)),
        )


def solve_pose(model: ArmModel, frame: Array, q_ref: Array) -> Array:
    """Joint angles for a hand frame, nearest ``q_ref``; refuses singular poses."""
    q = inverse(model, frame, q_ref)
    refuse_singular(model, q)
    return q


def plan_move(
    model: ArmModel,
    world: World,
    start: Array,
    goal: Array,
    speed: float,
    rate_hz: float,
    load: Load | None = None,
) -> JointMove:
    """Seed 000's joint move: limits at the goal, the twenty-point collision check.

    The quintic is monotonic, so a goal within the limits keeps every
    intermediate point within them (seed 000).  ``load``: the object in the
    hand, checked with link 6.
    """
    check_limits(model, goal)
    move = plan_joint_move(start, goal, np.asarray(model.max_velocity), speed, rate_hz)
    if move.samples > 0:
        u = np.arange(1, CHECKPOINTS + 1, dtype=np.float64) / CHECKPOINTS
        refuse_collision(model, world, move.at_fraction(u), load)
    return move


def solve_increment(
    model: ArmModel, q: Array, frame: Array, dp: Array, dr: Array, pose_change: bool
) -> Array:
    """Seed 004: the joint goal for a hand increment; singular regions bounce.

    The increment is applied to the hand frame (translation in the base
    frame, rotation ``dr`` about the base axes through P) and the new frame
    is solved in closed form, not by seed 004's inverse-Jacobian step: the
    result is exact, so the "drift ... due to accumulation of
    differentiation (linearization) error" that seed 004 leaves uncorrected
    cannot build up over many increments.

    Away from singular regions the arm keeps its pose (the closed form's
    branch); entering a region, or going deeper into one, needs
    ``pose_change`` (seed 004's button) and otherwise raises SINGULAR.
    """
    target = np.eye(4)
    target[:3, :3] = rotation_about(dr) @ frame[:3, :3]
    target[:3, 3] = frame[:3, 3] + dp
    here = singular_region(model, q)
    if pose_change or here is not None:
        goal = inverse(model, target, q)
    else:
        goal = inverse(model, target, q, keep_branch=branch(model, q))
    there = singular_region(model, goal)
    if there is None or pose_change:
        return goal
    if here is not None and here[0] == there[0] and there[1] >= here[1]:
        return goal  # already in this region and not going deeper: let the arm out
    kind, margin = there
    limit = SINGULAR_THRESHOLDS[kind - 1]
    raise _failed(
        FailureReason.SINGULAR,
        f"the move would enter the {kind.name.lower()} singular region (margin "
        f"{margin:.3f} < {limit}); the arm stays in its pose: set POSE_CHANGE to "
        "pass through and change pose",
        aux=(float(kind), margin, limit, 0.0),
    )


@dataclass(frozen=True, slots=True)
class PathPlan:
    """A Level-2 path solved to joints: ``joints[k]`` is the arm at sample k (0 = now)."""

    joints: Array
    duration: float
    drift_corrections: int


def plan_cartesian_path(
    model: ArmModel,
    world: World,
    start: Array,
    frame: Array,
    vias: Array,
    *,
    blend_time: float,
    hand_speed: float,
    speed: float,
    rate_hz: float,
    load: Load | None = None,
) -> PathPlan:
    """Seed 003 Level 2 from the hand ``frame`` (at joints ``start``) through ``vias`` (n, 3).

    The orientation is held; the hand runs at ``hand_speed`` m/s (already
    scaled by the change-speed fraction ``speed``, which also scales the
    joints' allowed velocities).  Checks, in order: every via point's reach
    (UNREACHABLE names the point), each sample's inverse kinematics in the
    starting pose's branch (JOINT_LIMIT, UNREACHABLE, SINGULAR with the
    trajectory point), the joints' velocities (the path is slowed down up to
    :data:`PATH_RETIMES` times), and the twenty-point collision check.
    """
    target = np.eye(4)
    target[:3, :3] = frame[:3, :3]
    for i, via in enumerate(vias, start=1):
        target[:3, 3] = via
        try:
            inverse_candidates(model, target, start)
        except CommandFailed as exc:
            # The root cause an operator needs, not the joint that first
            # strains on the way there.
            raise _failed(exc.reason, f"via point {i}: {exc.message}", exc.aux) from None
    keep = None if singular_region(model, start) else branch(model, start)
    vmax = np.asarray(model.max_velocity) * speed
    for _ in range(PATH_RETIMES + 1):
        path = plan_path(frame[:3, 3], vias, hand_speed, blend_time, rate_hz)
        if path.duration > MAX_PATH_SECONDS:
            raise _failed(
                FailureReason.BAD_ARGUMENT,
                f"the path would take {path.duration:.0f} s at speed fraction {speed:g} "
                f"(limit {MAX_PATH_SECONDS:.0f} s); raise the speed or split the path",
            )
        positions, _velocities, corrections = integrate_path(path)
        joints = _path_joints(model, positions, frame[:3, :3], start, keep)
        excess = float(np.max(np.abs(np.diff(joints, axis=0)) * rate_hz / vmax))
        if excess <= 1.0:
            break
        # Near the edges of the workspace a hand speed needs more joint
        # speed than allowed: slow the whole path down and plan again.
        hand_speed /= excess * 1.05
    else:
        raise _failed(
            FailureReason.SINGULAR,
            "the path needs joint velocities beyond the allowed maximum even when slowed; "
            "keep it away from singular regions or move the joints directly",
        )
    refuse_collision(model, world, joints[checkpoint_samples(len(joints) - 1)], load)
    return PathPlan(joints, path.duration, corrections)


def _path_joints(
    model: ArmModel,
    positions: Array,
    rotation: Array,
    start: Array,
    keep: tuple[int, int, int] | None,
) -> Array:
    """Joint vectors along a Cartesian path; refuses limits, reach and singular regions."""
    total = len(positions) - 1
    joints = np.empty((len(positions), 6))
    joints[0] = start
    frame = np.eye(4)
    frame[:3, :3] = rotation
    for k in range(1, len(positions)):
        frame[:3, 3] = positions[k]
        point = max(1, math.ceil(k * CHECKPOINTS / total))
        try:
            joints[k] = inverse(model, frame, joints[k - 1], keep_branch=keep)
        except CommandFailed as exc:
            raise _failed(
                exc.reason,
                f"{exc.message} (along the path near trajectory point {point})",
                exc.aux,
            ) from None
        refuse_singular(model, joints[k], point)
    return joints
