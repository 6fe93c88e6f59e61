"""The demo's link figures mean one thing each, with units in their names (issue 19:
"goodput_Bps 263.9" on a 240 B/s line summed both directions and telemetry)."""

from __future__ import annotations

import pytest

from linksim import DemoOptions, LinkConfig, run_demo


def test_each_direction_is_reported_separately_and_line_use_is_a_fraction() -> None:
    link = LinkConfig.preset("noisy-moon")
    report = run_demo(DemoOptions(link=link, virtual=True, progress=False)).as_dict()
    figures, seconds = report["link"], report["seconds"]
    assert "goodput_Bps" not in figures
    assert figures["payload_sent_Bps"] == pytest.approx(figures["bytes_sent"] / seconds, abs=0.1)
    assert figures["payload_received_Bps"] == pytest.approx(
        figures["bytes_received"] / seconds, abs=0.1
    )
    capacity = link.b_to_a.rate / link.b_to_a.bits_per_char  # type: ignore[operator]
    assert figures["line_use_received"] == pytest.approx(
        figures["wire_bytes_received"] / (capacity * seconds), abs=1e-3
    )
    for key in ("line_use_sent", "line_use_received"):
        assert 0 < figures[key] <= 1
    # Never more payload than the line could carry one way.
    assert figures["payload_received_Bps"] <= capacity


def test_a_tcp_run_has_no_line_to_be_busy() -> None:
    link = LinkConfig.preset("clean")
    report = run_demo(DemoOptions(link=link, virtual=True, progress=False, transport="tcp"))
    figures = report.as_dict()["link"]
    assert figures["payload_sent_Bps"] > 0
    assert "line_use_sent" not in figures


def test_the_human_report_is_on_stdout_and_progress_on_stderr(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Issue 19: ``linksim demo > run.txt`` kept nothing; results now go to stdout."""
    from linksim.cli import main

    assert main(["demo", "--virtual", "--plain"]) == 0
    out, err = capsys.readouterr()
    assert "OK: 11/11 commands completed" in out
    assert "link: rtt_s" in out
    assert "#1  sent" in err
    assert "#1  sent" not in out
