"""``linksim teleop``: seed 004's streaming teleoperation through the delayed link.

Prints a one-line summary (or, with ``--json``, the report as one JSON
object); exit status 0 when the run met its own verdict (``ok``: samples were
applied, shared compliance held the force limit, an emergency stop stopped the
arm and no sample after it moved it), 1 otherwise.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from typing import Any

from linksim._plotting import PlotUnavailable
from linksim.link import PRESETS, run_virtual
from linksim.teleop import (
    TeleopOptions,
    TeleopReport,
    plot_contact_force,
    run_teleop,
    run_teleop_loopback,
)
from serialsocket.interrupt import run_interruptibly
from tcpstream.teleop import TeleopMode

from ._args import SECONDS, SECONDS_OR_ZERO, SEED, read_key

__all__ = ["add_teleop_arguments", "teleop_main"]


def add_teleop_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim teleop``."""
    ap.add_argument(
        "--mode",
        choices=["joint", "cartesian", "rate", "index"],
        default="cartesian",
        help="seed 004's mode (default cartesian)",
    )
    ap.add_argument(
        "--task",
        choices=["surface", "peg"],
        default="surface",
        help="surface following on a table, or peg in hole (default surface)",
    )
    scheme = ap.add_mutually_exclusive_group()
    scheme.add_argument(
        "--force-reflection",
        dest="scheme",
        action="store_const",
        const="force-reflection",
        help="direct force reflection: contact forces pushed back into the operator's hand",
    )
    scheme.add_argument(
        "--shared-compliance",
        dest="scheme",
        action="store_const",
        const="shared-compliance",
        help="shared control: the arm yields to contact itself (the default)",
    )
    ap.add_argument(
        "--transport",
        choices=["serial", "tcp", "loopback"],
        default="serial",
        help="serial socket on the line, TCP with the line's delay, or real TCP over "
        "loopback with no delay (the latency benchmark; default serial)",
    )
    ap.add_argument(
        "--preset",
        choices=list(PRESETS),
        default="noisy-moon",
        help="the line (default noisy-moon: 2400 bit/s, 1.3 s, errors, bursts)",
    )
    ap.add_argument("--seed", type=SEED, default=1, help="impairment and nonce seed")
    ap.add_argument(
        "--duration",
        type=SECONDS,
        help="seconds of operation (default: the task's script, then one round trip and 1 s; "
        "loopback: 60)",
    )
    ap.add_argument(
        "--stop-at",
        type=SECONDS_OR_ZERO,
        help="press the emergency stop this many seconds into the script",
    )
    ap.add_argument(
        "--stop-via",
        choices=["teleop", "command"],
        default="teleop",
        help="--stop-at sends the sample channel's STOP (default) or the command session's "
        "EMERGENCY_STOP (implies --with-commands)",
    )
    ap.add_argument(
        "--with-commands",
        action="store_true",
        help="run the command session beside the sample channel on the same line (the "
        "stream mux: commands first)",
    )
    ap.add_argument(
        "--no-force-stop",
        action="store_true",
        help="let contact force pass the limit without stopping the arm (to watch it oscillate)",
    )
    ap.add_argument("--key-file", help="pre-shared key file: the channel is authenticated")
    ap.add_argument(
        "--virtual",
        action="store_true",
        help="one process on a virtual clock (instant, reproducible); without it, in real "
        "time, serial runs over two real ptys joined by the impaired relay and tcp over a "
        "real loopback connection seen through the line's delay",
    )
    ap.add_argument("--json", action="store_true", help="print the report as one JSON object")
    ap.add_argument(
        "--keyboard",
        action="store_true",
        help="drive the hand controller from the keyboard instead of the task's script "
        "(w/s a/d r/f move the handle 5 mm, q/e turn, space the index button, p pose change, "
        "g the gripper, x emergency stop, Q quit; keys may be piped in from a file)",
    )
    ap.add_argument(
        "--live",
        action="store_true",
        help="the teleoperation view on stderr: mode and buttons, force/torque bars, predicted "
        "vs confirmed hand, setpoint age, the link (redrawn on a terminal; the final view "
        "otherwise)",
    )
    ap.add_argument(
        "--compare-plot",
        metavar="FILE",
        help="run the task under shared compliance, direct force reflection and direct force "
        "reflection without the limit stop, and plot contact force against time (PNG) to FILE",
    )


def _summary(r: TeleopReport) -> str:
    age = r.setpoint_age_s
    return (
        f"linksim teleop: {r.mode} {r.task} {r.scheme} over {r.transport} ({r.preset}): "
        f"{'ok' if r.ok else 'FAILED'}; samples {r.samples_sampled} sampled, "
        f"{r.samples_sent} sent, {r.samples_applied} applied; setpoint age p50 "
        f"{age['p50']:.3f} s p99 {age['p99']:.3f} s; max contact force "
        f"{r.max_contact_force_n:.1f} N (limit {r.force_limit_n:g} N, "
        f"{r.force_limit_stops} limit stops); emergency stops {r.emergency_stops}"
        + (f"; {r.error}" if r.error else "")
    )


def teleop_main(args: argparse.Namespace) -> int:
    """Run, print, exit 0 when the report says ok."""
    try:
        key = read_key(args.key_file) if args.key_file else None
    except (OSError, ValueError) as exc:
        print(f"linksim teleop: {exc}", file=sys.stderr)
        return 2
    if args.transport == "loopback":
        result: dict[str, Any] = run_interruptibly(
            lambda: run_teleop_loopback(args.duration or 60.0, key=key)
        )
        ok = bool(result["every_sample_applied"])
        if args.json:
            print(json.dumps({"ok": ok, **result}))
        else:
            lat = result["latency_s"]
            print(
                f"linksim teleop: loopback TCP, {result['samples_sampled']} samples at "
                f"{result['sample_rate_hz']:g} Hz, {result['samples_applied']} applied; "
                f"sampling to execution p50 {lat['p50'] * 1e3:.2f} ms, p99 "
                f"{lat['p99'] * 1e3:.2f} ms, max {lat['max'] * 1e3:.2f} ms"
            )
        return 0 if ok else 1
    options = TeleopOptions(
        mode=TeleopMode[args.mode.upper()],
        task=args.task,
        scheme=args.scheme or "shared-compliance",
        transport=args.transport,
        preset=args.preset,
        seed=args.seed,
        key=key,
        stop_at=args.stop_at,
        force_stop=not args.no_force_stop,
        real=not args.virtual,
        live=args.live,
        keyboard=args.keyboard,
        commands=args.with_commands or args.stop_via == "command",
        stop_via=args.stop_via,
        duration=args.duration,
    )
    if args.compare_plot:
        return _compare(options, args.compare_plot, args.json)
    try:
        report = (
            run_virtual(run_teleop, options)
            if args.virtual
            else run_interruptibly(run_teleop, options)
        )
    except OSError as exc:  # the ptys or the line could not be opened
        print(f"linksim teleop: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(report.to_json()))
    else:
        print(_summary(report))
    return 0 if report.ok else 1


def _compare(options: TeleopOptions, path: str, as_json: bool) -> int:
    """The three schemes on one task and line; the plot; exit 0 when shared compliance
    held the limit and direct force reflection did not."""
    runs: list[tuple[TeleopReport, bool]] = []
    for scheme, stop in (
        ("shared-compliance", True),
        ("force-reflection", True),
        ("force-reflection", False),
    ):
        opts = dataclasses.replace(options, scheme=scheme, force_stop=stop)
        report = run_interruptibly(run_teleop, opts) if opts.real else run_virtual(run_teleop, opts)
        runs.append((report, stop))
    title = (
        f"{options.task}, {options.mode.name.lower()} mode, {options.preset} over "
        f"{options.transport} ({runs[0][0].one_way_delay_s:g} s one way)"
    )
    try:
        plot_contact_force(runs, path, title)
    except (PlotUnavailable, OSError) as exc:
        print(f"linksim teleop: {exc}", file=sys.stderr)
        return 1
    summary = [{"force_stop": stop, **r.to_json()} for r, stop in runs]
    if as_json:
        print(json.dumps({"plot": path, "runs": summary}))
    else:
        for r, _ in runs:
            print(_summary(r))
        print(f"linksim teleop: plot written to {path}")
    held = runs[0][0].max_contact_force_n <= runs[0][0].force_limit_n
    exceeded = runs[1][0].max_contact_force_n > runs[1][0].force_limit_n
    return 0 if held and exceeded else 1
