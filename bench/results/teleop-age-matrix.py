"""Setpoint age on a line, every mode, both tasks, several seeds.

Each run is ``linksim teleop --json --preset P --mode M --task T --seed S
[--virtual] [--duration D] [--with-commands] [--force-reflection]``; one JSON
line per run goes to stdout, a summary (the range of p50, p99 and max over the
runs, the largest contact force per scheme) to stderr::

    .venv/bin/python bench/results/teleop-age-matrix.py --duration 120 \\
        > bench/results/teleop-age-noisy-moon.jsonl
    .venv/bin/python bench/results/teleop-age-matrix.py --seeds 1 --schemes both \\
        > bench/results/teleop-matrix-virtual.jsonl
    .venv/bin/python bench/results/teleop-age-matrix.py --seeds 1 --schemes both \\
        --real-time > bench/results/teleop-matrix-ptys.jsonl

``--real-time`` drops ``--virtual``: two real ptys joined by ``linksim
relay``'s impaired line, one run at a time (about 30 s each), so the figures
are only as good as the machine is quiet.

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


SCHEMES = {
    "shared-compliance": ("shared-compliance",),
    "force-reflection": ("force-reflection",),
    "both": ("shared-compliance", "force-reflection"),
}


def run(args: argparse.Namespace, mode: str, task: str, scheme: str, seed: int) -> Any:
    argv = [sys.executable, "-m", "linksim", "teleop", "--json", f"--{scheme}"]
    argv += ["--preset", args.preset, "--mode", mode, "--task", task, "--seed", str(seed)]
    if not args.real_time:
        argv.append("--virtual")
    if args.duration is not None:
        argv += ["--duration", str(args.duration)]
    if args.with_commands:
        argv.append("--with-commands")
    done = subprocess.run(argv, capture_output=True, text=True, timeout=3600, check=False)
    try:
        row = json.loads(done.stdout)
    except json.JSONDecodeError:
        row = {
            "ok": False,
            "mode": mode,
            "task": task,
            "scheme": scheme,
            "error": done.stderr[-500:],
        }
    row.update(
        seed=seed,
        exit=done.returncode,
        with_commands=args.with_commands,
        clock="real" if args.real_time else "virtual",
    )
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="noisy-moon")
    ap.add_argument("--seeds", type=int, default=3, help="seeds 1..N (default 3)")
    ap.add_argument("--duration", type=float, default=None, help="seconds per run")
    ap.add_argument("--with-commands", action="store_true", help="the mux: commands beside")
    ap.add_argument("--schemes", choices=sorted(SCHEMES), default="shared-compliance")
    ap.add_argument("--real-time", action="store_true", help="real ptys, one run at a time")
    ap.add_argument("--jobs", type=int, default=2, help="parallel virtual runs (default 2)")
    args = ap.parse_args()
    cases = [
        (m, t, c, s)
        for c in SCHEMES[args.schemes]
        for m in MODES
        for t in TASKS
        for s in range(1, args.seeds + 1)
    ]
    rows = []
    jobs = 1 if args.real_time else args.jobs
    with concurrent.futures.ThreadPoolExecutor(jobs) as pool:
        futures = [pool.submit(run, args, m, t, c, s) for m, t, c, s in cases]
        for future in futures:
            row = future.result()
            rows.append(row)
            print(json.dumps(row), flush=True)
    failed = [r for r in rows if r["exit"] != 0 or not r["ok"]]
    ages = [r["setpoint_age_s"] for r in rows if "setpoint_age_s" in r]
    if not ages:
        print(f"{len(rows)} runs, all failed", file=sys.stderr)
        return 1
    print(
        f"{len(rows)} runs on {args.preset} ({len(failed)} failed): setpoint age "
        f"p50 {min(a['p50'] for a in ages):.3f}-{max(a['p50'] for a in ages):.3f} s, "
        f"p99 {min(a['p99'] for a in ages):.3f}-{max(a['p99'] for a in ages):.3f} s, "
        f"max {min(a['max'] for a in ages):.3f}-{max(a['max'] for a in ages):.3f} s; "
        f"samples applied {sum(r.get('samples_applied', 0) for r in rows)}",
        file=sys.stderr,
    )
    for scheme in SCHEMES[args.schemes]:
        forces = [
            r["max_contact_force_n"]
            for r in rows
            if r.get("scheme") == scheme and "max_contact_force_n" in r
        ]
        if forces:
            print(
                f"{scheme}: max contact force {min(forces):.1f}-{max(forces):.1f} N",
                file=sys.stderr,
            )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
