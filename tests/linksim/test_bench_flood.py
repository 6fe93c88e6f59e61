"""The flood benchmark runs against a real arm-server on loopback and prints valid JSON
(speed is not asserted; the rate limit's bound is tests/test_security.py's job)."""

from __future__ import annotations

import json
import subprocess
import sys


def test_bench_flood_json() -> None:
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "linksim",
            "bench",
            "flood",
            "--json",
            "--seconds",
            "0.5",
            "--limit",
            "100",
        ],
        capture_output=True,
        timeout=120,
        check=True,
    )
    (report,) = json.loads(out.stdout)
    assert report["benchmark"] == "flood"
    assert report["max_packet_rate"] == 100
    assert 0 < report["commands_answered"] <= report["commands_written"]
    assert report["server_cpu_s"] >= 0
    assert report["server_cpu_per_packet_us"] is not None


def test_bench_flood_rejects_nonsense() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "linksim", "bench", "flood", "--limit", "-1"],
        capture_output=True,
        timeout=60,
    )
    assert out.returncode == 2
    assert b"argument --limit: must be a number of packets a second in [0, 1000000]" in out.stderr
