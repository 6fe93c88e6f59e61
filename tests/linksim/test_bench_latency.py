"""The latency benchmark runs on loopback and prints valid JSON (speed is not asserted)."""

from __future__ import annotations

import json
import subprocess
import sys


def test_bench_latency_json() -> None:
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "linksim",
            "bench",
            "latency",
            "--json",
            "--count",
            "40",
            "--warmup",
            "5",
        ],
        capture_output=True,
        timeout=120,
        check=True,
    )
    reports = json.loads(out.stdout)
    assert [r["transport"] for r in reports] == ["tcp", "serial"]
    for report in reports:
        check(report)


def check(report: dict[str, object]) -> None:
    assert report["benchmark"] == "latency"
    assert report["count"] == 40
    assert report["packet_bytes"] == 216
    assert report["authenticated"] is False
    for side in ("command", "raw_echo"):
        figures = report[side]
        assert isinstance(figures, dict)
        assert 0 < figures["min_us"] <= figures["p50_us"] <= figures["p99_us"]
    assert isinstance(report["target_p50_within_10x"], bool)
    assert isinstance(report["target_p99_under_2ms"], bool)
