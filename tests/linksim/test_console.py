"""The operator console renders to strings: plain lines when not a TTY, rich text otherwise."""

from __future__ import annotations

import dataclasses
import io
import json
import math
import pathlib
import re

import pytest
from rich.console import Console

from linksim import DEFAULT_WORLD, TaskRun, rock_task
from linksim.arm import PUMA560, ObjectSpec
from linksim.cli import main
from linksim.control import ConsoleSession, ConsoleSnapshot, preview
from linksim.control._console import CommandRow, render, render_plain, render_text
from tcpstream import CommandResult, Feedback

HOME = Feedback(
    joints=DEFAULT_WORLD.initial_joints,
    finger_opening=0.08,
    p=(0.3988, -0.15005, 0.0652),
    s=(0.0, 1.0, 0.0),
    a=(0.0, 0.0, -1.0),
)
HOLDING = Feedback(
    joints=(0.1, 1.2, -3.3, 0.0, -0.9, 0.1),
    finger_opening=0.07,
    p=(0.57, 0.15, -0.315),
    s=(0.0, 1.0, 0.0),
    a=(0.0, 0.0, -1.0),
    tactile_left=True,
    tactile_right=True,
)


def snapshot() -> ConsoleSnapshot:
    return ConsoleSnapshot(
        title="telelink console: test",
        clock=12.5,
        mode="driving",
        confirmed=HOME,
        predicted=HOLDING,
        lower=PUMA560.lower,
        upper=PUMA560.upper,
        max_opening=0.08,
        commands=(
            CommandRow(1, "open fingers", "completed", 0.0, 2.6, 2.7, "ok"),
            CommandRow(2, "close fingers", "accepted", 0.0, 2.7, None, "ok"),
            CommandRow(3, "weigh", "sent", 0.0, None, None, "ok"),
        ),
        link={"rtt_s": 2.75, "window_occupancy": "2/28", "retransmissions": 3},
        in_flight=2,
        comparisons=4,
        flagged=1,
        max_joint_error=math.radians(1.5),
        last_flag="#1 joint 1.50 deg, hand 3.0 mm off the model",
        preview="all 3 commands pass, 1.10 s of motion",
    )


EXPECTED_PLAIN = """\
telelink console: test  [driving]  t=12.50 s
preview: all 3 commands pass, 1.10 s of motion
joint        confirmed  predicted  limits (deg)
  1  [------------|-----------]    +0.0     +5.7  -160..160
  2  [------------|-----------]   +90.0    +68.8  -45..225
  3  [--|---------------------]  -200.0   -189.1  -225..45
  4  [---------|--------------]    +0.0     +0.0  -110..170
  5  [---|--------------------]   -70.0    -51.6  -100..100
  6  [------------|-----------]    +0.0     +5.7  -266..266
confirmed: P (+0.399, -0.150, +0.065)  S (+0.000, +1.000, +0.000)  A (+0.000, +0.000, -1.000)  \
gripper  80.0 mm  tactile --
predicted: P (+0.570, +0.150, -0.315)  S (+0.000, +1.000, +0.000)  A (+0.000, +0.000, -1.000)  \
gripper  70.0 mm  tactile LR
 #  state      sent  accepted   done  model  command
 1  completed  0.00      2.60   2.70  ok     open fingers
 2  accepted   0.00      2.70      -  ok     close fingers
 3  sent       0.00         -      -  ok     weigh
link: RTT 2.75 s, window 2/28, retransmissions 3
model: 2 in flight, 4 comparisons, 1 flagged, max joint error 1.50 deg; \
last flag: #1 joint 1.50 deg, hand 3.0 mm off the model"""


def test_plain_render_is_a_stable_string() -> None:
    assert render_plain(snapshot()) == EXPECTED_PLAIN


def test_rich_render_to_text_at_120_columns() -> None:
    text = render_text(snapshot(), width=120)
    lines = text.splitlines()
    assert all(len(line) <= 120 for line in lines)
    assert lines[0].startswith("telelink console: test  [driving]  t=12.50 s")
    assert any(line.startswith("1      [------------|-----------]") for line in lines)
    assert any("tactile LR" in line and line.startswith("predicted") for line in lines)
    assert any(line.startswith("2  accepted") and "close fingers" in line for line in lines)
    assert "link: RTT 2.75 s, window 2/28, retransmissions 3" in text
    assert "1 flagged" in text
    assert "\x1b[" not in text


def test_a_joint_outside_its_limits_shows_as_alarm() -> None:
    bad = Feedback(
        joints=(3.0, 1.57, -3.49, 0.0, -1.22, 0.0),
        finger_opening=0.08,
        p=(0.0, 0.0, 0.0),
        s=(0.0, 1.0, 0.0),
        a=(0.0, 0.0, -1.0),
    )
    text = render_plain(
        ConsoleSnapshot("t", 0.0, "observer", bad, None, PUMA560.lower, PUMA560.upper, 0.08)
    )
    assert "  1  !!!!!!!!!!!!!!!!!!!!!!!!!!  +171.9        -  -160..160" in text
    assert "predicted: -" in text


def test_console_command_in_virtual_mode_writes_lines_and_json(
    tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "console.jsonl"
    status = main(
        ["console", "--virtual", "--preset", "clean", "--plain", "--json", "--log", str(log)]
    )
    out, err = capsys.readouterr()
    assert status == 0, err
    summary = json.loads(out)
    assert summary["ok"] is True
    assert summary["preview"]["ok"] is True
    assert summary["model"]["flagged"] == 0
    assert [c["state"] for c in summary["commands"]] == ["completed"] * 11
    # Line output: the initial and final snapshots, an event per command step.
    assert err.count("telelink console: rock task over serial (clean, virtual time)") == 2
    assert "preview: all 11 commands pass, 9.13 s of motion" in err
    assert err.count(" sent: ") == 11
    assert err.count(" completed: ") == 11
    assert log.stat().st_size > 0


def test_require_preview_sends_nothing_when_the_model_refuses(
    tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A rock beyond the arm's reach: the path over it is refused by the model.
    far = ObjectSpec("rock", (1.5, 0.0, -0.315), 0.07, 0.85)
    world = dataclasses.replace(DEFAULT_WORLD, objects=(far,))
    path = tmp_path / "far.toml"
    path.write_text(world.to_toml())
    status = main(
        ["console", "--virtual", "--plain", "--json", "--require-preview", "--world", str(path)]
    )
    out, err = capsys.readouterr()
    assert status == 1
    summary = json.loads(out)
    assert summary["preview"]["first_refusal"]["index"] == 2
    assert summary["preview"]["first_refusal"]["outcome"] == "UNREACHABLE"
    assert all(c["sent_s"] is None for c in summary["commands"])
    assert "nothing was sent" in summary["error"]
    assert "would be refused: UNREACHABLE" in err


def _frame(s: ConsoleSnapshot, width: int, height: int) -> list[str]:
    out = io.StringIO()
    Console(file=out, width=width, color_system=None).print(render(s, height, width))
    return out.getvalue().rstrip("\n").splitlines()


LONG_LINK = {
    "rtt_s": 2.75,
    "window_occupancy": "2/28",
    "pending": 2,
    "retransmissions": 3,
    "check_failures": 1,
    "reconnects": 0,
    "packets_sent": 120,
    "packets_received": 118,
    "bytes_sent": 12000,
    "bytes_received": 30000,
}


def _eleven(done: int) -> ConsoleSnapshot:
    rows = tuple(
        CommandRow(
            i,
            f"move along 2 via points to (+0.380, -0.450, -0.165) #{i}",
            "completed" if i <= done else "queued",
            0.0,
            None,
            None,
            "ok",
        )
        for i in range(1, 12)
    )
    return dataclasses.replace(snapshot(), commands=rows, link=LONG_LINK)


@pytest.mark.parametrize(("width", "height"), [(80, 24), (100, 30), (120, 24), (60, 15)])
def test_the_live_view_fits_the_terminal_and_keeps_the_link_line(width: int, height: int) -> None:
    lines = _frame(_eleven(done=5), width, height)
    assert len(lines) <= height
    assert max(len(line) for line in lines) <= width
    # Never dropped, one row each: the link and model lines, last.
    assert lines[-2].startswith("link: RTT 2.75 s, window 2/28")
    assert lines[-1].startswith("model: 2 in flight")
    queue = [int(m[1]) for line in lines if (m := re.match(r"\s*(\d+)\s+(completed|queued)", line))]
    # Detail goes before command rows: eight of them stay (two finished ones
    # above the first unfinished, #6), or every one that fits a tiny screen.
    assert len(queue) >= min(8, height - 7)
    assert 4 in queue
    assert 6 in queue


def test_80_by_24_drops_the_vectors_keeps_the_joint_bars() -> None:
    text = "\n".join(_frame(_eleven(done=5), 80, 24))
    assert "position against limits" in text  # the bars stay
    assert " S " not in text  # S and A go
    assert "tactile LR" in text  # the gripper stays
    assert "(3 earlier, 0 later commands not shown)" in text


def test_a_tall_wide_terminal_shows_everything() -> None:
    text = "\n".join(_frame(_eleven(done=5), 140, 60))
    assert all(f"#{n}" in text for n in range(1, 12))
    assert "not shown" not in text
    assert "(+0.000, +1.000, +0.000)" in text  # S


def test_the_final_frame_shows_every_command() -> None:
    assert all(f"#{n}" in render_text(_eleven(done=5)) for n in range(1, 12))


def test_preview_only_connects_to_nothing(
    tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["console", "--preview-only", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["ok"] is True
    assert report["duration_s"] == 9.128
    assert [c["outcome"] for c in report["commands"]] == ["ok"] * 11
    far = ObjectSpec("rock", (1.5, 0.0, -0.315), 0.07, 0.85)
    path = tmp_path / "far.toml"
    path.write_text(dataclasses.replace(DEFAULT_WORLD, objects=(far,)).to_toml())
    assert main(["console", "--preview-only", "--world", str(path)]) == 1
    out = capsys.readouterr().out  # the plan is the result: stdout (> plan.txt keeps it)
    assert "#2 " in out
    assert "UNREACHABLE: via point 1" in out
    assert out.count("SKIPPED") == 9
    assert out.rstrip().splitlines()[-1].startswith("REFUSED: 0.00 s of motion")


def test_an_observer_session_shows_reports_and_predicts_nothing() -> None:
    out = io.StringIO()
    clock = iter(float(t) for t in range(100))
    session = ConsoleSession(
        "watch",
        DEFAULT_WORLD,
        run=None,
        clock=lambda: next(clock),
        origin=0.0,
        out=out,
        live=False,
    )
    with session:
        session.telemetry(HOME)
        session.telemetry(HOLDING)
    snap = session.snapshot()
    assert snap.mode == "observer"
    assert snap.confirmed == HOLDING
    assert snap.predicted is None
    assert snap.comparisons == 0
    text = out.getvalue()
    assert "model: none (an observer does not see the commands" in text
    # Line mode: one state line per second of the run's clock.
    assert text.count("] state: joints (") == 2
    assert "tactile LR" in text


def test_force_line_from_squeeze_and_weigh_replies() -> None:
    task = rock_task(DEFAULT_WORLD).commands
    run = TaskRun(task)
    plan = preview(task)
    session = ConsoleSession(
        "t", DEFAULT_WORLD, run=run, clock=lambda: 0.0, origin=0.0, out=io.StringIO(), live=False
    )
    for record, outcome in list(zip(run.records, plan.outcomes, strict=True))[:7]:
        record.result = CommandResult(outcome.feedback, outcome.aux)
    assert session.snapshot().force == "gripping with 20 N, weighed 0.850 kg"
    for record, outcome in list(zip(run.records, plan.outcomes, strict=True))[7:]:
        record.result = CommandResult(outcome.feedback, outcome.aux)
    assert session.snapshot().force == "weighed 0.850 kg"  # let go in the bin
    assert "force: weighed 0.850 kg" in render_plain(session.snapshot())


def _teleop_view_lines() -> list[str]:
    from linksim.teleop._view import ViewState
    from linksim.teleop._view import render as render_view
    from tcpstream.teleop import Buttons, ContactFlags, Reply, ReplyStatus, Sample, TeleopMode

    six = (0.0, 0.0, 20.0, 0.5, -0.5, 0.0)
    sample = Sample(900, TeleopMode.CARTESIAN, Buttons.ENGAGED, 64, 10.0, (0.0,) * 6)
    reply = Reply(880, ReplyStatus.FOLLOWING, ContactFlags.CONTACT, 2, 64, 8.0, 0.01, six, six, six)
    state = ViewState(11.9, sample, reply, 11.0, (0.4, -0.15, 0.06), None, 50.0, 1.3)
    return render_view(state)


def test_the_console_shows_the_teleoperation_view_while_teleoperating() -> None:
    """Issue 22: the console gains a teleoperation view (mode and buttons, force/torque
    bars, predicted vs confirmed hand, setpoint age, the link) -- its teleoperating mode,
    which ``linksim teleop --live`` draws."""
    lines = _teleop_view_lines()
    session = ConsoleSession(
        "teleop", DEFAULT_WORLD, run=None, clock=lambda: 3.0, origin=0.0, out=io.StringIO()
    )
    session.teleop = lambda: lines
    session.link = lambda: {"rtt_s": 2.75, "retransmissions": 1}
    snap = session.snapshot()
    assert snap.mode == "teleoperating"
    assert snap.teleop == tuple(lines)
    plain = render_plain(snap).splitlines()
    # Without command telemetry the joint table would be all dashes: the view replaces it.
    assert plain == [
        "teleop  [teleoperating]  t=3.00 s",
        *lines,
        "link: RTT 2.75 s, retransmissions 1",
        "model: the hand's own increments (predicted) against the arm's replies (confirmed)",
    ]
    assert "Fz    20.00 N" in plain[5]
    # On an 80 x 24 terminal every line of the view stays, one row each.
    out = io.StringIO()
    Console(file=out, width=80, height=24, color_system=None).print(render(snap, 24, 80))
    rows = out.getvalue().splitlines()
    assert len(rows) == len(plain)
    for line, row in zip(lines, rows[1:], strict=False):
        assert row.rstrip()[:60] == line.rstrip()[:60]
