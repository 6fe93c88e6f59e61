"""Run a task script through an arm client, pipelined, and keep a record an operator can read.

:class:`TaskRun` submits every command of a script without waiting for the
previous one to finish (the arm queues them and executes in order), tracks
each one through *queued -> sent -> accepted -> completed | failed*, and stops
the arm if a command fails: the commands behind it were planned on the
assumption that it would succeed, so the run sends an emergency stop, which
flushes the arm's queue, rather than let them execute from the wrong place.

This module knows nothing of terminals or transports: the demo and
``linksim control`` give it a connected :class:`tcpstream.ArmClient` and a
callback that redraws whatever display they use.
"""

from __future__ import annotations

import contextlib
import enum
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import trio

from tcpstream import (
    ArmClient,
    Command,
    CommandCode,
    CommandFailed,
    CommandHandle,
    CommandResult,
    Feedback,
    SessionError,
)

__all__ = ["CommandRecord", "CommandState", "TaskRun", "describe", "feedback_record"]


class CommandState(enum.Enum):
    """Where one command of the script is."""

    QUEUED = "queued"
    """Not yet handed to the client (waiting for room in the pipeline)."""
    SENT = "sent"
    ACCEPTED = "accepted"
    """The arm queued it."""
    COMPLETED = "completed"
    FAILED = "failed"

    @property
    def final(self) -> bool:
        return self in (CommandState.COMPLETED, CommandState.FAILED)


def _xyz(words: Sequence[float]) -> str:
    return "(" + ", ".join(f"{w:+.3f}" for w in words) + ")"


def describe(command: Command) -> str:
    """A one-line human description of ``command`` (units: m, rad, N)."""
    a = command.args
    code = command.code
    if code is CommandCode.MOVE_PATH:
        n = int(a[0])
        goal = _xyz(a[2 + 3 * (n - 1) : 2 + 3 * n])
        return f"move along {n} via point{'s' if n != 1 else ''} to {goal}"
    if code is CommandCode.MOVE_CARTESIAN_DELTA:
        if not any(a[:6]):
            return "index (no motion)"
        return f"move hand by {_xyz(a[:3])}"
    if code is CommandCode.MOVE_JOINTS:
        return "move joints to (" + ", ".join(f"{math.degrees(x):.0f}" for x in a[:6]) + ") deg"
    if code is CommandCode.MOVE_JOINT:
        return f"move joint {int(a[0])} by {math.degrees(a[1]):+.1f} deg"
    if code is CommandCode.MOVE_TO_POSITION:
        return f"move hand to {_xyz(a[:3])}"
    if code is CommandCode.OPEN_FINGERS:
        return "open fingers" + (f" to {a[0] * 1000:.0f} mm" if a[0] else "")
    if code is CommandCode.SQUEEZE:
        return f"squeeze with {a[0]:.0f} N"
    if code is CommandCode.CHANGE_SPEED:
        return f"speed {a[0] * 100:.0f} %"
    if code is CommandCode.ADD_OBSTACLE:
        return f"add obstacle {_xyz(a[:3])}..{_xyz(a[3:6])}"
    return code.name.lower().replace("_", " ")


def feedback_record(feedback: Feedback) -> dict[str, Any]:
    """The arm state as a JSON-ready mapping (angles in radians and degrees)."""
    return {
        "joints_rad": [round(q, 6) for q in feedback.joints],
        "joints_deg": [round(math.degrees(q), 2) for q in feedback.joints],
        "finger_opening_m": round(feedback.finger_opening, 6),
        "p": [round(x, 6) for x in feedback.p],
        "s": [round(x, 6) for x in feedback.s],
        "a": [round(x, 6) for x in feedback.a],
        "tactile": [feedback.tactile_left, feedback.tactile_right],
        "error": feedback.error.name,
    }


@dataclass(slots=True)
class CommandRecord:
    """One command's journey, with the times (trio clock, seconds) of each step."""

    index: int
    command: Command
    label: str
    state: CommandState = CommandState.QUEUED
    sent_at: float | None = None
    accepted_at: float | None = None
    done_at: float | None = None
    result: CommandResult | None = None
    error: str | None = None
    reason: str | None = None

    def as_dict(self, origin: float) -> dict[str, Any]:
        def rel(t: float | None) -> float | None:
            return None if t is None else round(t - origin, 3)

        out: dict[str, Any] = {
            "index": self.index,
            "command": self.command.code.name,
            "label": self.label,
            "state": self.state.value,
            "sent_s": rel(self.sent_at),
            "accepted_s": rel(self.accepted_at),
            "done_s": rel(self.done_at),
        }
        if self.error is not None:
            out["error"] = self.error
            out["reason"] = self.reason
        if self.result is not None and self.command.code is CommandCode.WEIGH:
            out["mass_kg"] = round(self.result.aux[0], 4)
        return out


@dataclass(slots=True)
class TaskRun:
    """A script of commands and what became of each.

    Use :meth:`run` once.  ``records`` is live while it runs (for a display);
    ``on_change`` is called after every state change.
    """

    commands: Sequence[Command]
    on_change: Callable[[], None] = field(default=lambda: None)
    records: list[CommandRecord] = field(init=False)
    started_at: float = field(init=False, default=0.0)
    finished_at: float | None = field(init=False, default=None)
    stopped: bool = field(init=False, default=False)
    """True when a failure made the run stop the arm (emergency stop)."""

    def __post_init__(self) -> None:
        self.records = [CommandRecord(i + 1, c, describe(c)) for i, c in enumerate(self.commands)]

    # --- results -------------------------------------------------------------------

    def count(self, state: CommandState) -> int:
        return sum(1 for r in self.records if r.state is state)

    @property
    def sent(self) -> int:
        return sum(1 for r in self.records if r.sent_at is not None)

    @property
    def ok(self) -> bool:
        return all(r.state is CommandState.COMPLETED for r in self.records)

    @property
    def final_feedback(self) -> Feedback | None:
        """The arm state after the last command that completed.

        The last in request order (the arm runs them in that order): replies
        held up on the line arrive together, with one timestamp, so the time
        they were seen cannot tell which ran last."""
        done = [(r.index, r.result) for r in self.records if r.result is not None]
        return max(done, key=lambda d: d[0])[1].feedback if done else None

    @property
    def weighed_mass(self) -> float | None:
        for r in self.records:
            if r.command.code is CommandCode.WEIGH and r.result is not None:
                return r.result.aux[0]
        return None

    @property
    def first_failure(self) -> CommandRecord | None:
        return next((r for r in self.records if r.state is CommandState.FAILED), None)

    # --- running ---------------------------------------------------------------------

    async def run(self, client: ArmClient) -> None:
        """Submit every command, pipelined; return when each one is final.

        On the first failure the arm is stopped (its queue flushed) and the
        commands not yet sent are marked failed without being sent.  Session
        errors (the link died, the arm refused) propagate after the records
        say what happened.
        """
        self.started_at = trio.current_time()
        failed = trio.Event()
        stop_done = trio.Event()

        async def guard() -> None:
            await failed.wait()
            try:
                await self._stop(client)
            finally:
                stop_done.set()

        # Replies are applied to the records by one task, in request order:
        # with one task per command, replies that arrive together were
        # applied in whatever order trio woke the tasks ("#3 failed" before
        # "#2 completed", accepted times out of order), and the console's
        # predictor, fed in that order, flagged different divergences from
        # run to run (issue 19).
        sent: list[tuple[CommandRecord, CommandHandle]] = []
        wake = _Wake()

        try:
            async with trio.open_nursery() as outer:
                outer.start_soon(guard)
                async with trio.open_nursery() as followers:
                    followers.start_soon(self._apply_in_order, sent, wake, failed)
                    for record in self.records:
                        if failed.is_set():
                            break
                        handle = await client.submit(record.command)
                        record.state = CommandState.SENT
                        record.sent_at = trio.current_time()
                        self.on_change()
                        sent.append((record, handle))
                        followers.start_soon(_notify_on_progress, handle, wake)
                        # Let an immediate rejection be seen before the next submit.
                        await trio.lowlevel.checkpoint()
                        wake.set()
                    wake.closing = True
                    wake.set()
                if failed.is_set():
                    await stop_done.wait()
                outer.cancel_scope.cancel()
        finally:
            now = trio.current_time()
            for record in self.records:
                if not record.state.final:
                    record.state = CommandState.FAILED
                    record.error = record.error or "not run: an earlier command failed"
                    record.reason = record.reason or "NOT_RUN"
                    record.done_at = now
            self.finished_at = now
            self.on_change()

    async def _apply_in_order(
        self,
        sent: list[tuple[CommandRecord, CommandHandle]],
        wake: _Wake,
        failed: trio.Event,
    ) -> None:
        """Apply what the handles say to the records, oldest command first.

        A command's outcome is applied only once every earlier command's is:
        after a resume the arm pushes the outcome of a command that finished
        on the new connection at once, while those that finished during the
        outage are answered only when the re-sent commands reach it, a round
        trip later (seen through ``linksim proxy --cut``: #8 completed 14 s
        before #1).  The arm ran them in order; the records, the console and
        its predictor see them in that order too.
        """
        while True:
            await wake.wait()
            now = trio.current_time()
            earlier_final = True
            for record, handle in sent:
                if self._apply(record, handle, now, may_finish=earlier_final):
                    failed.set()
                earlier_final = earlier_final and record.state.final
            if wake.closing and all(record.state.final for record, _ in sent):
                return

    def _apply(
        self, record: CommandRecord, handle: CommandHandle, now: float, *, may_finish: bool
    ) -> bool:
        """Move ``record`` along as far as ``handle`` went; True if it just failed.

        With ``may_finish`` false (an earlier command is still open) it goes no
        further than ACCEPTED.
        """
        if record.state is CommandState.SENT and handle.position is not None:
            record.state = CommandState.ACCEPTED
            record.accepted_at = now
            self.on_change()
        if record.state.final or not handle.done or not may_finish:
            return False
        record.done_at = now
        error = handle.error
        if error is None:
            record.result = handle.result
            record.state = CommandState.COMPLETED
            self.on_change()
            return False
        record.state = CommandState.FAILED
        if isinstance(error, CommandFailed):
            record.error, record.reason = error.message, error.reason.name
        else:
            record.error, record.reason = str(error), type(error).__name__
        self.on_change()
        return True

    async def _stop(self, client: ArmClient) -> None:
        if all(r.state.final for r in self.records if r.sent_at is not None):
            return  # nothing queued behind the failure: nothing to flush
        self.stopped = True
        # The stop's own reply may be a failure (nothing left to stop): that is fine.
        with contextlib.suppress(CommandFailed, SessionError):
            await client.emergency_stop()


class _Wake:
    """A level-triggered wake-up for the one task that applies replies."""

    def __init__(self) -> None:
        self._event = trio.Event()
        self.closing = False
        """Every command has been submitted: stop once all are final."""

    def set(self) -> None:
        self._event.set()

    async def wait(self) -> None:
        await self._event.wait()
        self._event = trio.Event()


async def _notify_on_progress(handle: CommandHandle, wake: _Wake) -> None:
    """Wake the applier when ``handle`` is accepted and when it is settled."""
    with contextlib.suppress(CommandFailed, SessionError):
        await handle.accepted()
    wake.set()
    with contextlib.suppress(CommandFailed, SessionError):
        await handle.completed()
    wake.set()
