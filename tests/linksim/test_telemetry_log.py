"""The telemetry log round-trips and plots; malformed logs are refused with the line."""

from __future__ import annotations

import json
import pathlib

import pytest

from linksim import DEFAULT_WORLD
from linksim._plotting import PlotUnavailable
from linksim.cli import main
from linksim.control import TelemetryLog, plot_log, read_log
from tcpstream import Feedback

STATE = Feedback(
    joints=(0.1, 0.2, 0.3, 0.4, 0.5, 0.6),
    finger_opening=0.07,
    p=(0.5, 0.1, -0.3),
    s=(0.0, 1.0, 0.0),
    a=(0.0, 0.0, -1.0),
    tactile_left=True,
    tactile_right=True,
)


def write_example(path: pathlib.Path) -> None:
    with TelemetryLog(path, origin=100.0, title="test", world=DEFAULT_WORLD.to_toml()) as log:
        log.command(100.5, 1, "CLOSE_FINGERS", "close fingers", "sent")
        log.state(101.0, "telemetry", STATE)
        log.state(101.25, "completion", STATE)
        log.command(101.25, 1, "CLOSE_FINGERS", "close fingers", "completed")
        log.state(101.25, "predicted", STATE)
        log.command(102.0, 2, "WEIGH", "weigh", "failed", "NOT_GRASPING")
        log.record(102.0, "divergence", {"index": 2, "flagged": True})
        assert log.lines == 8


def test_log_round_trips(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "log.jsonl"
    write_example(path)
    contents = read_log(path)
    assert contents.header["schema"] == 1
    assert contents.header["title"] == "test"
    assert contents.header["world"] == DEFAULT_WORLD.to_toml()
    assert [s["t"] for s in contents.states] == [1.0, 1.25, 1.25]
    assert [s["source"] for s in contents.reported()] == ["telemetry", "completion"]
    first = contents.states[0]
    assert first["joints_rad"] == [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]
    assert first["finger_opening_m"] == 0.07
    assert first["tactile"] == [True, True]
    assert [(c["index"], c["event"]) for c in contents.commands] == [
        (1, "sent"),
        (1, "completed"),
        (2, "failed"),
    ]
    assert contents.commands[2]["reason"] == "NOT_GRASPING"
    assert contents.other == [{"type": "divergence", "t": 2.0, "index": 2, "flagged": True}]


def test_malformed_logs_are_refused_with_the_line(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "bad.jsonl"
    path.write_text('{"type": "state", "t": 0}\n')
    with pytest.raises(ValueError, match=r"bad.jsonl:1: the first record must be the header"):
        read_log(path)
    path.write_text('{"type": "header", "t": 0, "schema": 99}\n')
    with pytest.raises(ValueError, match=r"schema 99, this reader knows 1"):
        read_log(path)
    path.write_text('{"type": "header", "t": 0, "schema": 1}\n{"type": "state"\n')
    with pytest.raises(ValueError, match=r"bad.jsonl:2: not JSON"):
        read_log(path)
    path.write_text("")
    with pytest.raises(ValueError, match="empty log"):
        read_log(path)


def test_a_console_log_plots(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("matplotlib")
    log = tmp_path / "run.jsonl"
    assert main(["console", "--virtual", "--preset", "clean", "--plain", "--log", str(log)]) == 0
    contents = read_log(log)
    # Telemetry every tenth control sample (seed 004), a completion per command.
    assert len(contents.reported()) > 100
    assert sum(c["event"] == "completed" for c in contents.commands) == 11
    # What the plot draws as the model's end pose: one per completed command,
    # at its completion, on the reported pose there (the clean run diverges
    # nowhere), not the end of the whole queue drawn as a step.
    predictions = [r for r in contents.other if "predicted_joints_deg" in r]
    completions = {s["t"]: s for s in contents.states if s["source"] == "completion"}
    assert len(predictions) == 11
    for r in predictions:
        reported = completions[r["t"]]["joints_deg"]
        assert (
            max(abs(a - b) for a, b in zip(r["predicted_joints_deg"], reported, strict=True)) < 0.5
        )
    capsys.readouterr()
    png = tmp_path / "run.png"
    assert main(["plot", str(log), "--out", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The result -- where the plot went -- is stdout's, nothing else is (issue 19).
    assert capsys.readouterr().out.strip() == str(png)


def test_plotting_an_empty_log_says_why(
    tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("matplotlib")
    path = tmp_path / "empty.jsonl"
    TelemetryLog(path, origin=0.0).close()
    assert main(["plot", str(path), "--out", str(tmp_path / "x.png")]) == 1
    assert "no reported arm state" in capsys.readouterr().err
    with pytest.raises(PlotUnavailable, match="no reported arm state"):
        plot_log(path, tmp_path / "x.png")
    assert json.loads(path.read_text())["type"] == "header"


def test_a_record_carries_the_log_s_time_not_its_own(tmp_path: pathlib.Path) -> None:
    """A divergence holds the clock reading it was taken at; in the log (and on
    the plot) it must sit at the log's time from its origin.  On a real clock
    the two differ by hours, and the model's end poses fell off the plot."""
    path = tmp_path / "run.jsonl"
    with TelemetryLog(path, origin=123_000.0) as log:
        log.record(123_005.5, "divergence", {"t": 123_005.5, "predicted_joints_deg": [0.0] * 6})
    (divergence,) = read_log(path).other
    assert divergence["t"] == 5.5
    assert divergence["type"] == "divergence"
