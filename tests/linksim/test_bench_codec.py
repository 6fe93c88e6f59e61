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
    profiles = ["printable", "8bit", "escape", "escape+xon", "radix91"]
    assert combos == {(data, p) for data in ("binary", "text") for p in profiles}
    expansion = {(r["data"], r["profile"]): r["expansion"] for r in report["results"]}
    # Wire characters per byte are exact properties of the encodings (the
    # benchmark's random data is seeded): radix 91 is 16/13 for any data.
    assert (
        expansion[("binary", "radix91")] == expansion[("text", "radix91")] == 1.231
    )  # 5042 / 4096
    assert expansion[("text", "escape")] == 1.0
    assert 1.0 < expansion[("binary", "escape")] < expansion[("binary", "escape+xon")] < 1.04
    for r in report["results"]:
        assert r["bytes"] == 4096
        assert r["encode_MBps"] > 0
        assert r["parse_MBps"] > 0
        assert r["parse_per_field_MBps"] > 0
