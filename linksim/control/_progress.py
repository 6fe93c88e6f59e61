"""Live progress of a task run on the terminal (rich), or one line per change when not a TTY.

Progress goes to **stderr**: stdout is kept for the final report, so
``linksim demo --json | jq`` works while the operator still sees the run.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from types import TracebackType
from typing import Any

from rich.console import Console, Group
from rich.live import Live
from rich.table import Table
from rich.text import Text

from ._control import CommandState, TaskRun

__all__ = ["Progress"]

_STYLE = {
    CommandState.QUEUED: "dim",
    CommandState.SENT: "yellow",
    CommandState.ACCEPTED: "cyan",
    CommandState.COMPLETED: "green",
    CommandState.FAILED: "bold red",
}

LinkProbe = Callable[[], Mapping[str, Any]]
"""Returns the link's current figures (``rtt_s``, ``retransmissions``, ...)."""


def _link_line(figures: Mapping[str, Any]) -> str:
    parts = []
    rtt = figures.get("rtt_s")
    if isinstance(rtt, float) and math.isfinite(rtt):
        parts.append(f"RTT {rtt:.2f} s")
    for key, name in (
        ("retransmissions", "retransmissions"),
        ("check_failures", "check failures"),
        ("bytes_sent", "bytes out"),
        ("bytes_received", "bytes in"),
    ):
        if key in figures:
            parts.append(f"{name} {figures[key]}")
    return "link: " + (", ".join(parts) if parts else "connecting")


class Progress:
    """Shows a :class:`TaskRun` while it runs.  Use as a context manager.

    ``live`` chooses the redrawn rich table (a terminal) or plain lines, one
    per command state change; ``enabled=False`` shows nothing at all.
    """

    def __init__(
        self,
        run: TaskRun,
        *,
        title: str,
        link: LinkProbe | None = None,
        clock: Callable[[], float],
        live: bool | None = None,
        enabled: bool = True,
        console: Console | None = None,
    ) -> None:
        self.run = run
        self.title = title
        self.link = link
        self.clock = clock
        self.console = console or Console(stderr=True, highlight=False)
        self.enabled = enabled
        self.live_mode = self.console.is_terminal if live is None else live
        self._live: Live | None = None
        self._seen: dict[int, CommandState] = {}

    def __enter__(self) -> Progress:
        if self.enabled and self.live_mode:
            self._live = Live(
                self._render(), console=self.console, refresh_per_second=8, transient=False
            )
            self._live.__enter__()
        elif self.enabled:
            self._line(self.title)
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._live is not None:
            self._live.update(self._render())
            self._live.__exit__(exc_type, exc, tb)
            self._live = None

    def note(self, message: str) -> None:
        """A one-off status line (connecting, dialing...)."""
        if not self.enabled:
            return
        if self._live is not None:
            self._live.console.print(message, markup=False)
        else:
            self._line(message)

    def changed(self) -> None:
        """Call after any change of the run (the TaskRun's ``on_change``)."""
        if not self.enabled:
            return
        if self._live is not None:
            self._live.update(self._render())
            return
        elapsed = self.clock() - self.run.started_at
        for record in self.run.records:
            if self._seen.get(record.index) is record.state:
                continue
            self._seen[record.index] = record.state
            if record.state is CommandState.QUEUED:
                continue
            extra = f" -- {record.reason}: {record.error}" if record.error else ""
            self._line(
                f"[{elapsed:7.2f} s] #{record.index:<2} {record.state.value:<9} "
                f"{record.label}{extra}"
            )

    def _line(self, text: str) -> None:
        # One event, one line, however long: rich would hard-wrap at the
        # console width (80 when piped), splitting an event across lines and
        # breaking grep.  No markup either: an event's text is data.
        self.console.print(text, soft_wrap=True, markup=False)

    def _render(self) -> Group:
        now = self.clock()
        table = Table(title=self.title, title_justify="left", expand=False)
        table.add_column("#", justify="right")
        table.add_column("command")
        table.add_column("state")
        table.add_column("sent", justify="right")
        table.add_column("accepted", justify="right")
        table.add_column("done", justify="right")
        origin = self.run.started_at

        def at(t: float | None) -> str:
            return "" if t is None else f"{t - origin:6.2f} s"

        for r in self.run.records:
            state = Text(r.state.value, style=_STYLE[r.state])
            if r.error:
                state.append(f" {r.reason}", style="red")
            table.add_row(
                str(r.index), r.label, state, at(r.sent_at), at(r.accepted_at), at(r.done_at)
            )
        done = self.run.count(CommandState.COMPLETED)
        elapsed = (self.run.finished_at or now) - origin if origin else 0.0
        summary = Text(
            f"{done}/{len(self.run.records)} completed, "
            f"{self.run.count(CommandState.FAILED)} failed, {elapsed:.1f} s"
        )
        link = Text(_link_line(self.link() if self.link is not None else {}), style="dim")
        return Group(table, summary, link)
