"""What a controller keeps to make "exactly once" true, whatever the I/O library.

:class:`RequestBook` is sans-I/O: request ids, the commands sent without a
seen outcome, the failure barrier, and the resume decision of PROTOCOL.md
section 9.  The trio :class:`~tcpstream.ArmClient` and the asyncio client
(:mod:`tcpstream.asyncio`) each own only their futures, tasks and streams and
feed this one book, so both keep the same promises by construction.
:class:`CommandMethods` gives both the one-method-per-command surface.
"""

from __future__ import annotations

import abc
import logging
from collections.abc import Sequence
from dataclasses import dataclass

from . import _builders as build
from ._commands import Command, CommandCode, CommandFailed, CommandResult
from ._errors import (
    AuthenticationFailed,
    LocalProtocolError,
    OutcomeUnknown,
    Refused,
    SessionClosed,
    SessionError,
)
from ._events import (
    Accepted,
    CloseReason,
    Completed,
    Event,
    Failed,
    Granted,
    RefusalReceived,
    RefuseReason,
)

__all__ = [
    "CommandMethods",
    "RequestBook",
    "Settlement",
    "describe_error",
    "gave_up",
    "refusal_error",
]

log = logging.getLogger("tcpstream._client")

FINAL_REASONS = frozenset(
    {
        CloseReason.NORMAL,
        CloseReason.TERMINATED,
        CloseReason.REFUSED,
        CloseReason.AUTHENTICATION,
        CloseReason.SHUTDOWN,
        CloseReason.TAKEN_OVER,
        CloseReason.IDLE,
    }
)
"""Session ends after which reconnecting would be wrong."""


@dataclass(slots=True)
class _Sent:
    command: Command
    failures_seen: int


@dataclass(frozen=True, slots=True)
class Settlement:
    """What became of a request: ``result``, or ``error``; or, with neither,
    only that the arm accepted it at queue ``position``."""

    request_id: int
    result: CommandResult | None = None
    error: Exception | None = None
    position: int | None = None

    @property
    def final(self) -> bool:
        return self.result is not None or self.error is not None


class RequestBook:
    """Request ids and outcomes of one controller incarnation (sans-I/O).

    Call :meth:`register` for each command as it is sent, :meth:`on_event` for
    each connection event, :meth:`on_grant` on every grant (it says what to
    re-send), :meth:`settle_all` when the client gives up.  Each returns the
    settlements to deliver to the waiting callers.
    """

    def __init__(self) -> None:
        self.sent: dict[int, _Sent] = {}
        """Commands sent and not settled, by request id (bounded by max_in_flight)."""
        self.next_id = 1
        self.confirmed_highest = 0
        """The highest request id the arm confirmed taking in (ACCEPTED or
        COMPLETED): a GRANT reporting less means the arm's memory was lost."""
        self.failures_seen = 0
        """The highest request id of a FAILED reply received: sent with every
        command so the arm can tell what this client knew (the failure barrier)."""
        self.arm_instance: int | None = None
        self.rejected_by_arm = 0
        """FAILED replies matching no command: packets the arm could not use."""

    def register(self, command: Command) -> tuple[int, int]:
        """A command about to be sent: its request id and its "failures seen" stamp."""
        if self.next_id >= 2**32:
            raise LocalProtocolError("request ids exhausted; create a new client")
        rid = self.next_id
        self.next_id += 1
        self.sent[rid] = _Sent(command, self.failures_seen)
        return rid, self.failures_seen

    def on_event(self, event: Event) -> list[Settlement]:
        """ACCEPTED, COMPLETED and FAILED from the arm; other events return nothing."""
        if isinstance(event, Completed):
            self.confirmed_highest = max(self.confirmed_highest, event.request_id)
            return self._settle(event.request_id, result=event.result)
        if isinstance(event, Accepted):
            self.confirmed_highest = max(self.confirmed_highest, event.request_id)
            if event.request_id in self.sent:
                return [Settlement(event.request_id, position=event.position)]
            return []
        if isinstance(event, Failed):
            # The failure barrier: commands sent from now on say we know of it.
            self.failures_seen = max(self.failures_seen, event.request_id)
            if event.request_id in self.sent:
                error = CommandFailed(event.reason, event.message, event.aux)
                return self._settle(event.request_id, error=error)
            self.rejected_by_arm += 1
            log.warning("the arm rejected a packet: %s %s", event.reason.name, event.message)
        return []

    def on_grant(self, event: Granted) -> tuple[list[tuple[int, Command, int]], list[Settlement]]:
        """Resume (PROTOCOL.md 9): what to re-send, oldest first, and what is unknown.

        If the arm forgot us -- it restarted (new instance), has no memory of
        this identity, or no longer remembers ids it confirmed -- every command
        sent without a seen outcome may or may not have run there: it settles as
        :class:`OutcomeUnknown` rather than risk running twice.  Otherwise all
        are re-sent under the same ids and stamps: the arm answers from memory,
        attaches to the one running, or runs what it never received.
        """
        forgot = (
            not event.remembered
            or event.last_request_id < self.confirmed_highest
            or (self.arm_instance is not None and event.arm_instance != self.arm_instance)
        )
        self.arm_instance = event.arm_instance
        if not forgot:
            resend = [(rid, s.command, s.failures_seen) for rid, s in sorted(self.sent.items())]
            return resend, []
        self.confirmed_highest = event.last_request_id
        unknown: list[Settlement] = []
        for rid in sorted(self.sent):
            text = (
                f"request {rid}: the arm restarted or forgot this controller, so it "
                "cannot say whether the command ran; outcome unknown (not re-sent). "
                "Check the arm's state before commanding again"
            )
            unknown += self._settle(rid, error=OutcomeUnknown(text))
        return [], unknown

    def settle_all(self, why: SessionClosed) -> list[Settlement]:
        """The client gives up: every command sent ends :class:`OutcomeUnknown`."""
        out: list[Settlement] = []
        for rid in sorted(self.sent):
            unknown = OutcomeUnknown(f"request {rid} was sent, but {why}: outcome unknown")
            unknown.reason = why.reason
            out += self._settle(rid, error=unknown)
        return out

    def _settle(
        self, rid: int, *, result: CommandResult | None = None, error: Exception | None = None
    ) -> list[Settlement]:
        if self.sent.pop(rid, None) is None:
            return []
        return [Settlement(rid, result=result, error=error)]


def refusal_error(event: RefusalReceived) -> SessionError:
    """The typed error a caller gets for the arm's REFUSE."""
    if event.reason is RefuseReason.NOT_AUTHORIZED:
        return AuthenticationFailed(
            f"the arm refused our key ({event.message}); "
            "check that both ends have the same pre-shared key"
        )
    return Refused(event.reason, event.message)


def gave_up(lost: str, attempts: int, used: int, last_error: str) -> str:
    """Why a client stopped trying: the loss, then what reconnecting did."""
    if attempts == 0:
        return f"{lost}; reconnecting is off"
    text = f"{lost}; {used} reconnect attempt{'s' if used != 1 else ''} failed"
    return text + (f" (last: {last_error})" if last_error else "")


def describe_error(exc: BaseException) -> str:
    """One line for an error: its text, and its cause's when that adds something."""
    text = str(exc) or type(exc).__name__
    cause = exc.__cause__
    if cause is not None and str(cause) and str(cause) not in text:
        text += f" ({type(cause).__name__}: {cause})"
    return text


class CommandMethods(abc.ABC):
    """One awaitable method per command (seed 000's list and the additions)."""

    @abc.abstractmethod
    async def send(self, command: Command) -> CommandResult:
        """Run ``command`` and return its result; raises :class:`CommandFailed` on failure."""

    async def reinitialize(self) -> CommandResult:
        return await self.send(build.reinitialize())

    async def status(self) -> CommandResult:
        return await self.send(build.status())

    async def open_fingers(self, opening: float = 0.0) -> CommandResult:
        return await self.send(build.open_fingers(opening))

    async def close_fingers(self) -> CommandResult:
        return await self.send(build.close_fingers())

    async def move_to(
        self,
        p: Sequence[float],
        s: Sequence[float] | None = None,
        a: Sequence[float] | None = None,
    ) -> CommandResult:
        return await self.send(build.move_to(p, s, a))

    async def move_joints(self, joints: Sequence[float]) -> CommandResult:
        return await self.send(build.move_joints(joints))

    async def move_joint(self, joint: int, amount: float) -> CommandResult:
        return await self.send(build.move_joint(joint, amount))

    async def transform_to_pose(self, joints: Sequence[float]) -> CommandResult:
        return await self.send(build.transform_to_pose(joints))

    async def transform_to_joints(
        self, p: Sequence[float], s: Sequence[float], a: Sequence[float]
    ) -> CommandResult:
        return await self.send(build.transform_to_joints(p, s, a))

    async def squeeze(self, force: float) -> CommandResult:
        return await self.send(build.squeeze(force))

    async def weigh(self) -> CommandResult:
        return await self.send(build.weigh())

    async def change_speed(self, fraction: float) -> CommandResult:
        return await self.send(build.change_speed(fraction))

    async def center_fingers(self) -> CommandResult:
        return await self.send(build.center_fingers())

    async def terminate(self) -> CommandResult:
        return await self.send(build.terminate())

    async def move_delta(
        self,
        dp: Sequence[float],
        drot: Sequence[float] = (0.0, 0.0, 0.0),
        *,
        pose_change: bool = False,
    ) -> CommandResult:
        return await self.send(build.move_delta(dp, drot, pose_change=pose_change))

    async def move_path(
        self, points: Sequence[Sequence[float]], blend: float = 0.0
    ) -> CommandResult:
        return await self.send(build.move_path(points, blend))

    async def emergency_stop(self) -> CommandResult:
        """Halt now: bypasses the in-flight bound here and the queue at the arm."""
        return await self.send(build.emergency_stop())

    async def add_obstacle(
        self, minimum: Sequence[float], maximum: Sequence[float]
    ) -> CommandResult:
        return await self.send(build.add_obstacle(minimum, maximum))


def is_emergency(command: Command) -> bool:
    """An emergency stop bypasses the in-flight bound (and the arm's queue)."""
    return command.code is CommandCode.EMERGENCY_STOP
