"""Setpoint age on a line, every mode, both tasks, several seeds (virtual time).

Each run is ``linksim teleop --virtual --json --preset P --mode M --task T
--seed S [--duration D] [--with-commands]`` (shared compliance); one JSON line
per run goes to stdout, a summary (the range of p50, p99 and max over the
runs) to stderr::

    .venv/bin/python bench/results/teleop-age-matrix.py --duration 120 \\
        > bench/results/teleop-age-noisy-moon.jsonl

Issue 22's target on noisy-moon: p99 at most one way + 0.5 s (1.8 s).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import subprocess
import sys
from typing import Any

MODES = ("joint", "cartesian", "rate", "index")
TASKS = ("surface", "peg")


def run(preset: str, mode: str, task: str, seed: int, duration: float | None, cmds: bool) -> Any:
    argv = [sys.executable, "-m", "linksim", "teleop", "--virtual", "--json"]
    argv += ["--preset", preset, "--mode", mode, "--task", task, "--seed", str(seed)]
    if duration is not None:
        argv += ["--duration", str(duration)]
    if cmds:
        argv.append("--with-commands")
    done = subprocess.run(argv, capture_output=True, text=True, timeout=3600, check=False)
    row = json.loads(done.stdout)
    row.update(seed=seed, exit=done.returncode, with_commands=cmds)
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="noisy-moon")
    ap.add_argument("--seeds", type=int, default=3, help="seeds 1..N (default 3)")
    ap.add_argument("--duration", type=float, default=None, help="seconds per run")
    ap.add_argument("--with-commands", action="store_true", help="the mux: commands beside")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    cases = [(m, t, s) for m in MODES for t in TASKS for s in range(1, args.seeds + 1)]
    rows = []
    with concurrent.futures.ThreadPoolExecutor(args.jobs) as pool:
        futures = [
            pool.submit(run, args.preset, m, t, s, args.duration, args.with_commands)
            for m, t, s in cases
        ]
        for future in futures:
            row = future.result()
            rows.append(row)
            print(json.dumps(row), flush=True)
    ages = [r["setpoint_age_s"] for r in rows]
    failed = [r for r in rows if r["exit"] != 0 or not r["ok"]]
    print(
        f"{len(rows)} runs on {args.preset} ({len(failed)} failed): setpoint age "
        f"p50 {min(a['p50'] for a in ages):.3f}-{max(a['p50'] for a in ages):.3f} s, "
        f"p99 {min(a['p99'] for a in ages):.3f}-{max(a['p99'] for a in ages):.3f} s, "
        f"max {min(a['max'] for a in ages):.3f}-{max(a['max'] for a in ages):.3f} s; "
        f"samples applied {sum(r['samples_applied'] for r in rows)}",
        file=sys.stderr,
    )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
