"""A dead link is reported as a dead link, not as the arm refusing a command (issue 19)."""

from __future__ import annotations

import dataclasses
import sys

import pytest

from linksim import DemoOptions, LinkConfig, Outage, run_demo
from linksim.cli import main


def test_a_link_that_dies_is_reported_as_the_link_failing() -> None:
    link = LinkConfig.preset("noisy-moon")
    forever = (Outage(12.0, 1e6),)
    link = dataclasses.replace(
        link,
        a_to_b=dataclasses.replace(link.a_to_b, outages=forever),
        b_to_a=dataclasses.replace(link.b_to_a, outages=forever),
    )
    report = run_demo(DemoOptions(link=link, virtual=True, progress=False)).as_dict()
    assert report["ok"] is False
    error = report["error"]
    assert error.startswith("the link failed with command #1 (open fingers) unanswered: ")
    assert "refused" not in error
    assert "the link to the arm was lost" in error
    assert "outcome unknown" in error
    assert "Error(" not in error  # no Python repr


@pytest.mark.parametrize("command", ["demo", "console"])
def test_help_names_the_preset_the_command_runs(
    command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """The demo and the console run noisy-moon without --preset; --help said clean."""
    with pytest.raises(SystemExit):
        main([command, "--help"])
    assert "named preset (default: noisy-moon)" in " ".join(capsys.readouterr().out.split())


@pytest.mark.parametrize("stdout_is_a_terminal", [True, False])
def test_a_failed_run_says_why_once_where_the_user_looks(
    stdout_is_a_terminal: bool,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """On a terminal the report shows the error and stderr does not repeat it
    (it was printed twice); with stdout piped, the report goes to the pipe
    and stderr says what happened."""
    monkeypatch.setattr(sys.stdout, "isatty", lambda: stdout_is_a_terminal)
    assert main(["demo", "--virtual", "--outage", "12:1000000"]) == 1
    captured = capsys.readouterr()
    said = (captured.out + captured.err).count("the link failed with command #1")
    assert said == (1 if stdout_is_a_terminal else 2)
    assert "the link failed" in captured.out
    assert ("the link failed" in captured.err) is not stdout_is_a_terminal
