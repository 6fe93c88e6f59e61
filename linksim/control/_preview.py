"""Plan preview: what a list of commands will do, worked out locally before anything is sent.

Seed 003 section 2.2 ("Local NASREM"): a world model at the local site
simulates the remote levels so the operator can see planned motions before
the commands cross a link with seconds of delay.  The local model here *is*
the remote arm: a private :class:`~linksim.arm._arm.SimulatedArm` (same
kinematics, joint limits, obstacles, speeds, planner) played on a private
``trio.testing.MockClock``, so a preview refuses exactly what the remote arm
refuses -- by construction, not by a second implementation that could drift.

A minute of motion previews in a fraction of a second of wall time (every
control sample is still computed, because collisions and durations depend
on them).  :func:`preview` can be called from plain code or from inside a
trio run (then it runs its private trio loop on a helper thread and blocks
the caller until done: no time passes on the caller's clock, virtual or not).

Units: metres, radians, seconds (of arm time from the start of the plan).
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import trio
import trio.testing

from linksim.arm import (
    DEFAULT_WORLD,
    ObjectSpec,
    ObstacleSpec,
    SimulatedArm,
    WorldConfig,
    hand_frame,
    psa,
)
from tcpstream import Command, CommandCode, CommandFailed, FailureReason, Feedback

from ._control import describe, feedback_record

__all__ = [
    "ModelState",
    "PredictedOutcome",
    "PreviewReport",
    "model_state_of",
    "preview",
]

Joints = tuple[float, float, float, float, float, float]


@dataclass(frozen=True, slots=True)
class ModelState:
    """Everything the local model needs to stand where the arm stands.

    ``world`` holds the believed world *now*: its ``initial_joints``,
    ``initial_opening`` and ``speed`` are the arm's current joints (rad),
    finger opening (m) and speed fraction, its objects sit at their believed
    positions and its obstacles include any added at run time.  ``home`` is
    the world the session started from (REINITIALIZE returns to its pose and
    speed).  ``grasped`` names the object between the fingers.
    """

    world: WorldConfig
    home: WorldConfig
    grasped: str | None = None

    @classmethod
    def initial(cls, world: WorldConfig = DEFAULT_WORLD) -> ModelState:
        """The arm as ``world`` starts it."""
        return cls(world, world, None)

    def rebased(self, feedback: Feedback) -> ModelState:
        """This belief moved to a reported arm state (joints, opening, tactile switches).

        When the switches report an object the model does not hold, the
        nearest object of about the finger opening's size is believed to be
        in the hand (the world differs from the model: the object was not
        where expected); when they report none, nothing is held.
        """
        world = dataclasses.replace(
            self.world,
            initial_joints=feedback.joints,
            initial_opening=min(max(feedback.finger_opening, 0.0), self.world.max_opening),
        )
        holding = feedback.tactile_left and feedback.tactile_right
        grasped = self.grasped if holding else None
        if holding and grasped is None and world.objects:
            p = np.array(feedback.p)
            # The object the fingers closed on has the opening's size; among
            # those, the one nearest the hand is the one that was touched.
            best = min(
                world.objects,
                key=lambda o: (
                    abs(o.size - feedback.finger_opening) > 0.005,
                    float(np.linalg.norm(np.array(o.position) - p)),
                ),
            )
            objects = tuple(
                ObjectSpec(o.name, feedback.p, o.size, o.mass) if o is best else o
                for o in world.objects
            )
            world = dataclasses.replace(world, objects=objects)
            grasped = best.name
        return ModelState(world, self.home, grasped)


def model_state_of(arm: SimulatedArm, home: WorldConfig) -> ModelState:
    """The belief that reproduces ``arm`` (a local model after some commands)."""
    rows = arm.world.obstacles
    obstacles = tuple(
        ObstacleSpec(name, (r[0], r[2], r[4]), (r[1], r[3], r[5]))
        for name, r in zip(arm.world.obstacle_names, rows.tolist(), strict=True)
    )
    objects = tuple(
        ObjectSpec(
            o.name,
            (float(o.position[0]), float(o.position[1]), float(o.position[2])),
            o.size,
            o.mass,
        )
        for o in arm.world.objects
    )
    state = arm.state()
    world = dataclasses.replace(
        home,
        obstacles=obstacles,
        objects=objects,
        initial_joints=state.joints,
        initial_opening=state.finger_opening,
        speed=arm.statistics().speed,
    )
    return ModelState(world, home, arm.grasped)


@dataclass(frozen=True, slots=True)
class PredictedOutcome:
    """What one command is predicted to do.

    ``reason`` is NONE when it completes, the refusal's reason (with the
    arm's message and aux words) when the arm would refuse it, or SKIPPED
    when an earlier command's refusal means it would not run (the server's
    failure barrier).  ``start`` and ``duration`` are seconds of arm time from
    the start of the plan; ``feedback`` is the state after the command;
    ``path`` the joints (rad) at every telemetry sample during it, with times.
    """

    index: int
    command: Command
    label: str
    reason: FailureReason
    message: str
    aux: tuple[float, float, float, float]
    start: float
    duration: float
    feedback: Feedback
    path: tuple[tuple[float, Joints], ...] = ()

    @property
    def ok(self) -> bool:
        return self.reason is FailureReason.NONE

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "index": self.index,
            "command": self.command.code.name,
            "label": self.label,
            "outcome": "ok" if self.ok else self.reason.name,
            "start_s": round(self.start, 3),
            "duration_s": round(self.duration, 3),
        }
        if not self.ok:
            out["message"] = self.message
            out["aux"] = list(self.aux)
        return out


@dataclass(frozen=True, slots=True)
class PreviewReport:
    """A whole plan's prediction: per command, and where the arm ends up."""

    outcomes: tuple[PredictedOutcome, ...]
    start: Feedback
    final: Feedback
    duration: float
    """Seconds of arm time for the commands that run (not counting link delays)."""
    end_state: ModelState
    grasped: str | None

    @property
    def ok(self) -> bool:
        """True when no command would be refused."""
        return all(o.ok for o in self.outcomes)

    @property
    def first_refusal(self) -> PredictedOutcome | None:
        return next(
            (o for o in self.outcomes if not o.ok and o.reason is not FailureReason.SKIPPED), None
        )

    def as_dict(self) -> dict[str, Any]:
        refusal = self.first_refusal
        return {
            "ok": self.ok,
            "duration_s": round(self.duration, 3),
            "final": feedback_record(self.final),
            "grasped": self.grasped,
            "first_refusal": None if refusal is None else refusal.as_dict(),
            "commands": [o.as_dict() for o in self.outcomes],
        }


def preview(
    commands: Sequence[Command], state: ModelState | WorldConfig = DEFAULT_WORLD
) -> PreviewReport:
    """Run ``commands`` through a local copy of the arm starting from ``state``.

    Raises :class:`~linksim.link._config.ConfigError` when ``state`` cannot be
    stood in (a pose outside the limits or inside an obstacle).  Never
    contacts the remote arm and takes no time on the caller's clock.
    """
    if isinstance(state, WorldConfig):
        state = ModelState.initial(state)
    return _run_isolated(_preview_async, list(commands), state)


def _run_isolated(fn: Any, *args: Any) -> PreviewReport:
    """``trio.run(fn, *args)`` on a private virtual clock, even from inside a trio run.

    trio refuses a nested run in one thread, so inside a run the private
    loop gets a helper thread, joined synchronously: the caller's loop (and
    its clock) stands still meanwhile, which keeps virtual-time runs exact.
    """
    if not trio.lowlevel.in_trio_run():
        clock = trio.testing.MockClock(autojump_threshold=0)
        result: PreviewReport = trio.run(fn, *args, clock=clock)
        return result
    box: list[Any] = []

    def target() -> None:
        try:
            box.append(trio.run(fn, *args, clock=trio.testing.MockClock(autojump_threshold=0)))
        except BaseException as exc:  # handed to the caller's thread below
            box.append(exc)

    worker = threading.Thread(target=target, name="linksim-preview", daemon=True)
    worker.start()
    worker.join()
    if isinstance(box[0], BaseException):
        raise box[0]
    out: PreviewReport = box[0]
    return out


async def _preview_async(commands: list[Command], state: ModelState) -> PreviewReport:
    samples: list[tuple[float, Joints]] = []
    t0 = trio.current_time()
    arm = SimulatedArm(
        state.world, telemetry=lambda f: samples.append((trio.current_time() - t0, f.joints))
    )
    if state.grasped is not None:
        await _regrasp(arm)
    start = arm.state()
    outcomes: list[PredictedOutcome] = []
    refused = False
    for i, command in enumerate(commands, start=1):
        began = trio.current_time() - t0
        samples.clear()
        reason, message, aux = FailureReason.NONE, "", (0.0, 0.0, 0.0, 0.0)
        if refused and command.code not in (CommandCode.EMERGENCY_STOP, CommandCode.TERMINATE):
            reason, message = FailureReason.SKIPPED, "not run: an earlier command is refused"
        else:
            try:
                for step in _steps(command, state.home):
                    aux = (await arm.execute(step)).aux
            except CommandFailed as exc:
                reason, message, aux = exc.reason, exc.message, exc.aux
                refused = True
        now = trio.current_time() - t0
        outcomes.append(
            PredictedOutcome(
                i,
                command,
                describe(command),
                reason,
                message,
                aux,
                began,
                now - began,
                arm.state(),
                tuple(samples),
            )
        )
    end = model_state_of(arm, state.home)
    return PreviewReport(
        tuple(outcomes), start, arm.state(), trio.current_time() - t0, end, arm.grasped
    )


async def _regrasp(arm: SimulatedArm) -> None:
    """Re-establish a believed grasp in a fresh model arm (no motion when it fits).

    The object sits between the open-to-its-size fingers, so closing them
    takes zero samples and only records the grasp.  If it does not fit (the
    belief is inconsistent), nothing is done: closing would move the fingers.
    """
    p, s, a = psa(hand_frame(arm.model, arm.joints))
    opening = arm.state().finger_opening
    if arm.world.between_fingers(p, s, a, opening) is not None:
        await arm.execute(Command(CommandCode.CLOSE_FINGERS))


def _steps(command: Command, home: WorldConfig) -> tuple[Command, ...]:
    """The model commands that do what ``command`` does at the remote arm.

    REINITIALIZE returns to the *session's* initial pose and speed; the
    model arm was built at the current pose, so it is spelled out as the
    two commands the arm itself performs (speed reset, joint move).
    """
    if command.code is CommandCode.REINITIALIZE:
        return (
            Command(CommandCode.CHANGE_SPEED, (home.speed,)),
            Command(CommandCode.MOVE_JOINTS, home.initial_joints),
        )
    return (command,)
