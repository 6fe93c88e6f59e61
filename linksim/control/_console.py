"""The operator console: confirmed and predicted arm state, the command queue, the link.

Seed 004 section 4: the operator sees the robot's angles against their
joint limits, the gripper and force data, the state forwarded every tenth
sample; seed 003 section 2.2: the local model shows where the commands
already sent will take the arm.  The console is drawn from a plain
:class:`ConsoleSnapshot`, so the same state renders as a rich layout on a
terminal (:func:`render`) or as plain lines (:func:`render_plain`) when the
output is not a TTY -- and a test can render either to a string.

:class:`ConsoleSession` ties a :class:`~linksim.control._control.TaskRun` (or, for
an observer, nothing), a :class:`~linksim.control._predict.Predictor`, the
telemetry log and a link probe together; its hooks are called from
``TaskRun.on_change`` and the telemetry loop.
"""

from __future__ import annotations

import io
import math
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TextIO

from rich.console import Console, Group, RenderableType
from rich.live import Live
from rich.table import Table
from rich.text import Text

from linksim.arm import PUMA560, ArmModel, WorldConfig
from tcpstream import CommandCode, Feedback

from ._control import CommandRecord, CommandState, TaskRun
from ._predict import Predictor
from ._preview import PreviewReport
from ._telemetry_log import TelemetryLog

__all__ = [
    "CommandRow",
    "ConsoleSession",
    "ConsoleSnapshot",
    "render",
    "render_plain",
    "render_text",
]

LinkProbe = Callable[[], Mapping[str, Any]]

STATE_LINE_INTERVAL = 1.0
"""s: line output prints the arm state at most this often (telemetry comes
at 12.5 Hz, seed 004's every tenth sample: too fast to read as lines)."""

BAR = 24
"""Characters in a joint bar: one per 1/24 of the joint's range (~13 deg on the PUMA)."""


@dataclass(frozen=True, slots=True)
class CommandRow:
    """One line of the command queue; times in s from the start of the run."""

    index: int
    label: str
    state: str
    sent: float | None
    accepted: float | None
    done: float | None
    predicted: str
    """The model's verdict: ``ok``, a refusal's reason, or ``-`` when not previewed."""
    reason: str | None = None


@dataclass(frozen=True, slots=True)
class ConsoleSnapshot:
    """Everything the console shows at one moment (plain data; render it as you like).

    Joint angles in radians, ``lower``/``upper`` the joint limits (rad),
    openings in metres, ``clock`` in s from the start of the run.
    """

    title: str
    clock: float
    mode: str
    confirmed: Feedback | None
    predicted: Feedback | None
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    max_opening: float
    commands: tuple[CommandRow, ...] = ()
    link: Mapping[str, Any] = field(default_factory=dict)
    in_flight: int = 0
    comparisons: int = 0
    flagged: int = 0
    max_joint_error: float = 0.0
    last_flag: str | None = None
    preview: str | None = None
    status: str | None = None
    force: str | None = None
    """Seed 004's force data as far as the arm reports it: the commanded grip
    force while holding (SQUEEZE's reply) and the last weighed mass (WEIGH)."""
    teleop: tuple[str, ...] = ()
    """While teleoperating (mode ``teleoperating``): the teleoperation view's lines
    (:func:`linksim.teleop.render_view`) -- mode and buttons, force/torque bars,
    predicted vs confirmed hand, setpoint age, the sample channel's link."""


def _bar(q: float, lo: float, hi: float) -> str:
    """``[----|-----]``: where ``q`` sits between the limits; ``!`` when outside."""
    if not lo <= q <= hi:
        return "!" * (BAR + 2)
    k = min(BAR - 1, int((q - lo) / (hi - lo) * BAR))
    return "[" + "-" * k + "|" + "-" * (BAR - 1 - k) + "]"


def _deg(q: float) -> str:
    return f"{math.degrees(q):+7.1f}"


def _xyz(v: tuple[float, float, float]) -> str:
    return "(" + ", ".join(f"{x:+.3f}" for x in v) + ")"


def _time(t: float | None) -> str:
    return "-" if t is None else f"{t:.2f}"


def _link_text(link: Mapping[str, Any]) -> str:
    parts = []
    rtt = link.get("rtt_s")
    if isinstance(rtt, float) and math.isfinite(rtt):
        parts.append(f"RTT {rtt:.2f} s")
    for key, name in (
        # Most telling first: a narrow live view cuts the line at its end.
        ("window_occupancy", "window"),
        ("pending", "in flight"),
        ("retransmissions", "retransmissions"),
        ("check_failures", "check failures"),
        ("reconnects", "reconnects"),
        ("packets_sent", "packets out"),
        ("packets_received", "packets in"),
        ("bytes_sent", "out"),
        ("bytes_received", "in"),
    ):
        if key in link:
            parts.append(f"{name} {link[key]}")
    return ", ".join(parts) if parts else "connecting"


def _gripper(f: Feedback | None) -> str:
    if f is None:
        return "-"
    switches = ("L" if f.tactile_left else "-") + ("R" if f.tactile_right else "-")
    return f"{f.finger_opening * 1000:5.1f} mm  tactile {switches}"


def _state_summary(f: Feedback) -> str:
    """One line of arm state for line output (degrees, metres)."""
    joints = ", ".join(f"{math.degrees(q):.1f}" for q in f.joints)
    return f"state: joints ({joints}) deg, P {_xyz(f.p)} m, gripper {_gripper(f)}"


def _state_lines(s: ConsoleSnapshot) -> list[str]:
    lines = ["joint        confirmed  predicted  limits (deg)"]
    for j in range(len(s.lower)):
        c = s.confirmed.joints[j] if s.confirmed else None
        p = s.predicted.joints[j] if s.predicted else None
        bar = _bar(c, s.lower[j], s.upper[j]) if c is not None else " " * (BAR + 2)
        lines.append(
            f"  {j + 1}  {bar} {_deg(c) if c is not None else '      -'}  "
            f"{_deg(p) if p is not None else '      -'}  "
            f"{math.degrees(s.lower[j]):.0f}..{math.degrees(s.upper[j]):.0f}"
        )
    for name, f in (("confirmed", s.confirmed), ("predicted", s.predicted)):
        if f is None:
            lines.append(f"{name:>9}: -")
            continue
        lines.append(
            f"{name:>9}: P {_xyz(f.p)}  S {_xyz(f.s)}  A {_xyz(f.a)}  gripper {_gripper(f)}"
            + (f"  error {f.error.name}" if f.error.value else "")
        )
    return lines


def _model_line(s: ConsoleSnapshot) -> str:
    if s.mode == "teleoperating":
        return "model: the hand's own increments (predicted) against the arm's replies (confirmed)"
    if s.mode == "observer":
        return "model: none (an observer does not see the commands, so it predicts nothing)"
    text = (
        f"model: {s.in_flight} in flight, {s.comparisons} comparisons, {s.flagged} flagged, "
        f"max joint error {math.degrees(s.max_joint_error):.2f} deg"
    )
    if s.last_flag:
        text += f"; last flag: {s.last_flag}"
    return text


def render_plain(s: ConsoleSnapshot) -> str:
    """The snapshot as plain text lines (no colour, no cursor movement)."""
    lines = [f"{s.title}  [{s.mode}]  t={s.clock:.2f} s"]
    if s.preview:
        lines.append(f"preview: {s.preview}")
    lines += s.teleop
    if not s.teleop or s.confirmed is not None:
        lines += _state_lines(s)
    if s.commands:
        lines.append(" #  state      sent  accepted   done  model  command")
        for r in s.commands:
            lines.append(
                f"{r.index:2d}  {r.state:<9} {_time(r.sent):>5} {_time(r.accepted):>9} "
                f"{_time(r.done):>6}  {r.predicted:<5}  {r.label}"
                + (f"  [{r.reason}]" if r.reason else "")
            )
    if s.force:
        lines.append("force: " + s.force)
    lines.append("link: " + _link_text(s.link))
    lines.append(_model_line(s))
    if s.status:
        lines.append(s.status)
    return "\n".join(lines)


_STYLE = {
    "queued": "dim",
    "sent": "yellow",
    "accepted": "cyan",
    "completed": "green",
    "failed": "bold red",
}


DETAIL_LEVELS = 4
"""How much a live frame shows, from 0 (everything) to 3 (the least): 1 drops
the S and A vectors, 2 also the limit bars, the preview line and the pose
table (the gripper keeps one line), 3 also the joint table (one line each for
confirmed and predicted).  The link and model lines are never dropped."""


def _queue_window(rows: tuple[CommandRow, ...], room: int | None) -> tuple[int, int]:
    """Which command rows fit in ``room`` terminal rows: [start, stop).

    The window keeps two finished commands above the first unfinished one
    (the operator sees what just happened and what runs next).
    """
    if room is None or len(rows) <= max(1, room):
        return 0, len(rows)
    room = max(1, room - 1)  # one row says what is hidden
    active = next(
        (i for i, r in enumerate(rows) if r.state not in ("completed", "failed")), len(rows)
    )
    start = max(0, min(active - 2, len(rows) - room))
    return start, start + room


def _plain_table() -> Table:
    return Table(box=None, pad_edge=False, show_edge=False)


def _joint_table(s: ConsoleSnapshot, bars: bool) -> Table:
    state = _plain_table()
    names = ["joint", "position against limits", "confirmed", "predicted", "limits"]
    for name in names if bars else [n for n in names if n != "position against limits"]:
        state.add_column(name, justify="right" if name in ("confirmed", "predicted") else "left")
    for j in range(len(s.lower)):
        c = s.confirmed.joints[j] if s.confirmed else None
        p = s.predicted.joints[j] if s.predicted else None
        near = c is not None and min(c - s.lower[j], s.upper[j] - c) < math.radians(10)
        bar = Text(_bar(c, s.lower[j], s.upper[j]) if c is not None else "", "red" if near else "")
        cells: list[RenderableType] = [str(j + 1)]
        if bars:
            cells.append(bar)
        cells += [
            Text(_deg(c), "red" if near else "") if c is not None else "-",
            _deg(p) if p is not None else "-",
            f"{math.degrees(s.lower[j]):.0f}..{math.degrees(s.upper[j]):.0f} deg",
        ]
        state.add_row(*cells)
    return state


def _pose_table(s: ConsoleSnapshot, vectors: bool) -> Table:
    poses = _plain_table()
    columns = ("", "P (m)", "S", "A", "gripper", "error") if vectors else ("", "P (m)", "gripper")
    for name in columns:
        poses.add_column(name)
    for name, f in (("confirmed", s.confirmed), ("predicted", s.predicted)):
        if f is None:
            poses.add_row(name, *["-"] * (len(columns) - 1))
        elif vectors:
            poses.add_row(name, _xyz(f.p), _xyz(f.s), _xyz(f.a), _gripper(f), f.error.name)
        else:
            error = f"  {f.error.name}" if f.error.value else ""
            poses.add_row(name, _xyz(f.p), _gripper(f) + error)
    return poses


def _joint_lines(s: ConsoleSnapshot) -> list[RenderableType]:
    out: list[RenderableType] = []
    for name, f in (("confirmed", s.confirmed), ("predicted", s.predicted)):
        joints = "-" if f is None else " ".join(_deg(q).strip() for q in f.joints) + " deg"
        gripper = "" if f is None else f", gripper {_gripper(f)}"
        out.append(Text(f"{name}: {joints}{gripper}", no_wrap=True, overflow="ellipsis"))
    return out


def _queue_table(s: ConsoleSnapshot, start: int, stop: int) -> Table:
    queue = _plain_table()
    for name in ("#", "state", "sent", "accepted", "done", "model", "command"):
        queue.add_column(name, justify="right" if name in ("#", "sent", "done") else "left")
    for r in s.commands[start:stop]:
        label = r.label + (f"  [{r.reason}]" if r.reason else "")
        queue.add_row(
            str(r.index),
            Text(r.state, _STYLE.get(r.state, "")),
            _time(r.sent),
            _time(r.accepted),
            _time(r.done),
            Text(r.predicted, "green" if r.predicted == "ok" else "bold red"),
            Text(label, no_wrap=True, overflow="ellipsis"),
        )
    return queue


def _state_parts(
    s: ConsoleSnapshot, detail: int, line: Callable[[str], Text]
) -> list[RenderableType]:
    """The joint and pose tables at ``detail``."""
    parts: list[RenderableType] = []
    if detail < 3:
        parts.append(_joint_table(s, bars=detail < 2))
    if detail < 2:
        parts.append(_pose_table(s, vectors=detail < 1))
    elif detail == 3:
        parts += _joint_lines(s)
    else:
        gripper = f"gripper: confirmed {_gripper(s.confirmed)}, predicted {_gripper(s.predicted)}"
        parts.append(line(gripper))
    return parts


def _parts(
    s: ConsoleSnapshot, detail: int, window: tuple[int, int] | None, fit: bool
) -> list[RenderableType]:
    """The frame at ``detail`` with the queue rows ``window`` (None: no queue).

    ``fit``: the link and model lines stay one row each (cut with an ellipsis)."""

    def line(text: str, style: str = "") -> Text:
        return Text(text, style=style, no_wrap=fit, overflow="ellipsis" if fit else "fold")

    parts: list[RenderableType] = [line(f"{s.title}  [{s.mode}]  t={s.clock:.2f} s", "bold")]
    if s.preview and detail < 2:
        parts.append(line("preview: " + s.preview))
    # The teleoperation view is the point of the frame while teleoperating: never cut.
    parts += [Text(t, no_wrap=True, overflow="ellipsis") for t in s.teleop]
    if not s.teleop or s.confirmed is not None:
        # (Teleoperating without command telemetry the tables would be all dashes.)
        parts += _state_parts(s, detail, line)
    if s.commands and window is not None:
        start, stop = window
        parts.append(_queue_table(s, start, stop))
        hidden = len(s.commands) - (stop - start)
        if hidden:
            parts.append(
                line(f"   ({start} earlier, {len(s.commands) - stop} later commands not shown)")
            )
    if s.force:
        parts.append(line("force: " + s.force))
    parts.append(line("link: " + _link_text(s.link)))
    parts.append(line(_model_line(s), "bold red" if s.flagged else ""))
    if s.status:
        parts.append(line(s.status, "bold"))
    return parts


QUEUE_ROWS = 8
"""Command rows a live frame keeps before it drops detail (or all there are)."""


def _tables_fit(s: ConsoleSnapshot, detail: int, width: int) -> bool:
    """The joint and pose tables at ``detail`` take one row per line at ``width``."""
    if detail < 3 and _rows([_joint_table(s, bars=detail < 2)], width) > 1 + len(s.lower):
        return False
    return detail >= 2 or _rows([_pose_table(s, vectors=detail < 1)], width) <= 3


def _rows(parts: list[RenderableType], width: int) -> int:
    """Terminal rows ``parts`` take at ``width`` columns."""
    out = io.StringIO()
    Console(file=out, width=width, color_system=None, force_terminal=False).print(Group(*parts))
    return len(out.getvalue().splitlines())


def render(
    s: ConsoleSnapshot, height: int | None = None, width: int | None = None
) -> RenderableType:
    """The snapshot as a rich layout: state table, command table, link and model lines.

    With ``height`` (terminal rows; ``width`` columns, default 80) the frame
    fits the terminal: detail is dropped step by step (:data:`DETAIL_LEVELS`)
    until no table wraps and the queue keeps :data:`QUEUE_ROWS` rows (or all
    it has), then the queue shows the window that fits.  The link and model lines always stay, one
    row each.  Without ``height`` everything is shown (the final frame).
    """
    if height is None:
        return Group(*_parts(s, 0, (0, len(s.commands)), fit=False))
    columns = width or 80
    want = min(len(s.commands), QUEUE_ROWS)
    for detail in range(DETAIL_LEVELS):
        if not _tables_fit(s, detail, columns):
            continue  # a table wrapping its rows is worse than less detail
        # The queue's header row counts as fixed; its rows get the rest.
        fixed = _rows(_parts(s, detail, None, fit=True), columns) + (1 if s.commands else 0)
        room = height - fixed
        if room >= want:
            break
    window = _queue_window(s.commands, max(1, room))
    return Group(*_parts(s, detail, window, fit=True))


def render_text(s: ConsoleSnapshot, width: int = 120) -> str:
    """The rich layout rendered to plain text (no colour) at ``width`` columns."""
    out = io.StringIO()
    Console(file=out, width=width, color_system=None, force_terminal=False).print(render(s))
    return out.getvalue()


class ConsoleSession:
    """What the console shows, kept up to date: run + predictor + log + link probe.

    ``run`` is None for an observer.  ``clock`` reads the run's clock (s);
    ``origin`` is its reading at the start.  Call :meth:`changed` from
    ``TaskRun.on_change`` and :meth:`telemetry` for every telemetry sample.
    """

    def __init__(
        self,
        title: str,
        world: WorldConfig,
        *,
        run: TaskRun | None,
        clock: Callable[[], float],
        origin: float,
        log: TelemetryLog | None = None,
        link: LinkProbe | None = None,
        model: ArmModel = PUMA560,
        out: TextIO | None = None,
        live: bool | None = None,
    ) -> None:
        self.title = title
        self.world = world
        self.run = run
        self.predictor = Predictor(world)
        self.preview: PreviewReport | None = None
        self.status: str | None = None
        self._clock = clock
        self._origin = origin
        self._log = log
        self.link: LinkProbe | None = link
        """Returns the link figures shown (RTT, window occupancy, retransmissions...)."""
        self.teleop: Callable[[], Sequence[str]] | None = None
        """While teleoperating: returns the teleoperation view's lines (the console's
        ``teleoperating`` mode; ``linksim teleop --live`` sets it)."""
        self._model = model
        self._seen: dict[int, CommandState] = {}
        self._out = out if out is not None else sys.stderr
        self._live_wanted = self._out.isatty() if live is None else live
        self._live: Live | None = None
        self._console: Console | None = None
        self._last_flag: str | None = None
        self.telemetry_samples = 0
        self._last_state_line = -math.inf

    # --- display -------------------------------------------------------------------

    def __enter__(self) -> ConsoleSession:
        if self._live_wanted:
            console = Console(file=self._out)
            self._console = console
            self._live = Live(self._render(), console=console, auto_refresh=False)
            self._live.__enter__()
        else:
            print(render_plain(self.snapshot()), file=self._out, flush=True)
        return self

    @property
    def is_live(self) -> bool:
        """Redrawn in place (a terminal), rather than printed as lines."""
        return self._live_wanted

    def __exit__(self, *exc: object) -> None:
        if self._live is not None:
            # The last frame stays on the screen: all of it (rich stops a
            # live display with overflow visible, so nothing is cut).
            self._live.update(render(self.snapshot()))
            self._live.__exit__(None, None, None)
            self._live = None
        else:
            print(render_plain(self.snapshot()), file=self._out, flush=True)

    def _render(self) -> RenderableType:
        if self._console is None:
            return render(self.snapshot())
        size = self._console.size
        return render(self.snapshot(), size.height, size.width)

    def _line(self, text: str) -> None:
        if self._live is None:
            print(f"[{self._clock() - self._origin:8.2f}] {text}", file=self._out, flush=True)

    def refresh(self) -> None:
        """Redraw (live mode); line mode prints events as they happen instead."""
        if self._live is not None:
            self._live.update(self._render(), refresh=True)

    # --- inputs ----------------------------------------------------------------------

    def set_preview(self, report: PreviewReport) -> None:
        self.preview = report
        if self._log is not None:
            self._log.record(self._clock(), "preview", report.as_dict())
        self._line("preview: " + self._preview_text(report))

    def changed(self) -> None:
        """A command changed state (``TaskRun.on_change``): feed the model, log, redraw."""
        now = self._clock()
        if self.run is None:
            return
        for record in self.run.records:
            before = self._seen.get(record.index, CommandState.QUEUED)
            if record.state is before:
                continue
            self._seen[record.index] = record.state
            self._command_event(record, before, now)
        self.refresh()

    def _command_event(self, record: CommandRecord, before: CommandState, now: float) -> None:
        state = record.state
        if before is CommandState.QUEUED and record.sent_at is not None:
            self.predictor.sent(record.index, record.command)
            self._event(record, "sent", now)
        if state is CommandState.ACCEPTED:
            self._event(record, "accepted", now)
        if state.final:
            feedback = record.result.feedback if record.result is not None else None
            failure = None if state is CommandState.COMPLETED else record.reason
            divergence = self.predictor.completed(
                record.index, now, feedback=feedback, failure=failure
            )
            self._event(record, state.value, now, record.reason if failure else None)
            if feedback is not None and self._log is not None:
                self._log.state(now, "completion", feedback)
            if divergence is not None:
                if self._log is not None:
                    self._log.record(now, "divergence", divergence.as_dict())
                if divergence.flagged:
                    self._last_flag = (
                        f"#{record.index} {divergence.outcome or ''} joint "
                        f"{math.degrees(divergence.joint_error):.2f} deg, hand "
                        f"{divergence.position_error * 1000:.1f} mm off the model"
                    )
                    self._line("DIVERGENCE " + self._last_flag)
            predicted = self.predictor.predicted
            if predicted is not None and self._log is not None:
                self._log.state(now, "predicted", predicted)

    def _event(
        self, record: CommandRecord, event: str, now: float, reason: str | None = None
    ) -> None:
        if self._log is not None:
            self._log.command(
                now, record.index, record.command.code.name, record.label, event, reason
            )
        self._line(f"#{record.index} {event}: {record.label}" + (f" [{reason}]" if reason else ""))

    def telemetry(self, feedback: Feedback) -> None:
        """A telemetry sample (every tenth control sample, seed 004)."""
        now = self._clock()
        self.telemetry_samples += 1
        if self._log is not None:
            self._log.state(now, "telemetry", feedback)
        if self.run is None:
            # An observer does not know what the controller sent: it shows
            # the arm's reports and predicts nothing (no false divergences).
            self.predictor.reset(feedback, now)
        else:
            divergence = self.predictor.observe(feedback, now)
            if divergence.flagged and self._log is not None:
                self._log.record(now, "divergence", divergence.as_dict())
        if self._live is None and now - self._last_state_line >= STATE_LINE_INTERVAL:
            self._last_state_line = now
            self._line(_state_summary(feedback))
        self.refresh()

    # --- output ----------------------------------------------------------------------

    @staticmethod
    def _preview_text(report: PreviewReport) -> str:
        refusal = report.first_refusal
        if refusal is None:
            return (
                f"all {len(report.outcomes)} commands pass, {report.duration:.2f} s of motion, "
                f"ends at P {_xyz(report.final.p)}"
            )
        return (
            f"#{refusal.index} ({refusal.label}) would be refused: "
            f"{refusal.reason.name}: {refusal.message}"
        )

    def snapshot(self) -> ConsoleSnapshot:
        """The console's state now."""
        predictions: dict[int, str] = {}
        if self.preview is not None:
            predictions = {o.index: "ok" if o.ok else o.reason.name for o in self.preview.outcomes}
        rows: tuple[CommandRow, ...] = ()
        if self.run is not None:
            origin = self.run.started_at or self._origin

            def rel(t: float | None) -> float | None:
                return None if t is None else t - origin

            rows = tuple(
                CommandRow(
                    r.index,
                    r.label,
                    r.state.value,
                    rel(r.sent_at),
                    rel(r.accepted_at),
                    rel(r.done_at),
                    predictions.get(r.index, "-"),
                    r.reason,
                )
                for r in self.run.records
            )
        p = self.predictor
        return ConsoleSnapshot(
            title=self.title,
            clock=self._clock() - self._origin,
            mode=self._mode(),
            confirmed=p.confirmed,
            predicted=None if self.run is None else p.predicted,
            lower=self._model.lower,
            upper=self._model.upper,
            max_opening=self.world.max_opening,
            commands=rows,
            link=dict(self.link()) if self.link is not None else {},
            in_flight=len(p.in_flight),
            comparisons=p.comparisons,
            flagged=p.flagged,
            max_joint_error=p.max_joint_error,
            last_flag=self._last_flag,
            preview=None if self.preview is None else self._preview_text(self.preview),
            status=self.status,
            force=self._force(),
            teleop=tuple(self.teleop()) if self.teleop is not None else (),
        )

    def _mode(self) -> str:
        if self.teleop is not None:
            return "teleoperating"
        return "observer" if self.run is None else "driving"

    def _force(self) -> str | None:
        """Grip force and weighed mass from the completed commands' replies."""
        if self.run is None:
            return None
        grip: float | None = None
        mass: float | None = None
        for r in self.run.records:
            if r.result is None:
                continue
            code = r.command.code
            if code is CommandCode.SQUEEZE:
                grip = r.result.aux[0]
            elif code is CommandCode.WEIGH:
                mass = r.result.aux[0]
            elif code is CommandCode.OPEN_FINGERS and not (
                r.result.feedback.tactile_left and r.result.feedback.tactile_right
            ):
                grip = None  # let go: no force on an object any more
        parts = []
        if grip is not None:
            parts.append(f"gripping with {grip:.0f} N")
        if mass is not None:
            parts.append(f"weighed {mass:.3f} kg")
        return ", ".join(parts) or None
