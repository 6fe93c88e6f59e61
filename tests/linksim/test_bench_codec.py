"""The codec benchmark runs on a tiny input and prints valid JSON (speed is not asserted)."""

from __future__ import annotations

import json
import subprocess
import sys


def test_bench_codec_json() -> None:
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "linksim",
            "bench",
            "codec",
            "--json",
            "--size",
            "4096",
            "--repeat",
            "1",
        ],
        capture_output=True,
        timeout=120,
        check=True,
    )
    report = json.loads(out.stdout)
    assert report["benchmark"] == "codec"
    combos = {(r["data"], r["profile"]) for r in report["results"]}
    assert combos == {
        ("binary", "printable"),
        ("binary", "8bit"),
        ("text", "printable"),
        ("text", "8bit"),
    }
    for r in report["results"]:
        assert r["bytes"] == 4096
        assert r["encode_MBps"] > 0
        assert r["parse_MBps"] > 0
