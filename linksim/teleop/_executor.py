"""The command session's view of the teleoperated arm (a :class:`tcpstream.Executor`).

Beside the sample channel the command session stays open (on the same line
through the stream mux): STATUS reports the arm's state, an EMERGENCY_STOP
halts it at once -- the same latch as the sample channel's STOP -- and every
motion command is refused while the arm is under teleoperation.
"""

from __future__ import annotations

from collections.abc import Callable

from tcpstream import (
    Command,
    CommandCode,
    CommandFailed,
    CommandResult,
    FailureReason,
    Feedback,
)

from ._contact import Array
from ._remote import RemoteArm

__all__ = ["TeleopExecutor"]


def _three(v: Array) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


class TeleopExecutor:
    """STATUS and EMERGENCY_STOP for an arm driven by samples."""

    def __init__(self, remote: RemoteArm, on_stop: Callable[[], None] | None = None) -> None:
        self.remote = remote
        self._on_stop = on_stop or remote.emergency_stop
        self.armed = True
        """Halts latch the arm only while armed (the run disarms before tearing down)."""
        self.halts: list[FailureReason] = []

    @property
    def control_rate_hz(self) -> float:
        return self.remote.config.control_rate

    async def execute(self, command: Command) -> CommandResult:
        if command.code in (CommandCode.STATUS, CommandCode.TRANSFORM):
            return CommandResult(self.state())
        raise CommandFailed(
            FailureReason.BAD_ARGUMENT,
            "the arm is under teleoperation: only STATUS and EMERGENCY_STOP are taken",
            feedback=self.state(),
        )

    def halt(self, reason: FailureReason) -> None:
        if self.armed and reason is FailureReason.STOPPED:
            self.halts.append(reason)
            self._on_stop()

    def state(self) -> Feedback:
        r = self.remote
        q = [float(x) for x in r.q]
        return Feedback(
            joints=(q[0], q[1], q[2], q[3], q[4], q[5]),
            finger_opening=0.08 * (1.0 - r.gripper / 255.0),
            p=_three(r.p),
            s=_three(r.r[:, 1]),
            a=_three(r.r[:, 2]),
            tactile_left=False,
            tactile_right=False,
            error=FailureReason.STOPPED if r.stopped else FailureReason.NONE,
        )
