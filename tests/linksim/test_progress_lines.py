"""Plain progress lines are never wrapped (issue 19: piped output was hard-wrapped
at 80 columns by rich, splitting event lines mid-sentence)."""

from __future__ import annotations

import io

from rich.console import Console

from linksim import TaskRun
from linksim.control import CommandState, Progress
from tcpstream import commands


def test_a_long_event_stays_on_one_line_when_piped() -> None:
    out = io.StringIO()
    console = Console(file=out, width=80, force_terminal=False, highlight=False)
    run = TaskRun([commands.move_path([(0.38, -0.45, -0.165), (0.4, 0.1, 0.2)])])
    with Progress(run, title="t " * 60, clock=lambda: 0.0, live=False, console=console) as view:
        record = run.records[0]
        record.error = "request 1 was sent, but [the link] was lost " * 4
        record.reason = "OutcomeUnknown"
        record.state = CommandState.FAILED
        view.changed()
        view.note("[dial] " + "x" * 150)
    lines = out.getvalue().splitlines()
    assert len(lines) == 3, lines
    assert lines[0].rstrip() == ("t " * 60).rstrip()
    assert lines[1].startswith("[   0.00 s] #1  failed    move along 2 via points")
    assert lines[1].rstrip().endswith("[the link] was lost")
    assert lines[2] == "[dial] " + "x" * 150
