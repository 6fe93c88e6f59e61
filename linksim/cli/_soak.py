"""``linksim soak``: options and output of the soak (the run is :func:`linksim.bench.run_soak`).

Prints the report as one JSON object; exit status 1 when the verdict
(:func:`linksim.bench.check_soak`) lists a problem.
"""

from __future__ import annotations

import argparse
import json
import sys

from linksim.bench import check_soak, run_soak

from ._args import SEED, FloatRange

__all__ = ["add_soak_arguments", "soak_main"]


_HOURS = FloatRange(0.0, 24.0 * 365, lo_open=True, unit="hours")
"""Simulated hours: a year of virtual time is the most anyone will wait for."""


def add_soak_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim soak``."""
    ap.add_argument("--hours", type=_HOURS, default=24.0, help="simulated hours (default 24)")
    ap.add_argument("--seed", type=SEED, default=0, help="impairment and traffic seed")
    ap.add_argument(
        "--outage-every", type=_HOURS, default=3.0, help="hours between outages (default 3)"
    )
    ap.add_argument("--no-bulk", action="store_true", help="commands only")
    ap.add_argument("--quiet", action="store_true", help="no progress line per simulated hour")


def soak_main(args: argparse.Namespace) -> int:
    """``linksim soak [--hours H] [--seed N]``: run, print JSON, exit 1 on failure."""
    report = run_soak(
        args.hours,
        args.seed,
        outage_every=args.outage_every,
        bulk=not args.no_bulk,
        progress=not args.quiet,
    )
    problems = check_soak(report)
    summary = report.as_dict()
    summary["halts"] = len(report.halts)
    summary["problems"] = problems
    json.dump(summary, sys.stdout, indent=1)
    sys.stdout.write("\n")
    return 1 if problems else 0
