"""``SimulatedArm``: the remote manipulator that the tcpstream command server drives.

It implements :class:`tcpstream.Executor` on trio time: every motion is
planned in full first (joint limits, reachability, singular regions, seed
000's collision check at twenty points) and refused before it starts, then
played out one control sample at a time (``trio.sleep_until`` on a fixed
grid of ``1 / control_rate_hz`` s), so on a ``MockClock`` a minute of motion
takes no wall time and every run is identical.

* Cancelling :meth:`execute`, or calling :meth:`halt`, stops the motion before
  the next sample: the joints stay at the last sample played, the grasped
  object with them, and :meth:`state` is consistent at once.
* Telemetry: the optional ``telemetry`` callback gets the feedback array every
  ``telemetry_every``-th sample of motion (seed 004 forwards every tenth).
* Failures raise :class:`CommandFailed` with the reason, a message that tells
  the operator what to do, the reason's aux words (tcpstream/_commands.py) and
  the state at the failure; the feedback's error indicator keeps the reason
  until the next command succeeds.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass

import numpy as np
import trio

from linksim._errors import ConfigError
from tcpstream import Command, CommandCode, CommandFailed, CommandResult, FailureReason, Feedback
from tcpstream.commands import CommandFlags, validate_arguments

from ._collision import Load, first_collision
from ._kinematics import PUMA560, ArmModel, Array, check_limits, frame_from_psa, hand_frame, psa
from ._planner import plan_cartesian_path, plan_move, solve_increment, solve_pose
from ._trajectory import QUINTIC_PEAK_RATE, quintic
from ._world import DEFAULT_WORLD, World, WorldConfig

__all__ = ["ArmStatistics", "SimulatedArm"]

logger = logging.getLogger(__name__)

Aux = tuple[float, float, float, float]
NO_AUX: Aux = (0.0, 0.0, 0.0, 0.0)

SQUEEZE_TIME = 0.2
"""Seconds for the gripper to build up a commanded squeeze force."""


@dataclass(frozen=True, slots=True)
class ArmStatistics:
    """A snapshot of the arm's counters (trio's ``statistics()`` naming)."""

    commands: int
    completed: int
    failed: int
    collisions_refused: int
    halts: int
    samples: int
    motion_seconds: float
    drift_corrections: int
    moving: bool
    speed: float
    grasping: str | None
    obstacles: int
    last_error: FailureReason


def _six(q: Array) -> tuple[float, float, float, float, float, float]:
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]), float(q[4]), float(q[5]))


def _vec(v: Array) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def _command_failed(reason: FailureReason, message: str, aux: Aux = NO_AUX) -> CommandFailed:
    return CommandFailed(reason, message, aux=aux)


class SimulatedArm:
    """A PUMA 560 with a parallel gripper in a world of boxes and objects.

    ``config`` describes the world (:data:`DEFAULT_WORLD` by default);
    ``model`` the arm (its ``max_velocity`` is replaced by the world's
    ``max_joint_velocity``).  Raises :class:`ConfigError` when the initial
    pose is outside the joint limits or inside an obstacle.
    """

    def __init__(
        self,
        config: WorldConfig = DEFAULT_WORLD,
        *,
        model: ArmModel = PUMA560,
        telemetry: Callable[[Feedback], None] | None = None,
    ) -> None:
        self._config = config
        self._model = dataclasses.replace(model, max_velocity=config.max_joint_velocity)
        self._world = World(config)
        self._rng = np.random.default_rng(config.seed)
        self._telemetry = telemetry
        self._q = np.array(config.initial_joints, dtype=np.float64)
        try:
            check_limits(self._model, self._q)
        except CommandFailed as exc:
            raise ConfigError(f"initial_joints: {exc.message}") from None
        hit = first_collision(
            self._model, self._q[None, :], self._world.obstacles, config.clearance
        )
        if hit is not None:
            raise ConfigError(
                f"initial_joints: link {hit.link} is inside obstacle "
                f"{self._world.obstacle_names[hit.obstacle]!r}"
            )
        self._opening = config.initial_opening
        self._speed = config.speed
        self._grasped: int | None = None
        self._grasp_offset = np.zeros(3)  # object centre in the hand frame
        self._grip_force = 0.0
        self._error = FailureReason.NONE
        self._halt_reason: FailureReason | None = None
        self._interrupted = False  # a motion was cancelled from outside, not yet halted
        self._motion_scope: trio.CancelScope | None = None
        self._busy = False
        self._frame = hand_frame(self._model, self._q)
        # Counters for statistics().
        self._commands = self._completed = self._failed = 0
        self._collisions_refused = self._halts = self._samples = 0
        self._drift_corrections = 0
        self._handlers: dict[CommandCode, Callable[[Command], Awaitable[Aux]]] = {
            CommandCode.REINITIALIZE: self._reinitialize,
            CommandCode.STATUS: self._status,
            CommandCode.OPEN_FINGERS: self._open_fingers,
            CommandCode.CLOSE_FINGERS: self._close_fingers,
            CommandCode.MOVE_TO_POSITION: self._move_to_position,
            CommandCode.MOVE_JOINTS: self._move_joints,
            CommandCode.MOVE_JOINT: self._move_joint,
            CommandCode.TRANSFORM: self._status,  # handled in execute: no state change
            CommandCode.SQUEEZE: self._squeeze,
            CommandCode.WEIGH: self._weigh,
            CommandCode.CHANGE_SPEED: self._change_speed,
            CommandCode.CENTER_FINGERS: self._center_fingers,
            CommandCode.TERMINATE: self._status,
            CommandCode.MOVE_CARTESIAN_DELTA: self._move_cartesian_delta,
            CommandCode.MOVE_PATH: self._move_path,
            CommandCode.EMERGENCY_STOP: self._status,
            CommandCode.ADD_OBSTACLE: self._add_obstacle,
        }

    # ------------------------------------------------------------------ Executor

    @property
    def control_rate_hz(self) -> float:
        """The control sample rate (seed 000: 125 Hz)."""
        return self._config.control_rate_hz

    @property
    def world(self) -> World:
        """The world the arm lives in (objects move as the arm handles them)."""
        return self._world

    @property
    def model(self) -> ArmModel:
        return self._model

    async def execute(self, command: Command) -> CommandResult:
        """Carry out one command; see the module docstring for the contract."""
        if self._busy:
            raise _command_failed(
                FailureReason.ARM_FAULT, "execute called while another command is running"
            )
        self._busy = True
        self._halt_reason = None
        self._interrupted = False
        self._commands += 1
        logger.debug("execute %s flags=%s", command.code.name, command.flags)
        try:
            validate_arguments(command)
            if command.code is CommandCode.TRANSFORM:
                feedback = self._transform(command)
                aux = NO_AUX
            else:
                aux = await self._handlers[command.code](command)
                feedback = None
        except CommandFailed as exc:
            self._failed += 1
            self._error = exc.reason
            if exc.reason is FailureReason.COLLISION:
                self._collisions_refused += 1
            logger.debug("%s failed: %s", command.code.name, exc)
            raise CommandFailed(exc.reason, exc.message, exc.aux, self.state()) from None
        except (ValueError, ArithmeticError, LookupError) as exc:
            self._failed += 1
            self._error = FailureReason.ARM_FAULT
            raise CommandFailed(
                FailureReason.ARM_FAULT, f"simulated arm fault: {exc!r}", feedback=self.state()
            ) from exc
        finally:
            self._busy = False
        self._completed += 1
        self._error = FailureReason.NONE
        return CommandResult(feedback or self.state(), aux)

    def halt(self, reason: FailureReason) -> None:
        """Stop any motion now (idempotent).

        When it stops a motion -- running, or just cancelled by the caller --
        the reason shows in the error indicator; a halt of an arm at rest
        changes nothing there.
        """
        self._halts += 1
        stopped = self._motion_scope is not None or self._interrupted
        self._interrupted = False
        if stopped and reason is not FailureReason.NONE:
            self._error = reason
        if self._motion_scope is not None:
            self._halt_reason = reason
            self._motion_scope.cancel()

    def state(self) -> Feedback:
        """The feedback array now (cheap: the hand frame is kept up to date per sample)."""
        p, s, a = psa(self._frame)
        tactile = self._grasped is not None
        return Feedback(
            joints=_six(self._q),
            finger_opening=float(self._opening),
            p=_vec(p),
            s=_vec(s),
            a=_vec(a),
            tactile_left=tactile,
            tactile_right=tactile,
            error=self._error,
        )

    def statistics(self) -> ArmStatistics:
        """Counters since construction."""
        grasped = None if self._grasped is None else self._world.objects[self._grasped].name
        return ArmStatistics(
            commands=self._commands,
            completed=self._completed,
            failed=self._failed,
            collisions_refused=self._collisions_refused,
            halts=self._halts,
            samples=self._samples,
            motion_seconds=self._samples / self.control_rate_hz,
            drift_corrections=self._drift_corrections,
            moving=self._motion_scope is not None,
            speed=self._speed,
            grasping=grasped,
            obstacles=len(self._world.obstacles),
            last_error=self._error,
        )

    @property
    def joints(self) -> Array:
        """The joint angles now (rad, a copy)."""
        return self._q.copy()

    @property
    def grasped(self) -> str | None:
        """The name of the object between the fingers, if any."""
        return None if self._grasped is None else self._world.objects[self._grasped].name

    @property
    def grip_force(self) -> float:
        """The squeeze force commanded on the grasped object (N)."""
        return self._grip_force

    # ---------------------------------------------------------------- playback

    def _set_joints(self, q: Array) -> None:
        self._q = q
        self._frame = hand_frame(self._model, q)
        if self._grasped is not None:
            obj = self._world.objects[self._grasped]
            obj.position = self._frame[:3, :3] @ self._grasp_offset + self._frame[:3, 3]

    async def _play(self, samples: int, step: Callable[[int], None]) -> None:
        """Run ``step(k)`` at samples k = 1..samples on the control grid; halt-aware."""
        if samples <= 0:
            return
        dt = 1.0 / self.control_rate_hz
        start = trio.current_time()
        played = 0
        with trio.CancelScope() as scope:
            self._motion_scope = scope
            try:
                for k in range(1, samples + 1):
                    await trio.sleep_until(start + k * dt)
                    step(k)
                    played = k
                    self._samples += 1
                    every = self._config.telemetry_every
                    if self._telemetry is not None and self._samples % every == 0:
                        self._telemetry(self.state())
            except trio.Cancelled:
                # Ours (a halt) is caught by the scope below; anyone else's
                # (the server's emergency stop) propagates, and the halt()
                # that follows records why the motion ended.
                self._interrupted = not scope.cancel_called
                raise
            finally:
                self._motion_scope = None
        if scope.cancelled_caught:
            reason = self._halt_reason or FailureReason.STOPPED
            raise _command_failed(
                reason,
                f"halted after sample {played} of {samples}; the arm is at rest at the "
                "reported pose: re-plan from there",
            )

    async def _move_to(self, goal: Array) -> None:
        """Plan seed 000's joint move to ``goal`` (or refuse it) and play it."""
        move = plan_move(
            self._model, self._world, self._q, goal, self._speed, self.control_rate_hz, self._load()
        )
        await self._play(move.samples, lambda k: self._set_joints(move.at(k)))

    def _load(self) -> Load | None:
        """The object in the hand, for the collision check."""
        if self._grasped is None:
            return None
        return Load(self._grasp_offset.copy(), self._world.objects[self._grasped].size)

    def _solve(self, p: Array, s: Array, a: Array) -> Array:
        """Inverse kinematics for P, S, A nearest the current joints; refuses singular poses."""
        return solve_pose(self._model, frame_from_psa(p, s, a), self._q)

    def _move_fingers(self, target: float) -> tuple[int, Callable[[int], None]]:
        """Samples and step for the fingers: the same quintic, peaking at the finger speed."""
        start, delta = self._opening, target - self._opening
        seconds = QUINTIC_PEAK_RATE * abs(delta) / self._config.finger_speed
        samples = math.ceil(seconds * self.control_rate_hz - 1e-9) if delta else 0

        def step(k: int) -> None:
            self._opening = target if k >= samples else start + delta * float(quintic(k / samples))

        return samples, step

    # ---------------------------------------------------------------- commands

    async def _status(self, command: Command) -> Aux:
        return NO_AUX

    async def _reinitialize(self, command: Command) -> Aux:
        self._speed = self._config.speed
        await self._move_to(np.array(self._config.initial_joints, dtype=np.float64))
        return NO_AUX

    async def _change_speed(self, command: Command) -> Aux:
        self._speed = float(command.args[0])
        return (self._speed, 0.0, 0.0, 0.0)

    async def _move_joints(self, command: Command) -> Aux:
        await self._move_to(np.array(command.args[:6], dtype=np.float64))
        return NO_AUX

    async def _move_joint(self, command: Command) -> Aux:
        goal = self._q.copy()
        goal[int(command.args[0]) - 1] += command.args[1]
        await self._move_to(goal)
        return NO_AUX

    async def _move_to_position(self, command: Command) -> Aux:
        p = np.array(command.args[0:3])
        if CommandFlags.SPECIFIED_ORIENTATION in command.flags:
            s, a = np.array(command.args[3:6]), np.array(command.args[6:9])
        else:
            s, a = self._frame[:3, 1], self._frame[:3, 2]
        await self._move_to(self._solve(p, s, a))
        return NO_AUX

    def _transform(self, command: Command) -> Feedback:
        """TRANSFORM: joints -> P, S, A or back, as a feedback array; no motion."""
        if CommandFlags.TO_JOINTS in command.flags:
            args = np.array(command.args)
            q = self._solve(args[0:3], args[3:6], args[6:9])
        else:
            q = np.array(command.args[:6], dtype=np.float64)
        p, s, a = psa(hand_frame(self._model, q))
        now = self.state()
        return dataclasses.replace(
            now,
            joints=_six(q),
            p=_vec(p),
            s=_vec(s),
            a=_vec(a),
            error=FailureReason.NONE,
        )

    async def _move_cartesian_delta(self, command: Command) -> Aux:
        """Seed 004: an incremental move (see :func:`solve_increment`); all zero is index mode."""
        dp = np.array(command.args[0:3])
        dr = np.array(command.args[3:6])
        if not dp.any() and not dr.any():
            return NO_AUX  # index mode: the hand controller moves, the arm does not
        pose_change = CommandFlags.POSE_CHANGE in command.flags
        goal = solve_increment(self._model, self._q, self._frame, dp, dr, pose_change)
        await self._move_to(goal)
        return NO_AUX

    async def _move_path(self, command: Command) -> Aux:
        """Seed 003 Level 2: via points joined by straight lines and parabolic blends."""
        n = int(command.args[0])
        plan = plan_cartesian_path(
            self._model,
            self._world,
            self._q.copy(),
            self._frame.copy(),
            np.array(command.args[2 : 2 + 3 * n]).reshape(n, 3),
            blend_time=command.args[1] or self._config.blend_time,
            hand_speed=self._config.cartesian_speed * self._speed,
            speed=self._speed,
            rate_hz=self.control_rate_hz,
            load=self._load(),
        )
        self._drift_corrections += plan.drift_corrections
        joints = plan.joints
        await self._play(len(joints) - 1, lambda k: self._set_joints(joints[k]))
        return (plan.duration, float(plan.drift_corrections), 0.0, 0.0)

    async def _open_fingers(self, command: Command) -> Aux:
        target = command.args[0] or self._config.max_opening
        if target > self._config.max_opening:
            raise _command_failed(
                FailureReason.BAD_ARGUMENT,
                f"finger opening {target} m exceeds the gripper's {self._config.max_opening} m",
            )
        if self._grasped is not None:
            obj = self._world.objects[self._grasped]
            if target <= obj.size:
                return NO_AUX  # the fingers already rest on the object
            # Release: the object falls to the support below it.
            obj.position[2] = self._world.rest_height(self._grasped)
            self._grasped = None
            self._grip_force = 0.0
        elif target < self._opening:
            # "Opening" to less than now closes the fingers: they stop on
            # whatever is between them, as CLOSE_FINGERS does.
            await self._close_to(target)
            return NO_AUX
        samples, step = self._move_fingers(target)
        await self._play(samples, step)
        return NO_AUX

    async def _close_fingers(self, command: Command) -> Aux:
        if self._grasped is None:
            await self._close_to(0.0)
        return NO_AUX

    async def _close_to(self, limit: float) -> None:
        """Close the fingers to ``limit`` or until both tactile switches touch an object."""
        p, s, a = psa(self._frame)
        index = self._world.between_fingers(p, s, a, self._opening)
        if index is not None and self._world.objects[index].size <= limit:
            index = None  # the fingers stop before they reach it
        final = limit if index is None else self._world.objects[index].size
        samples, step = self._move_fingers(min(final, self._opening))
        await self._play(samples, step)
        if index is not None:
            # Both tactile switches close: the fingers centre the object between them.
            obj = self._world.objects[index]
            d = obj.position - p
            obj.position = obj.position - (d @ s) * s
            self._grasped = index
            self._grasp_offset = self._frame[:3, :3].T @ (obj.position - p)

    def _holding(self, what: str) -> int:
        if self._grasped is None:
            raise _command_failed(
                FailureReason.NOT_GRASPING,
                f"cannot {what}: no object between the fingers (the tactile switches are open); "
                "center the fingers over an object and close them first",
            )
        return self._grasped

    async def _squeeze(self, command: Command) -> Aux:
        self._holding("squeeze")
        force = command.args[0]
        if force > self._config.max_grip_force:
            raise _command_failed(
                FailureReason.BAD_ARGUMENT,
                f"grip force {force} N exceeds the gripper's {self._config.max_grip_force} N",
            )
        await self._play(math.ceil(SQUEEZE_TIME * self.control_rate_hz - 1e-9), lambda k: None)
        self._grip_force = force
        return (force, 0.0, 0.0, 0.0)

    async def _weigh(self, command: Command) -> Aux:
        index = self._holding("weigh")
        samples = math.ceil(self._config.weigh_time * self.control_rate_hz - 1e-9)
        await self._play(samples, lambda k: None)
        mass = self._world.objects[index].mass
        noise = self._config.weigh_noise
        measured = mass + (float(self._rng.normal(0.0, noise)) if noise > 0 else 0.0)
        return (measured, noise, 0.0, 0.0)

    async def _center_fingers(self, command: Command) -> Aux:
        """Move the hand sideways (normal to A) until the nearest object is on the approach axis."""
        p, s, a = psa(self._frame)
        index = self._world.nearest_in_range(p, self._config.proximity_range, self._grasped)
        if index is None:
            raise _command_failed(
                FailureReason.NO_OBJECT,
                f"no object within the proximity sensors' {self._config.proximity_range} m; "
                "move the hand nearer the object (an intermediate point above it) and retry",
            )
        d = self._world.objects[index].position - p
        lateral = d - (d @ a) * a
        await self._move_to(self._solve(p + lateral, s, a))
        return (float(index), float(np.linalg.norm(lateral)), 0.0, 0.0)

    async def _add_obstacle(self, command: Command) -> Aux:
        lo = (command.args[0], command.args[1], command.args[2])
        hi = (command.args[3], command.args[4], command.args[5])
        try:
            index = self._world.add_obstacle(lo, hi)
        except ConfigError as exc:
            raise _command_failed(FailureReason.BAD_ARGUMENT, str(exc)) from None
        return (float(index), float(len(self._world.obstacles)), 0.0, 0.0)
