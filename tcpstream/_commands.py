"""The manipulator's command set, its argument and feedback arrays, and the executor contract.

Seed 000 (JPL manipulator, "Planning"): "Input to the manipulator system
consists of an integer command and an eighteen-word argument array. Feedback
from the system to the user is given via the argument array. The array on
return contains the six joint variables and the finger opening, the arm's
position vector P, finger sliding vector S, and approach vector A, tactile
sensor readings (from 2 microswitches), and an error indicator."

Six joints, the finger opening and three 3-vectors are sixteen words; the two
microswitches share one word (a bit mask) and the error indicator takes the
last, which makes exactly eighteen (:class:`FeedbackSlot`).

This module is pure data: it defines *what* a command means, not how it
travels (the packet codec) or how it is carried out (the executor, for
example ``linksim``'s simulated arm).  Units are SI throughout: metres,
radians, seconds, kilograms, newtons.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

ARGUMENT_WORDS = 18
"""Seed 000: "an eighteen-word argument array" (float64 on the wire)."""

AUX_WORDS = 4
"""Extra result words in a reply (a weighed mass, where a collision was found)."""

MAX_PATH_POINTS = 5
"""Via points in one MOVE_PATH command: 5 x (x, y, z) + count + blend fit in 18 words."""

JOINTS = 6

LENGTH_BOUND = 100.0
"""Metres: the largest position, displacement, opening or box coordinate a
command may carry.  Far outside any manipulator's workspace (the PUMA 560
reaches under 1 m), and small enough that nothing the arm computes from it --
a distance, a squared norm, a planner's error -- can overflow to infinity and
leave the arm unable to say what went wrong."""
ANGLE_BOUND = 4 * math.pi
"""Radians: the largest joint angle, joint step or rotation step (two turns)."""
FORCE_BOUND = 1.0e5
"""Newtons: the largest grip force a SQUEEZE may ask for."""
TIME_BOUND = 3600.0
"""Seconds: the longest blend time a MOVE_PATH may ask for."""


class CommandCode(enum.IntEnum):
    """Manipulator commands (u16 on the wire).

    1-13 are seed 000's command list in its order; 14-16 come from seed 004
    (incremental Cartesian moves for teleoperation), seed 003 section 5
    (the Level-2 via-point path interpolator) and the safety requirement of an
    emergency stop; 17 lets the operator add an obstacle at run time (seed 000,
    "Safety": the arm contends with rectangular obstacle envelopes).
    """

    REINITIALIZE = 1
    """Reset the arm to its initial pose and speed; reply carries the feedback array."""
    STATUS = 2
    """No motion; reply carries the feedback array (seed 000: "reinitialization and status")."""
    OPEN_FINGERS = 3
    """args[0]: finger opening in metres, or 0 for fully open."""
    CLOSE_FINGERS = 4
    """Close until both tactile switches report contact or the fingers are shut."""
    MOVE_TO_POSITION = 5
    """args[0:3] P (m); with flag SPECIFIED_ORIENTATION also args[3:6] S and args[6:9] A."""
    MOVE_JOINTS = 6
    """args[0:6]: target joint angles (rad), all joints start and stop together."""
    MOVE_JOINT = 7
    """args[0]: joint number 1..6; args[1]: signed amount to move it by (rad)."""
    TRANSFORM = 8
    """No motion.  Default: args[0:6] joints -> reply's P, S, A slots.  With flag
    TO_JOINTS: args[0:3] P, args[3:6] S, args[6:9] A -> reply's joint slots."""
    SQUEEZE = 9
    """args[0]: grip force (N), > 0; requires a grasped object."""
    WEIGH = 10
    """Reply aux[0]: the grasped object's mass (kg); requires a grasped object."""
    CHANGE_SPEED = 11
    """args[0]: fraction (0, 1] of the maximum allowed velocity vector."""
    CENTER_FINGERS = 12
    """Centre the hand over the nearest object in proximity-sensor range."""
    TERMINATE = 13
    """End the session after the queue drains (seed 000: "terminate execution")."""
    MOVE_CARTESIAN_DELTA = 14
    """Seed 004: args[0:3] delta position (m), args[3:6] delta rotation (rad,
    about the base axes).  All zero is index mode: no motion, acknowledged.
    Entering a singular region needs flag POSE_CHANGE."""
    MOVE_PATH = 15
    """Seed 003 Level 2: args[0] n via points (1..5), args[1] blend time (s, 0 for
    the default), args[2:2+3n] the points' positions (m); orientation is held."""
    EMERGENCY_STOP = 16
    """Halt all motion now, bypassing the queue; queued commands fail with STOPPED."""
    ADD_OBSTACLE = 17
    """args[0:3] box minimum corner, args[3:6] maximum corner (m, base frame)."""


class CommandFlags(enum.IntFlag):
    """Per-command option bits (u16 on the wire)."""

    NONE = 0
    SPECIFIED_ORIENTATION = 0x0001
    """MOVE_TO_POSITION: use the S and A given in the arguments, not the current ones."""
    TO_JOINTS = 0x0002
    """TRANSFORM: P, S, A -> joint angles (inverse kinematics)."""
    POSE_CHANGE = 0x0004
    """MOVE_CARTESIAN_DELTA: the operator allows passing into a singular region (seed 004)."""


class FailureReason(enum.IntEnum):
    """Why a command (or a packet) failed: the reason code of a ``failed`` reply.

    1-15 say what happened to a command at the arm (the executor raises them;
    7, 8 and 10 the server sets when it stops, or skips, a command); 32 and up
    belong to the session and packet layers.
    """

    NONE = 0
    JOINT_LIMIT = 1
    """aux: (joint number, requested angle, lower limit, upper limit)."""
    UNREACHABLE = 2
    """The pose is outside the workspace; no inverse-kinematics solution."""
    SINGULAR = 3
    """The pose or motion enters a singular region (without POSE_CHANGE)."""
    COLLISION = 4
    """aux: (link number 1..6, obstacle index, trajectory point 1..20, 0)."""
    NO_OBJECT = 5
    """CENTER_FINGERS found nothing in proximity-sensor range."""
    NOT_GRASPING = 6
    """SQUEEZE or WEIGH without an object between the fingers."""
    STOPPED = 7
    """Halted by an emergency stop (or dropped from the queue by one)."""
    DEADMAN = 8
    """Halted because the controller fell silent for longer than the deadman time."""
    BAD_ARGUMENT = 9
    """Out-of-range or non-finite argument; aux[0] is the offending word index."""
    SKIPPED = 10
    """Not run: an earlier command of this controller failed at the arm (aux[0]
    is its request id) and this one was sent before the controller had seen
    that failure -- it was planned for a state the arm is not in.  Re-plan from
    the arm's state (STATUS) and send again."""
    ARM_FAULT = 15
    """The executor failed unexpectedly; the message says how."""

    BAD_PACKET = 32
    """Undecodable packet (size, magic, version, kind)."""
    UNKNOWN_COMMAND = 33
    NOT_AUTHORIZED = 34
    """Missing or wrong MAC, replayed or reordered counter, or an observer commanding."""
    QUEUE_FULL = 35
    TERMINATING = 36
    """The session is ending; no new commands are taken."""
    EXPIRED = 37
    """The request id is at or below the highest the arm has taken from this
    controller but no longer in its exactly-once memory: not run now, because it
    may have run before.  Send it again under a new request id if it should run."""


class FeedbackSlot(enum.IntEnum):
    """Index of each quantity in the eighteen-word feedback array (seed 000)."""

    JOINT_1 = 0
    JOINT_2 = 1
    JOINT_3 = 2
    JOINT_4 = 3
    JOINT_5 = 4
    JOINT_6 = 5
    FINGER_OPENING = 6
    P_X = 7
    P_Y = 8
    P_Z = 9
    S_X = 10
    S_Y = 11
    S_Z = 12
    A_X = 13
    A_Y = 14
    A_Z = 15
    TACTILE = 16
    """Bit 0: left microswitch in contact; bit 1: right (as a float, 0..3)."""
    ERROR = 17
    """0, or the :class:`FailureReason` of the last command that failed."""


Vector3 = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class Feedback:
    """The arm's state as seed 000's feedback array describes it.

    ``p`` is the hand position; ``s`` (finger sliding) and ``a`` (approach)
    are unit vectors, orthogonal to each other.
    """

    joints: tuple[float, float, float, float, float, float]
    finger_opening: float
    p: Vector3
    s: Vector3
    a: Vector3
    tactile_left: bool = False
    tactile_right: bool = False
    error: FailureReason = FailureReason.NONE

    def to_words(self) -> tuple[float, ...]:
        """The eighteen words in :class:`FeedbackSlot` order."""
        tactile = (1 if self.tactile_left else 0) | (2 if self.tactile_right else 0)
        return (
            *self.joints,
            self.finger_opening,
            *self.p,
            *self.s,
            *self.a,
            float(tactile),
            float(int(self.error)),
        )

    @classmethod
    def from_words(cls, words: Sequence[float]) -> Feedback:
        """Inverse of :meth:`to_words`; raises ``ValueError`` on a malformed array."""
        if len(words) != ARGUMENT_WORDS:
            raise ValueError(f"feedback needs {ARGUMENT_WORDS} words, got {len(words)}")
        w = [float(x) for x in words]
        if not all(math.isfinite(x) for x in w):
            raise ValueError("feedback words must be finite")
        tactile = int(w[FeedbackSlot.TACTILE])
        if tactile != w[FeedbackSlot.TACTILE] or not 0 <= tactile <= 3:
            raise ValueError(f"tactile word must be 0..3, got {w[FeedbackSlot.TACTILE]}")
        code = int(w[FeedbackSlot.ERROR])
        try:
            error = FailureReason(code)
        except ValueError:
            raise ValueError(f"unknown error indicator {w[FeedbackSlot.ERROR]}") from None
        return cls(
            joints=(w[0], w[1], w[2], w[3], w[4], w[5]),
            finger_opening=w[6],
            p=(w[7], w[8], w[9]),
            s=(w[10], w[11], w[12]),
            a=(w[13], w[14], w[15]),
            tactile_left=bool(tactile & 1),
            tactile_right=bool(tactile & 2),
            error=error,
        )


def _zero_args() -> tuple[float, ...]:
    return (0.0,) * ARGUMENT_WORDS


@dataclass(frozen=True, slots=True)
class Command:
    """One manipulator command: seed 000's integer command and argument array."""

    code: CommandCode
    args: tuple[float, ...] = field(default_factory=_zero_args)
    flags: CommandFlags = CommandFlags.NONE

    def __post_init__(self) -> None:
        if len(self.args) != ARGUMENT_WORDS:
            # Pad short argument lists so callers can write Command(code, (x, y, z)).
            if len(self.args) > ARGUMENT_WORDS:
                raise ValueError(f"at most {ARGUMENT_WORDS} argument words, got {len(self.args)}")
            padded = tuple(float(a) for a in self.args) + (0.0,) * (ARGUMENT_WORDS - len(self.args))
            object.__setattr__(self, "args", padded)


@dataclass(frozen=True, slots=True)
class CommandResult:
    """What a completed command returns: the state after it, and any extra result words."""

    feedback: Feedback
    aux: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)


class CommandFailed(Exception):
    """Raised by an executor (and by the client) when a command fails.

    ``reason`` is the wire reason code, ``message`` says what happened and what
    to do, ``aux`` carries the reason's detail words (see :class:`FailureReason`)
    and ``feedback`` the arm's state at the failure when known.
    """

    def __init__(
        self,
        reason: FailureReason,
        message: str,
        aux: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0),
        feedback: Feedback | None = None,
    ) -> None:
        super().__init__(f"{reason.name}: {message}")
        self.reason = reason
        self.message = message
        self.aux = aux
        self.feedback = feedback


@runtime_checkable
class Executor(Protocol):
    """What the command server calls: the arm (simulated or real).

    Contract:

    * ``execute`` carries out one command on trio time and returns the state
      after it, or raises :class:`CommandFailed`.  The server calls it for one
      command at a time, in order; it never sees TERMINATE or EMERGENCY_STOP
      (the session handles those).
    * Cancelling ``execute`` (the server does this for an emergency stop or a
      deadman expiry) halts motion within one control sample and leaves the
      arm at rest in a consistent state.  The server then calls :meth:`halt`.
    * ``halt`` is synchronous and idempotent: stop any motion now.
    * ``state`` is a cheap snapshot, callable at any time (telemetry).
    * ``control_rate_hz`` is the control sample rate (seed 000: 125 Hz);
      telemetry goes out every N-th sample (seed 004 forwards every tenth).
    """

    @property
    def control_rate_hz(self) -> float: ...

    async def execute(self, command: Command) -> CommandResult: ...

    def halt(self, reason: FailureReason) -> None: ...

    def state(self) -> Feedback: ...


def validate_arguments(command: Command) -> None:
    """Check what can be checked without the arm: arity, finiteness and ranges.

    Raises :class:`CommandFailed` with ``BAD_ARGUMENT`` (aux[0] = the offending
    word index) so the client refuses a bad command before it crosses a slow
    link, and the server refuses it again before the arm sees it.  Joint limits,
    reachability and collisions are the executor's to check.
    """
    args = command.args
    code = command.code

    def bad(index: int, why: str) -> CommandFailed:
        return CommandFailed(
            FailureReason.BAD_ARGUMENT,
            f"{code.name} argument word {index}: {why}",
            aux=(float(index), 0.0, 0.0, 0.0),
        )

    for i, word in enumerate(args):
        if not math.isfinite(word):
            raise bad(i, f"{word!r} is not a finite number")
    for first, last, bound, unit in _magnitudes(command):
        for i in range(first, last):
            if abs(args[i]) > bound:
                raise bad(i, f"{args[i]:g} is out of range (|value| <= {bound:g} {unit})")

    if code is CommandCode.OPEN_FINGERS and args[0] < 0:
        raise bad(0, "finger opening must be >= 0 (0 opens fully)")
    if code is CommandCode.MOVE_JOINT:
        if args[0] != int(args[0]) or not 1 <= args[0] <= JOINTS:
            raise bad(0, f"joint number must be 1..{JOINTS}, got {args[0]}")
    elif code is CommandCode.SQUEEZE and args[0] <= 0:
        raise bad(0, "grip force must be > 0 N")
    elif code is CommandCode.CHANGE_SPEED and not 0 < args[0] <= 1:
        raise bad(0, f"speed fraction must be in (0, 1], got {args[0]}")
    elif code is CommandCode.MOVE_PATH:
        n = args[0]
        if n != int(n) or not 1 <= n <= MAX_PATH_POINTS:
            raise bad(0, f"via-point count must be 1..{MAX_PATH_POINTS}, got {n}")
        if args[1] < 0:
            raise bad(1, "blend time must be >= 0 (0 for the default)")
    elif code is CommandCode.ADD_OBSTACLE:
        for axis in range(3):
            if args[axis] >= args[axis + 3]:
                raise bad(axis + 3, "box maximum must exceed its minimum on every axis")
    elif code in (CommandCode.MOVE_TO_POSITION, CommandCode.TRANSFORM):
        needs_frame = (
            code is CommandCode.MOVE_TO_POSITION
            and CommandFlags.SPECIFIED_ORIENTATION in command.flags
        ) or (code is CommandCode.TRANSFORM and CommandFlags.TO_JOINTS in command.flags)
        if needs_frame:
            s, a = args[3:6], args[6:9]
            for start, vec, name in ((3, s, "S"), (6, a, "A")):
                norm = math.sqrt(sum(x * x for x in vec))
                if abs(norm - 1.0) > 1e-3:
                    raise bad(start, f"{name} must be a unit vector (|{name}| = {norm:.4g})")
            dot = sum(x * y for x, y in zip(s, a, strict=True))
            if abs(dot) > 1e-3:
                raise bad(6, f"S and A must be orthogonal (S.A = {dot:.4g})")


def _magnitudes(command: Command) -> list[tuple[int, int, float, str]]:
    """Word ranges ``[first, last)`` of ``command`` and the bound on their size.

    Checked before anything else looks at the numbers, so that an argument far
    outside the workspace is a BAD_ARGUMENT, never an overflow in the planner.
    """
    code, args = command.code, command.args
    length, angle = (LENGTH_BOUND, "m"), (ANGLE_BOUND, "rad")
    spans: list[tuple[int, int, tuple[float, str]]] = []
    if code is CommandCode.OPEN_FINGERS:
        spans.append((0, 1, length))
    elif code is CommandCode.MOVE_TO_POSITION:
        spans.append((0, 3, length))
    elif code is CommandCode.MOVE_JOINTS:
        spans.append((0, JOINTS, angle))
    elif code is CommandCode.MOVE_JOINT:
        spans.append((1, 2, angle))
    elif code is CommandCode.TRANSFORM:
        to_joints = CommandFlags.TO_JOINTS in command.flags
        spans.append((0, 3, length) if to_joints else (0, JOINTS, angle))
    elif code is CommandCode.SQUEEZE:
        spans.append((0, 1, (FORCE_BOUND, "N")))
    elif code is CommandCode.MOVE_CARTESIAN_DELTA:
        spans += [(0, 3, length), (3, 6, angle)]
    elif code is CommandCode.MOVE_PATH:
        # The count itself is checked exactly later; bound what it spans.
        n = int(args[0]) if 1 <= args[0] <= MAX_PATH_POINTS else MAX_PATH_POINTS
        spans += [(1, 2, (TIME_BOUND, "s")), (2, 2 + 3 * n, length)]
    elif code is CommandCode.ADD_OBSTACLE:
        spans.append((0, 6, length))
    return [(first, last, bound, unit) for first, last, (bound, unit) in spans]
