"""The control station: task runs, the operator console, prediction, preview, telemetry.

* :class:`TaskRun`: a task script run pipelined through an arm client, with a
  record of every command (:class:`CommandRecord`, :class:`CommandState`);
  :class:`Progress` shows it on stderr.
* :func:`preview` plays commands on a local copy of the arm
  (:class:`PreviewReport`); :class:`Predictor` keeps the predicted state
  ahead of the confirmed one and records :class:`Divergence`;
  :class:`ConsoleSession` / :class:`ConsoleSnapshot` draw it
  (:func:`render_plain`: a snapshot as plain text lines).
* Your own commands: :func:`parse_command` reads the operator's command
  language (``move_joint 1 20deg``; :class:`CommandSyntaxError`),
  :func:`resolve_task` / :func:`load_task` a task file (:class:`TaskFile`,
  :class:`TaskFileError`).  The console's command line: :class:`CommandStack`
  (sans-I/O: lines in, previews, sends and outcomes out) and
  :func:`run_command_line` with :func:`script_lines` or :class:`TerminalLines`.
* :class:`TelemetryLog` / :func:`read_log` write and read the JSON-lines log
  (:func:`parse_log` reads it from lines, stdin for one);
  :func:`plot_log` plots it (``linksim plot``).
"""

from __future__ import annotations

from ._command_line import CommandStack
from ._console import ConsoleSession, ConsoleSnapshot, render_plain
from ._control import CommandRecord, CommandState, TaskRun, feedback_record
from ._interactive import LineSource, TerminalLines, run_command_line, script_lines
from ._plot import plot_log
from ._predict import Divergence, Predictor
from ._preview import ModelState, PredictedOutcome, PreviewReport, preview
from ._progress import Progress
from ._taskfile import TaskFile, TaskFileError, load_task, resolve_task
from ._telemetry_log import TelemetryLog, parse_log, read_log
from ._vocabulary import CommandSyntaxError, format_command, parse_command

__all__ = [
    "CommandRecord",
    "CommandStack",
    "CommandState",
    "CommandSyntaxError",
    "ConsoleSession",
    "ConsoleSnapshot",
    "Divergence",
    "LineSource",
    "ModelState",
    "PredictedOutcome",
    "Predictor",
    "PreviewReport",
    "Progress",
    "TaskFile",
    "TaskFileError",
    "TaskRun",
    "TelemetryLog",
    "TerminalLines",
    "feedback_record",
    "format_command",
    "load_task",
    "parse_command",
    "parse_log",
    "plot_log",
    "preview",
    "read_log",
    "render_plain",
    "resolve_task",
    "run_command_line",
    "script_lines",
]
