"""The console's command line: the sans-I/O stack fed lines, and the front ends around it."""

from __future__ import annotations

import dataclasses
import io
import json
import math
import os
import pty
import re
import select
import signal
import sys
import time

import pytest

from linksim import DEFAULT_WORLD
from linksim.cli import main
from linksim.control import CommandStack, preview
from linksim.control._command_line import (
    EmergencyStop,
    EntryState,
    Quit,
    Say,
    Submit,
    WaitIdle,
    complete_line,
)
from tcpstream import Command, CommandCode, CommandResult, Feedback

DEG = math.pi / 180
STAMP = re.compile(r"^\[ *\d+\.\d\d\]")
"""The time stamp of an event line: ``[   12.19]``."""
J1_20 = Command(CommandCode.MOVE_JOINT, (1.0, 20 * DEG))


def _texts(outputs: list[object]) -> list[str]:
    return [o.text for o in outputs if isinstance(o, Say)]


def _after(commands: list[Command]) -> Feedback:
    """The state the model predicts after ``commands`` from the default world."""
    return preview(commands, DEFAULT_WORLD).final


# -- the stack, sans I/O ----------------------------------------------------------------


def test_a_command_is_previewed_queued_and_handed_out() -> None:
    stack = CommandStack(origin=100.0)
    out = stack.feed("move_joint 1 20deg", 100.0)
    assert out == [
        Say(
            "#1 move joint 1 by +20.0 deg -- model: completes in 0.66 s, "
            "hand at (+0.426, -0.005, +0.065) m; queued"
        ),
        Submit(1, J1_20),
    ]
    assert stack.entry(1).state is EntryState.QUEUED
    assert not stack.idle


def test_sent_accepted_completed_against_the_prediction() -> None:
    stack = CommandStack(origin=100.0)
    stack.feed("move_joint 1 20deg", 100.0)
    assert _texts(stack.sent(1, 100.5)) == ["[    0.50] #1 SENT"]
    assert _texts(stack.accepted(1, 101.0, 0)) == ["[    1.00] #1 ACCEPTED (queue position 0)"]
    assert stack.accepted(1, 101.0, 0) == []  # once
    result = CommandResult(_after([J1_20]))
    assert _texts(stack.completed(1, 102.0, result)) == [
        "[    2.00] #1 COMPLETED: as predicted (joints 0.00 deg, hand 0.0 mm, fingers 0.0 mm "
        "from the model)"
    ]
    assert stack.completed(1, 102.0, result) == []  # a duplicate reply changes nothing
    assert stack.idle
    assert stack.ok
    assert stack.summary(102.0)["commands"][0] == {
        "index": 1,
        "line": "move_joint 1 20deg",
        "command": "MOVE_JOINT",
        "label": "move joint 1 by +20.0 deg",
        "predicted": "ok",
        "forced": False,
        "state": "completed",
        "sent_s": 0.5,
        "accepted_s": 1.0,
        "done_s": 2.0,
        "as_predicted": True,
    }


def test_an_arm_that_differs_from_the_model_is_flagged_and_followed() -> None:
    stack = CommandStack()
    stack.feed("move_joint 1 20deg", 0.0)
    stack.sent(1, 0.0)
    actual = dataclasses.replace(
        _after([J1_20]), joints=(25 * DEG, *DEFAULT_WORLD.initial_joints[1:])
    )
    text = _texts(stack.completed(1, 1.0, CommandResult(actual)))[0]
    assert text.startswith("[    1.00] #1 COMPLETED: DIVERGES from the model: the arm's state")
    assert "joints 5.00 deg" in text
    assert text.endswith("the model now follows the arm")
    assert stack.summary(1.0)["model"]["flagged"] == 1
    # The next preview starts where the arm said it is: 25 + 140 > 160.
    refused = _texts(stack.feed("move_joint 1 140deg", 1.0))[0]
    assert "JOINT_LIMIT: joint 1 would be at 165.0 deg" in refused


def test_a_command_the_model_refuses_is_not_sent_unless_forced() -> None:
    stack = CommandStack()
    out = stack.feed("move_joint 1 200deg", 0.0)
    assert out == [
        Say(
            "#1 move joint 1 by +200.0 deg -- model: JOINT_LIMIT: joint 1 would be at 200.0 deg, "
            "outside its range -160..160 deg; not sent ('force move_joint 1 200deg' sends it "
            "anyway)"
        )
    ]
    assert stack.entry(1).state is EntryState.REFUSED
    assert stack.rejected == 1
    assert not stack.ok
    forced = stack.feed("force\tmove_joint 1 200deg", 0.0)
    assert isinstance(forced[1], Submit)
    assert _texts(forced)[0].endswith("; queued (forced)")
    stack.sent(2, 0.0)
    text = _texts(stack.failed(2, 1.0, "JOINT_LIMIT", "joint 1 would be at 200.0 deg", _after([])))[
        0
    ]
    assert text == (
        "[    1.00] #2 FAILED: JOINT_LIMIT: joint 1 would be at 200.0 deg -- as predicted "
        "(joints 0.00 deg, hand 0.0 mm, fingers 0.0 mm from the model)"
    )


def test_a_failure_the_model_did_not_predict_diverges() -> None:
    stack = CommandStack()
    stack.feed("move_joint 1 20deg", 0.0)
    stack.sent(1, 0.0)
    text = _texts(stack.failed(1, 1.0, "COLLISION", "link 6 hits the rack", _after([])))[0]
    assert "DIVERGES from the model: model predicted completion, arm reported COLLISION" in text


def test_the_preview_starts_after_the_commands_in_flight() -> None:
    stack = CommandStack()
    assert isinstance(stack.feed("move_joint 6 250deg", 0.0)[-1], Submit)
    stack.sent(1, 0.0)
    # 250 + 20 = 270 > 266: refused although 20 deg alone is fine.
    assert "joint 6 would be at 270.0 deg" in _texts(stack.feed("move_joint 6 20deg", 0.0))[0]
    assert "not run: an earlier command is refused" not in _texts(stack.feed("weigh", 0.0))[0]


def test_the_emergency_stop_bypasses_the_queue_and_the_model_restarts_where_it_stopped() -> None:
    stack = CommandStack()
    stack.feed("path 550,150,-100mm 550,150,-200mm blend=2s", 0.0)
    stack.sent(1, 0.0)
    out = stack.feed("estop", 1.0)
    assert out == [
        Say("[    1.00] EMERGENCY STOP: sent at once; the queued commands fail"),
        EmergencyStop(),
    ]
    assert stack.feed("estop now", 1.0)[-1] == EmergencyStop()  # the language's estop too
    halted = dataclasses.replace(_after([]), joints=(0.3, *DEFAULT_WORLD.initial_joints[1:]))
    assert _texts(stack.stopped(2.0, halted))[0].startswith(
        "[    2.00] EMERGENCY STOP: the arm stopped, hand at"
    )
    assert stack.predictor.base.world.initial_joints[0] == 0.0  # #1 still pending
    assert _texts(stack.failed(1, 2.5, "STOPPED", "halted by stopped"))[0] == (
        "[    2.50] #1 FAILED: STOPPED: halted by stopped -- not run, for reasons of the "
        "session, not of the world"
    )
    assert stack.predictor.base.world.initial_joints[0] == 0.3  # where the stop left it
    assert stack.stops == 2


def test_console_words() -> None:
    stack = CommandStack()
    assert stack.feed("  # a comment", 0.0) == []
    assert stack.feed("", 0.0) == []
    assert stack.feed("wait", 0.0) == [WaitIdle()]
    assert stack.feed("quit", 0.0) == [Quit()]
    assert stack.feed("exit", 0.0) == [Quit()]
    assert stack.feed("queue", 0.0) == [Say("queue: empty (nothing in flight)")]
    stack.feed("weigh  # no object: refused", 0.0)
    stack.feed("move_joint 2 5deg", 0.0)
    assert _texts(stack.feed("queue", 0.0)) == [
        "queue: 1 pending\n  #2   queued    model ok           move joint 2 by +5.0 deg"
    ]
    assert _texts(stack.feed("history", 0.0))[0].splitlines()[-3:] == [
        "   6  move_joint 2 5deg",
        "   7  queue",
        "   8  history",
    ]
    assert _texts(stack.feed("help move_by", 0.0)) == [
        "move_by DP [ROT] [pose_change]\n"
        "  seed 004's incremental move: the hand by dP, turned by rot about the base axes\n"
        "  arguments: dp: 3 numbers in m|cm|mm; rot: 3 numbers in deg|°|rad\n"
        "  example: move_by 0,0,-120mm"
    ]
    assert _texts(stack.feed("help   status", 0.0)) == [
        "status: the console's view: confirmed and predicted state, the commands, the link"
    ]
    overview = _texts(stack.feed("help", 0.0))[0]
    assert "  move_joint      move_joint 1 20deg" in overview
    assert overview.splitlines()[-1].startswith("console: help [COMMAND], status, queue")
    status = _texts(stack.feed("status", 0.0))[0]
    assert status.splitlines()[0] == "telelink console: command line  [driving]  t=0.00 s"
    assert " 2  queued        -         -      -  ok     move joint 2 by +5.0 deg" in status


def test_mistakes_are_messages_not_exceptions() -> None:
    stack = CommandStack()
    assert _texts(stack.feed("move_joint 1 20", 0.0)) == [
        "error: move_joint: by (angle): '20' needs a unit (deg, °, rad), for example 20deg"
    ]
    assert _texts(stack.feed("force", 0.0)) == ["error: force what? (force COMMAND ARGS...)"]
    assert _texts(stack.feed("help nosuch", 0.0))[0].startswith("error: unknown command")
    assert stack.rejected == 2
    assert stack.entries == []


def test_completion() -> None:
    assert complete_line("st") == ["status"]
    assert complete_line("q") == ["query", "queue", "quit"]
    assert complete_line("force mo") == ["move_by", "move_joint", "move_joints", "move_to"]
    assert "status" not in complete_line("force ")
    assert complete_line("help sq") == ["squeeze"]
    assert complete_line("help st") == ["status"]
    assert complete_line("path 1,2,3mm b") == ["blend="]
    assert complete_line("open_fingers 60") == [
        "60%",
        "60N",
        "60cm",
        "60deg",
        "60m",
        "60mm",
        "60ms",
        "60rad",
        "60s",
        "60°",
    ]


# -- through linksim console --interactive, piped (a script) ------------------------------

SCRIPT = """\
help move_joint
move_joint 1 20deg
move_joint 1 200deg          # refused by the model
force move_joint 1 200deg    # sent anyway: fails as predicted
wait
move_jiont 1 2deg
status
quit
"""


def _console(script: str, monkeypatch: pytest.MonkeyPatch, *options: str) -> int:
    monkeypatch.setattr(sys, "stdin", io.StringIO(script))
    return main(["console", "--virtual", "--preset", "moon", "--interactive", *options])


def test_a_piped_session_is_the_same_every_time(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _console(SCRIPT, monkeypatch, "--json") == 1  # a refusal and a failure
    out, err = capsys.readouterr()
    assert _console(SCRIPT, monkeypatch, "--json") == 1
    again, err2 = capsys.readouterr()
    assert (again, err2) == (out, err)
    summary = json.loads(out)
    assert [(c["state"], c["predicted"], c["forced"]) for c in summary["commands"]] == [
        ("completed", "ok", False),
        ("refused", "JOINT_LIMIT", False),
        ("failed", "JOINT_LIMIT", True),
    ]
    assert summary["commands"][2]["as_predicted"] is True
    assert summary["rejected_lines"] == 2
    assert summary["model"]["flagged"] == 0
    lines = err.splitlines()
    assert lines[0] == (
        "telelink console: command line over serial (moon, virtual time); "
        "help lists the commands, Tab completes, quit ends"
    )
    assert "telelink> move_joint 1 20deg" in lines
    # The times are the link's (serialsocket's timers); the words are the stack's.
    events = [STAMP.sub("[t]", line) for line in lines if STAMP.match(line)]
    assert events == [
        "[t] #1 SENT",
        "[t] #3 SENT",
        "[t] #1 ACCEPTED (queue position 0)",
        "[t] #3 ACCEPTED (queue position 1)",
        "[t] #1 COMPLETED: as predicted (joints 0.00 deg, hand 0.0 mm, fingers 0.0 mm from the "
        "model)",
        "[t] #3 FAILED: JOINT_LIMIT: joint 1 would be at 220.0 deg, outside its range -160..160 "
        "deg -- as predicted (joints 0.00 deg, hand 0.0 mm, fingers 0.0 mm from the model)",
    ]
    assert "error: unknown command 'move_jiont'; did you mean move_joint" in err
    assert "Traceback" not in err


def test_a_clean_session_exits_0_and_ends_when_the_lines_do(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    script = "open_fingers 40mm\nmove_by 0,0,-50mm\nmove_by 0,0,50mm\nopen_fingers\n"
    assert _console(script, monkeypatch, "--json") == 0
    out, err = capsys.readouterr()
    summary = json.loads(out)
    assert summary["ok"] is True
    assert [c["state"] for c in summary["commands"]] == ["completed"] * 4
    assert err.count(" COMPLETED: as predicted") == 4


@pytest.mark.parametrize(
    ("options", "words"),
    [
        (["--task", "x.toml"], "not with --task"),
        (["--log", "x.jsonl"], "--log is for a task run; not with --interactive"),
        (["--force"], "--force is for a task run"),
        (["--require-preview"], "--require-preview is for a task run"),
        (["--world", "-"], "reads its command lines on stdin"),
    ],
)
def test_options_that_would_be_ignored_are_refused(
    options: list[str],
    words: str,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert _console("quit\n", monkeypatch, *options) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert words in err


# -- at a terminal: readline, completion, Ctrl-C ------------------------------------------------

LIMIT = 60.0
"""s: a hang guard only; the test waits for output, never for time."""


def _read_until(fd: int, words: str) -> str:
    seen = ""
    deadline = time.monotonic() + LIMIT
    while words not in seen and time.monotonic() < deadline:
        ready, _, _ = select.select([fd], [], [], 1.0)
        if ready:
            try:
                seen += os.read(fd, 4096).decode(errors="replace")
            except OSError:
                break
    return seen


def test_at_a_terminal_tab_completes_and_ctrl_c_exits_130() -> None:
    argv = [sys.executable, "-m", "linksim", "console", "--virtual", "--preset", "clean", "-i"]
    pid, fd = pty.fork()
    if pid == 0:  # pragma: no cover -- the child
        # A test run started in the background inherits SIGINT ignored (a
        # shell does that for background jobs); a user's terminal does not.
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        os.execv(sys.executable, argv)
    try:
        assert "telelink> " in _read_until(fd, "telelink> ")
        os.write(fd, b"move_joint 1 20deg\r")
        assert "#1 COMPLETED: as predicted" in _read_until(fd, "#1 COMPLETED: as predicted")
        os.write(fd, b"stat\t\r")  # Tab completes "status"
        assert "model: 0 in flight" in _read_until(fd, "model: 0 in flight")
        os.write(fd, b"\x03")  # Ctrl-C, as the terminal sends it
        assert "linksim console: interrupted" in _read_until(fd, "interrupted")
    finally:
        _, status = os.waitpid(pid, 0)
        os.close(fd)
    assert os.waitstatus_to_exitcode(status) == 130


def test_a_session_the_arm_ended_is_one_line_not_a_traceback(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _console("terminate\nwait\nmove_joint 1 5deg\n", monkeypatch) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = err.splitlines()
    assert STAMP.sub("[t]", lines[-2]).startswith(
        "[t] #2 FAILED: SessionClosed: the session is closed"
    )
    assert lines[-2].endswith(
        "-- the session's failure, not the arm's: nothing to compare with the model"
    )
    assert lines[-1].startswith("linksim console: the session is closed; nothing was sent")


def test_while_idle_the_model_stands_where_the_telemetry_says() -> None:
    stack = CommandStack()
    elsewhere = dataclasses.replace(
        _after([]), joints=(*DEFAULT_WORLD.initial_joints[:5], 250 * DEG)
    )
    assert stack.telemetry(elsewhere, 0.0) == []
    # From 250 deg, 20 more is past joint 6's 266 deg limit.
    assert "joint 6 would be at 270.0 deg" in _texts(stack.feed("move_joint 6 20deg", 0.0))[0]
    # A pose the model cannot stand in: it says so, and force sends unpreviewed.
    stack.telemetry(dataclasses.replace(elsewhere, joints=(150 * DEG, *elsewhere.joints[1:])), 1.0)
    assert _texts(stack.feed("move_joint 1 -20deg", 1.0)) == [
        "#2 move joint 1 by -20.0 deg -- model: cannot predict (initial_joints: link 3 is inside "
        "obstacle 'rack'); not sent ('force move_joint 1 -20deg' sends it anyway)"
    ]
    forced = stack.feed("force move_joint 1 -20deg", 1.0)
    assert isinstance(forced[-1], Submit)
    assert stack.entry(3).prediction == "-"
