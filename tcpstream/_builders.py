"""Commands built from natural arguments: one function per command of seed 000 (and 003, 004).

Shared by the async client and the blocking facade, so both check arity the
same way before anything crosses the link.  Every function returns a
:class:`~tcpstream.Command`; :func:`~tcpstream.commands.validate_arguments` then checks ranges.
"""

from __future__ import annotations

from collections.abc import Sequence

from ._commands import JOINTS, MAX_PATH_POINTS, Command, CommandCode, CommandFlags

__all__ = [
    "add_obstacle",
    "center_fingers",
    "change_speed",
    "close_fingers",
    "emergency_stop",
    "move_delta",
    "move_joint",
    "move_joints",
    "move_path",
    "move_to",
    "open_fingers",
    "reinitialize",
    "squeeze",
    "status",
    "terminate",
    "transform_to_joints",
    "transform_to_pose",
    "weigh",
]

C = CommandCode


def _vec(name: str, v: Sequence[float], n: int = 3) -> tuple[float, ...]:
    if len(v) != n:
        raise ValueError(f"{name} needs {n} numbers, got {len(v)}")
    return tuple(float(x) for x in v)


def reinitialize() -> Command:
    return Command(C.REINITIALIZE)


def status() -> Command:
    return Command(C.STATUS)


def open_fingers(opening: float = 0.0) -> Command:
    """Open to ``opening`` metres (0: fully)."""
    return Command(C.OPEN_FINGERS, (opening,))


def close_fingers() -> Command:
    return Command(C.CLOSE_FINGERS)


def move_to(
    p: Sequence[float], s: Sequence[float] | None = None, a: Sequence[float] | None = None
) -> Command:
    """Move the hand to ``p``; with both ``s`` and ``a``, to that orientation too."""
    if (s is None) != (a is None):
        raise ValueError("give both S and A for a specified orientation, or neither")
    if s is None or a is None:
        return Command(C.MOVE_TO_POSITION, _vec("P", p))
    return Command(
        C.MOVE_TO_POSITION,
        _vec("P", p) + _vec("S", s) + _vec("A", a),
        CommandFlags.SPECIFIED_ORIENTATION,
    )


def move_joints(joints: Sequence[float]) -> Command:
    """All six joints to these angles (rad), starting and stopping together."""
    return Command(C.MOVE_JOINTS, _vec("joints", joints, JOINTS))


def move_joint(joint: int, amount: float) -> Command:
    """Move joint ``joint`` (1..6) by ``amount`` radians."""
    return Command(C.MOVE_JOINT, (float(joint), amount))


def transform_to_pose(joints: Sequence[float]) -> Command:
    """Joints -> P, S, A (in the reply's feedback slots; no motion)."""
    return Command(C.TRANSFORM, _vec("joints", joints, JOINTS))


def transform_to_joints(p: Sequence[float], s: Sequence[float], a: Sequence[float]) -> Command:
    """P, S, A -> joints (in the reply's joint slots; no motion)."""
    return Command(C.TRANSFORM, _vec("P", p) + _vec("S", s) + _vec("A", a), CommandFlags.TO_JOINTS)


def squeeze(force: float) -> Command:
    """Squeeze the grasped object with ``force`` newtons."""
    return Command(C.SQUEEZE, (force,))


def weigh() -> Command:
    """Weigh the grasped object (the reply's aux[0], kg)."""
    return Command(C.WEIGH)


def change_speed(fraction: float) -> Command:
    """Use ``fraction`` (0, 1] of the maximum velocity."""
    return Command(C.CHANGE_SPEED, (fraction,))


def center_fingers() -> Command:
    return Command(C.CENTER_FINGERS)


def terminate() -> Command:
    """End the session once the queue drains."""
    return Command(C.TERMINATE)


def move_delta(
    dp: Sequence[float],
    drot: Sequence[float] = (0.0, 0.0, 0.0),
    *,
    pose_change: bool = False,
) -> Command:
    """Seed 004's incremental Cartesian move: ``dp`` (m), ``drot`` (rad, base axes)."""
    flags = CommandFlags.POSE_CHANGE if pose_change else CommandFlags.NONE
    return Command(C.MOVE_CARTESIAN_DELTA, _vec("dp", dp) + _vec("drot", drot), flags)


def move_path(points: Sequence[Sequence[float]], blend: float = 0.0) -> Command:
    """Seed 003's Level-2 via-point path through up to five positions (orientation held)."""
    if not 1 <= len(points) <= MAX_PATH_POINTS:
        raise ValueError(f"a path has 1..{MAX_PATH_POINTS} via points, got {len(points)}")
    words: list[float] = [float(len(points)), blend]
    for i, pt in enumerate(points):
        words.extend(_vec(f"point {i + 1}", pt))
    return Command(C.MOVE_PATH, tuple(words))


def emergency_stop() -> Command:
    return Command(C.EMERGENCY_STOP)


def add_obstacle(minimum: Sequence[float], maximum: Sequence[float]) -> Command:
    """A rectangular obstacle from its minimum to its maximum corner (m, base frame)."""
    return Command(C.ADD_OBSTACLE, _vec("minimum", minimum) + _vec("maximum", maximum))
