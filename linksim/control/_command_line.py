"""The console's command line, sans-I/O: lines in, previews, sends and outcomes out.

In the spirit of Yamcs's command stack: every command the operator types is

1. **parsed** (:mod:`~linksim.control._vocabulary`: ``move_joint 1 20deg``),
2. **previewed** on the local model from where the commands already in
   flight will leave the arm (:func:`~linksim.control._preview.preview`), and
   refused there if the model says the arm would refuse it -- unless the line
   starts with ``force``,
3. **queued** and handed out as a :class:`Submit` for the I/O layer to send,
4. then its **ACCEPTED / COMPLETED / FAILED** is shown against the prediction:
   the :class:`~linksim.control._predict.Predictor` compares the arm's report
   with the model and says whether they agree.

:class:`CommandStack` does no I/O and reads no clock: :meth:`CommandStack.feed`
takes a line and the time and returns :data:`Output` events (text to show,
commands to send, an emergency stop, a wait, the end); the methods
:meth:`~CommandStack.sent`, :meth:`~CommandStack.accepted`,
:meth:`~CommandStack.completed` and :meth:`~CommandStack.failed` take what
the link reported.  A test feeds it lines; ``linksim console --interactive``
feeds it a terminal (:mod:`~linksim.control._interactive`).

The console's own words: ``help [COMMAND]``, ``status`` (the console's view:
confirmed and predicted state, queue, link), ``queue``, ``history``, ``wait``
(until nothing is in flight), ``force COMMAND``, ``estop`` (immediate,
bypassing the queue), ``quit``.  ``#`` starts a comment.
"""

from __future__ import annotations

import collections
import enum
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from linksim._errors import ConfigError
from linksim.arm import DEFAULT_WORLD, PUMA560, WorldConfig
from tcpstream import Command, CommandCode, CommandResult, Feedback

from ._console import CommandRow, ConsoleSnapshot, render_plain
from ._control import describe
from ._predict import NOT_RUN, Divergence, Predictor
from ._preview import PredictedOutcome, preview
from ._vocabulary import VERBS, CommandSyntaxError, complete, parse_command, verb_of

__all__ = [
    "CONSOLE_WORDS",
    "CommandStack",
    "EmergencyStop",
    "EntryState",
    "Output",
    "Quit",
    "Say",
    "StackEntry",
    "Submit",
    "WaitIdle",
    "complete_line",
]

CONSOLE_WORDS = ("force", "help", "history", "queue", "quit", "exit", "status", "wait")
"""Words the console handles itself (``estop`` is in the language, sent at once)."""

CONSOLE_HELP = {
    "force": "force COMMAND ARGS...: send a command the model says the arm would refuse",
    "help": "help [COMMAND]: the commands, or one command's arguments and an example",
    "history": "the lines typed so far, numbered (the arrow keys recall them)",
    "queue": "the commands sent and not yet answered, with the model's verdict on each",
    "quit": "wait for the commands pending (at most --timeout), then end the session",
    "exit": "as quit",
    "status": "the console's view: confirmed and predicted state, the commands, the link",
    "wait": "take no more lines until every command sent is answered (at most --timeout)",
}
"""``help WORD`` for the console's own words."""

MAX_HISTORY = 1000
"""Lines kept for ``history`` (readline keeps its own for the arrow keys)."""

MAX_ENTRIES = 10_000
"""Commands a session may send: each stays on the stack for ``queue``, the
summary and the model; ten thousand is hours of typing."""


class EntryState(enum.Enum):
    """Where a command typed at the console is."""

    REFUSED = "refused"
    """The model said the arm would refuse it; not sent (``force`` sends it)."""
    QUEUED = "queued"
    """Previewed and handed out to be sent."""
    SENT = "sent"
    ACCEPTED = "accepted"
    COMPLETED = "completed"
    FAILED = "failed"

    @property
    def pending(self) -> bool:
        """Sent (or about to be) and not yet answered for good."""
        return self in (EntryState.QUEUED, EntryState.SENT, EntryState.ACCEPTED)


@dataclass(slots=True)
class StackEntry:
    """One command line's journey; times on the caller's clock (s)."""

    index: int
    line: str
    command: Command
    label: str
    predicted: PredictedOutcome | None
    """None when the model could not run (``force`` sends it unpreviewed)."""
    forced: bool
    state: EntryState
    entered_at: float
    sent_at: float | None = None
    accepted_at: float | None = None
    done_at: float | None = None
    reason: str | None = None
    message: str | None = None
    aux: tuple[float, float, float, float] | None = None
    divergence: Divergence | None = None

    @property
    def prediction(self) -> str:
        """``ok``, the reason the model gave, or ``-`` when it could not run."""
        if self.predicted is None:
            return "-"
        return "ok" if self.predicted.ok else self.predicted.reason.name

    def as_dict(self, origin: float) -> dict[str, Any]:
        def rel(t: float | None) -> float | None:
            return None if t is None else round(t - origin, 3)

        out: dict[str, Any] = {
            "index": self.index,
            "line": self.line,
            "command": self.command.code.name,
            "label": self.label,
            "predicted": self.prediction,
            "forced": self.forced,
            "state": self.state.value,
            "sent_s": rel(self.sent_at),
            "accepted_s": rel(self.accepted_at),
            "done_s": rel(self.done_at),
        }
        if self.reason is not None:
            out["reason"] = self.reason
            out["message"] = self.message
        if self.divergence is not None:
            out["as_predicted"] = not self.divergence.flagged
        if self.aux is not None and self.command.code is CommandCode.WEIGH:
            out["mass_kg"] = round(self.aux[0], 4)
        return out


@dataclass(frozen=True, slots=True)
class Say:
    """Show ``text`` to the operator (one or more lines)."""

    text: str


@dataclass(frozen=True, slots=True)
class Submit:
    """Send ``command`` (entry ``index``); report back with :meth:`CommandStack.sent`."""

    index: int
    command: Command


@dataclass(frozen=True, slots=True)
class EmergencyStop:
    """Send the emergency stop now, bypassing the queue."""


@dataclass(frozen=True, slots=True)
class WaitIdle:
    """Take no more lines until nothing is pending (:attr:`CommandStack.idle`)."""


@dataclass(frozen=True, slots=True)
class Quit:
    """The operator is done: wait for what is pending, then end the session."""


Output = Say | Submit | EmergencyStop | WaitIdle | Quit
LinkProbe = Callable[[], Mapping[str, Any]]


def complete_line(text: str) -> list[str]:
    """Completions of the last word of ``text`` (the line so far): command and
    console words, then keywords, flags and units (``force`` and ``help`` take a command)."""
    words = text.split()
    if words and words[0] == "force" and (len(words) > 1 or text.endswith(" ")):
        return complete(text.split(None, 1)[1] if len(words) > 1 else "")
    if words and words[0] == "help" and (len(words) > 1 or text.endswith(" ")):
        partial = words[1] if len(words) > 1 else ""
        return sorted(n for n in (*VERBS, *CONSOLE_HELP) if n.startswith(partial))
    return complete(text, CONSOLE_WORDS)


def _xyz(v: tuple[float, float, float]) -> str:
    return "(" + ", ".join(f"{x:+.3f}" for x in v) + ")"


@dataclass(slots=True)
class CommandStack:
    """The command line's state: entries, history, the model.  See the module docstring.

    ``world`` is the model's (and, unless told otherwise, the arm's)
    starting world.  ``origin`` is the caller's clock at the start (times
    shown are from it).  ``link`` returns the link figures ``status`` shows.
    """

    world: WorldConfig = DEFAULT_WORLD
    origin: float = 0.0
    link: LinkProbe | None = None
    predictor: Predictor = field(init=False)
    entries: list[StackEntry] = field(init=False, default_factory=list)
    history: collections.deque[str] = field(
        init=False, default_factory=lambda: collections.deque(maxlen=MAX_HISTORY)
    )
    rejected: int = field(init=False, default=0)
    """Lines that made no command (typos, refusals by the model)."""
    stops: int = field(init=False, default=0)
    _stopped_at: Feedback | None = field(init=False, default=None)
    """The arm's state in the emergency stop's reply, until the commands it halted are settled."""

    def __post_init__(self) -> None:
        self.predictor = Predictor(self.world)

    # --- state ------------------------------------------------------------------------

    @property
    def idle(self) -> bool:
        """Nothing is waiting to be sent or answered."""
        return not any(e.state.pending for e in self.entries)

    @property
    def pending(self) -> list[StackEntry]:
        return [e for e in self.entries if e.state.pending]

    def count(self, state: EntryState) -> int:
        return sum(1 for e in self.entries if e.state is state)

    @property
    def ok(self) -> bool:
        """Every line made a command, and every command sent completed."""
        return self.rejected == 0 and all(
            e.state is EntryState.COMPLETED for e in self.entries if e.sent_at is not None
        )

    def entry(self, index: int) -> StackEntry:
        return self.entries[index - 1]

    def _t(self, now: float) -> str:
        return f"[{now - self.origin:8.2f}]"

    # --- lines --------------------------------------------------------------------------

    def feed(self, line: str, now: float) -> list[Output]:
        """One line from the operator."""
        text = line.split("#", 1)[0].strip()
        if not text:
            return []
        self.history.append(text)
        word, *more = text.split(None, 1)
        rest = more[0].strip() if more else ""
        if word in ("quit", "exit"):
            return [Quit()]
        if word == "help":
            return [Say(self._help(rest))]
        if word == "status":
            return [Say(render_plain(self.snapshot(now)))]
        if word == "queue":
            return [Say(self._queue_text(now))]
        if word == "history":
            return [Say("\n".join(f"{i:4d}  {h}" for i, h in enumerate(self.history, 1)))]
        if word == "wait":
            return [WaitIdle()]
        if word == "estop":
            self.stops += 1
            return [
                Say(f"{self._t(now)} EMERGENCY STOP: sent at once; the queued commands fail"),
                EmergencyStop(),
            ]
        forced = word == "force"
        if forced:
            text = rest
            if not text:
                self.rejected += 1
                return [Say("error: force what? (force COMMAND ARGS...)")]
        return self._command(text, now, forced)

    def _command(self, text: str, now: float, forced: bool) -> list[Output]:
        try:
            command = parse_command(text)
        except CommandSyntaxError as exc:
            self.rejected += 1
            return [Say(f"error: {exc}")]
        if command.code is CommandCode.EMERGENCY_STOP:
            return self.feed("estop", now)
        if len(self.entries) >= MAX_ENTRIES:
            self.rejected += 1
            return [Say(f"error: this session has sent {MAX_ENTRIES} commands; start another")]
        index = len(self.entries) + 1
        before = [e.command for e in self.pending]
        try:
            outcome: PredictedOutcome | None = preview(
                [*before, command], self.predictor.base
            ).outcomes[-1]
        except ConfigError as exc:  # the arm reported a pose the model cannot stand in
            outcome = None
            self.predictor.model_error = str(exc)
        entry = StackEntry(
            index, text, command, describe(command), outcome, forced, EntryState.QUEUED, now
        )
        verdict = self._verdict(outcome)
        if (outcome is None or not outcome.ok) and not forced:
            entry.state = EntryState.REFUSED
            self.entries.append(entry)
            self.rejected += 1
            return [
                Say(
                    f"#{index} {entry.label} -- model: {verdict}; not sent "
                    f"('force {text}' sends it anyway)"
                )
            ]
        self.entries.append(entry)
        note = " (forced)" if forced and (outcome is None or not outcome.ok) else ""
        return [
            Say(f"#{index} {entry.label} -- model: {verdict}; queued{note}"),
            Submit(index, command),
        ]

    def _verdict(self, outcome: PredictedOutcome | None) -> str:
        if outcome is None:
            return f"cannot predict ({self.predictor.model_error})"
        if outcome.ok:
            took = f"in {outcome.duration:.2f} s" if outcome.duration else "(no motion)"
            return f"completes {took}, hand at {_xyz(outcome.feedback.p)} m"
        return f"{outcome.reason.name}: {outcome.message}"

    # --- what the link reports ----------------------------------------------------------

    def sent(self, index: int, now: float) -> list[Output]:
        """Entry ``index`` went out (the client took it)."""
        entry = self.entry(index)
        if entry.state is not EntryState.QUEUED:
            return []
        entry.state, entry.sent_at = EntryState.SENT, now
        self.predictor.sent(index, entry.command)
        return [Say(f"{self._t(now)} #{index} SENT")]

    def accepted(self, index: int, now: float, position: int | None = None) -> list[Output]:
        """The arm queued entry ``index`` (at ``position``, when known)."""
        entry = self.entry(index)
        if entry.state is not EntryState.SENT:
            return []
        entry.state, entry.accepted_at = EntryState.ACCEPTED, now
        where = f" (queue position {position})" if position is not None else ""
        return [Say(f"{self._t(now)} #{index} ACCEPTED{where}")]

    def completed(self, index: int, now: float, result: CommandResult) -> list[Output]:
        """The arm completed entry ``index`` and reported ``result``."""
        entry = self.entry(index)
        if not entry.state.pending:
            return []
        entry.state, entry.done_at, entry.aux = EntryState.COMPLETED, now, result.aux
        divergence = self.predictor.completed(index, now, feedback=result.feedback)
        entry.divergence = divergence
        extra = ""
        if entry.command.code is CommandCode.WEIGH:
            extra = f", weighed {result.aux[0]:.3f} kg"
        elif entry.command.code is CommandCode.SQUEEZE:
            extra = f", gripping with {result.aux[0]:.0f} N"
        return [Say(f"{self._t(now)} #{index} COMPLETED{extra}: {self._against(entry)}")]

    def failed(
        self,
        index: int,
        now: float,
        reason: str,
        message: str,
        feedback: Feedback | None = None,
        *,
        session: bool = False,
    ) -> list[Output]:
        """Entry ``index`` failed (``reason``: the FailureReason's name; with
        ``session``, the session error's type name: the link or the session
        ended, so whether it ran is the session's to say, not the model's)."""
        entry = self.entry(index)
        if not entry.state.pending:
            return []
        entry.state, entry.done_at = EntryState.FAILED, now
        entry.reason, entry.message = reason, message
        failure = "NOT_RUN" if session else reason
        entry.divergence = self.predictor.completed(index, now, feedback=feedback, failure=failure)
        if session:
            against = "the session's failure, not the arm's: nothing to compare with the model"
        elif reason in NOT_RUN:
            against = "not run, for reasons of the session, not of the world"
        else:
            against = self._against(entry)
        self._settle_stop(now)
        return [Say(f"{self._t(now)} #{index} FAILED: {reason}: {message} -- {against}")]

    def _settle_stop(self, now: float) -> None:
        """After an emergency stop, once the commands it halted are settled, the model
        starts again from where the stop left the arm (a halted motion ends part way)."""
        if self._stopped_at is not None and self.idle:
            self.predictor.reset(self._stopped_at, now)
            self._stopped_at = None

    def _against(self, entry: StackEntry) -> str:
        """The outcome against the model's prediction, in words."""
        d = entry.divergence
        predicted = entry.prediction
        actual = "ok" if entry.state is EntryState.COMPLETED else (entry.reason or "?")
        if d is None:
            if predicted == actual:
                return f"as the model predicted ({predicted})"
            return f"the model predicted {predicted} (no comparison: {self.predictor.model_error})"
        size = (
            f"joints {math.degrees(d.joint_error):.2f} deg, hand {d.position_error * 1000:.1f} mm, "
            f"fingers {d.opening_error * 1000:.1f} mm from the model"
        )
        if not d.flagged:
            return f"as predicted ({size})"
        what = d.outcome or "the arm's state differs from the model"
        return f"DIVERGES from the model: {what} ({size}); the model now follows the arm"

    def telemetry(self, feedback: Feedback, now: float) -> list[Output]:
        """A telemetry sample: compared with the predicted path while commands are
        pending (``status`` shows the counts); while none is, the model stands where
        the arm says it is, so the next preview starts from the real arm (one that a
        previous session left elsewhere, or moved by hand)."""
        if self.idle:
            self.predictor.reset(feedback, now)
        else:
            self.predictor.observe(feedback, now)
        return []

    def stopped(
        self, now: float, feedback: Feedback | None = None, error: str | None = None
    ) -> list[Output]:
        """The emergency stop's reply came back: the arm's state (``feedback``),
        or ``error``, why it did not work."""
        if error is not None:
            return [Say(f"{self._t(now)} EMERGENCY STOP: {error}")]
        self._stopped_at = feedback
        self._settle_stop(now)
        where = "" if feedback is None else f", hand at {_xyz(feedback.p)} m"
        return [Say(f"{self._t(now)} EMERGENCY STOP: the arm stopped{where}")]

    # --- views ------------------------------------------------------------------------------

    def snapshot(self, now: float) -> ConsoleSnapshot:
        """The console's state (rendered by ``status``)."""
        p = self.predictor

        def rel(t: float | None) -> float | None:
            return None if t is None else t - self.origin

        rows = tuple(
            CommandRow(
                e.index,
                e.label,
                e.state.value,
                rel(e.sent_at),
                rel(e.accepted_at),
                rel(e.done_at),
                e.prediction,
                e.reason,
            )
            for e in self.entries[-20:]
        )
        return ConsoleSnapshot(
            title="telelink console: command line",
            clock=now - self.origin,
            mode="driving",
            confirmed=p.confirmed,
            predicted=p.predicted,
            lower=PUMA560.lower,
            upper=PUMA560.upper,
            max_opening=self.world.max_opening,
            commands=rows,
            link=dict(self.link()) if self.link is not None else {},
            in_flight=len(p.in_flight),
            comparisons=p.comparisons,
            flagged=p.flagged,
            max_joint_error=p.max_joint_error,
        )

    def _queue_text(self, now: float) -> str:
        pending = self.pending
        if not pending:
            return "queue: empty (nothing in flight)"
        lines = [f"queue: {len(pending)} pending"]
        for e in pending:
            lines.append(f"  #{e.index:<3} {e.state.value:<9} model {e.prediction:<12} {e.label}")
        return "\n".join(lines)

    def _help(self, topic: str) -> str:
        if topic in CONSOLE_HELP:
            return f"{topic}: {CONSOLE_HELP[topic]}"
        if topic:
            try:
                verb = verb_of(topic)
            except CommandSyntaxError as exc:
                return f"error: {exc}"
            params = "; ".join(p.describe() for p in verb.params)
            if verb.repeated is not None:
                params = verb.repeated.describe() + (f"; {params}" if params else "")
            return (
                f"{verb.usage()}\n  {verb.summary}\n  arguments: {params or 'none'}\n"
                f"  example: {verb.example}"
            )
        width = max(len(v.name) for v in VERBS.values())
        lines = ["commands (units on every length and angle: mm, cm, m, deg, rad; s; N; %):"]
        lines += [f"  {v.name:<{width}}  {v.example:<44} {v.summary}" for v in VERBS.values()]
        lines.append(
            "console: help [COMMAND], status, queue, history, wait, force COMMAND, quit "
            "(# starts a comment; Tab completes)"
        )
        return "\n".join(lines)

    def complete(self, text: str) -> list[str]:
        """Completions for ``text`` (the line so far): :func:`complete_line`."""
        return complete_line(text)

    def summary(self, now: float) -> dict[str, Any]:
        """The session as a JSON-ready record (``--json``)."""
        p = self.predictor
        return {
            "ok": self.ok,
            "commands": [e.as_dict(self.origin) for e in self.entries],
            "rejected_lines": self.rejected,
            "emergency_stops": self.stops,
            "model": {
                "comparisons": p.comparisons,
                "flagged": p.flagged,
                "max_joint_error_rad": round(p.max_joint_error, 6),
                "max_position_error_m": round(p.max_position_error, 6),
            },
            "seconds": round(now - self.origin, 3),
        }
