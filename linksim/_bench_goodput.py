"""``linksim bench goodput``: ARQ goodput against the line's theoretical limit, on virtual time.

Every figure this command prints is *virtual-time*: two sans-I/O endpoints
exchange bytes through the seeded impairment engine on an explicit clock
(:mod:`linksim._bench_transfer`), so the same arguments give the same rows on
any machine, loaded or idle.  Only the run time of the command itself depends
on the machine.

Modes:

* default / ``--full``: the designed grid, every sweep in
  :data:`~linksim._bench_grid.SWEEPS` (a few minutes on two cores);
* ``--quick``: the base row and a few neighbours (well under a minute);
* ``--sweep NAME``: chosen sweeps;
* any of ``--rate --delay --ber --burst --window --max-len --payload
  --profile --eight-bit``: the cross product of the values given, the base
  point supplying the rest (``--window`` and the others may repeat).

Output: a text table, or ``--json`` (the rows as one JSON array on stdout),
and/or ``--output FILE.json``, or ``--summary`` (the markdown tables of
bench/results/README.md); ``--plot FILE.png`` draws efficiency against
delay and against error rate, one line per window (needs the ``plot`` extra).
The exit status is 1 if any row's delivered data was not exact.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ._bench_grid import (
    BASE,
    QUICK,
    ROW_KEYS,
    SWEEPS,
    Point,
    auto_packet_length,
    build_grid,
    cpu_count,
    make_payload,
    run_grid,
)
from ._bench_transfer import BENCH_BURST, PROFILES, limit_goodput, simulate
from ._cliargs import BAUD, DELAY, ENDPOINT_LENGTH, JOBS, PROBABILITY, SEED, SIZE, WINDOW

__all__ = ["GoodputResult", "add_arguments", "main", "run_transfer", "theoretical_goodput"]


# -- the single-transfer API (kept for callers of the first version) ------------------


@dataclass(frozen=True, slots=True)
class GoodputResult:
    """One measured transfer (the regression tests' view of a point).

    Attributes:
        window, max_len, rate, delay, byte_error_rate, payload, profile: the point.
        bytes: payload size.
        seconds: virtual time from connection to the last byte delivered.
        goodput: payload bytes per virtual second.
        theoretical: the limit for this line, packet size and data, bytes/s.
        efficiency: goodput / theoretical (the rows' ``ratio_to_limit``).
        retransmissions, timeouts, naks: sender-side counters.
        ok: every byte arrived exactly once, in order.
    """

    window: int
    max_len: int
    rate: float
    delay: float
    byte_error_rate: float
    payload: str
    profile: str
    bytes: int
    seconds: float
    goodput: float
    theoretical: float
    efficiency: float
    retransmissions: int
    timeouts: int
    naks: int
    ok: bool


def theoretical_goodput(
    payload: bytes,
    *,
    rate: float,
    bits_per_char: int = 10,
    max_len: int,
    byte_error_rate: float,
    eight_bit: bool = False,
    burst: bool = False,
) -> float:
    """The theoretical limit in payload bytes/s (see :mod:`linksim._bench_transfer`)."""
    limit, _ = limit_goodput(
        payload,
        rate=rate * 10 / bits_per_char,
        max_len=max_len,
        encoding=PROFILES["8bit" if eight_bit else "printable"],
        byte_error_rate=byte_error_rate,
        burst=BENCH_BURST if burst else None,
    )
    return limit


def run_transfer(
    *,
    window: int,
    rate: float,
    delay: float,
    byte_error_rate: float,
    size: int,
    max_len: int = 128,
    payload_kind: str = "binary",
    eight_bit: bool = False,
    seed: int = 1,
    burst: bool = False,
) -> GoodputResult:
    """Send ``size`` bytes one way over an impaired line and measure the goodput.

    ``burst`` adds the grid's Gilbert-Elliott case on top of ``byte_error_rate``.
    The transfer runs to completion (no time cap short of a protocol failure).
    """
    profile = "8bit" if eight_bit else "printable"
    payload = make_payload(payload_kind, size, seed)
    ge = BENCH_BURST if burst else None
    m = simulate(
        payload,
        rate=rate,
        delay=delay,
        byte_error_rate=byte_error_rate,
        burst=ge,
        window=window,
        max_len=max_len,
        encoding=PROFILES[profile],
        seed=seed,
        # A generous bound so that a protocol bug cannot spin forever.
        time_cap=50 * size / (rate / 10) + 1000 * (2 * delay + 1),
    )
    theory, _ = limit_goodput(
        payload,
        rate=rate,
        max_len=max_len,
        encoding=PROFILES[profile],
        byte_error_rate=byte_error_rate,
        burst=ge,
    )
    goodput = m.delivered / m.seconds if m.seconds > 0 else 0.0
    return GoodputResult(
        window=window,
        max_len=max_len,
        rate=rate,
        delay=delay,
        byte_error_rate=byte_error_rate,
        payload=payload_kind,
        profile=profile,
        bytes=size,
        seconds=round(m.seconds, 3),
        goodput=round(goodput, 3),
        theoretical=round(theory, 3),
        efficiency=round(goodput / theory, 4) if theory else 0.0,
        retransmissions=m.retransmissions,
        timeouts=m.timeouts,
        naks=m.naks,
        ok=m.ok and m.complete,
    )


# -- the CLI ------------------------------------------------------------------------------


def _length(text: str) -> int | str:
    if text == "auto":
        return text
    try:
        return ENDPOINT_LENGTH(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"must be a packet length in {ENDPOINT_LENGTH.describe()} or 'auto', got {text!r}"
        ) from None


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim bench goodput``."""
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--full", action="store_true", help="the whole designed grid (default)")
    mode.add_argument("--quick", action="store_true", help="the base row and a few neighbours")
    mode.add_argument(
        "--sweep",
        action="append",
        choices=sorted(SWEEPS),
        metavar="NAME",
        help=f"run only these sweeps (repeatable): {', '.join(SWEEPS)}",
    )
    mode.add_argument(
        "--from-json", type=Path, metavar="FILE", help="plot or print saved rows; run nothing"
    )
    custom = ap.add_argument_group(
        "custom points (cross product of the values given; the base point supplies the rest)"
    )
    custom.add_argument("--rate", type=BAUD, action="append", help="line rate, bit/s")
    custom.add_argument("--delay", type=DELAY, action="append", help="one-way delay, s")
    custom.add_argument("--ber", type=PROBABILITY, action="append", help="byte error rate")
    custom.add_argument("--burst", action="store_true", help="add Gilbert-Elliott bursts")
    custom.add_argument("--window", type=WINDOW, action="append", help="window, 1..31")
    custom.add_argument(
        "--max-len", type=_length, action="append", help="max packet length, or 'auto'"
    )
    custom.add_argument("--payload", choices=["binary", "text", "commands"], action="append")
    custom.add_argument("--profile", choices=sorted(PROFILES), action="append")
    custom.add_argument("--eight-bit", action="store_true", help="same as --profile 8bit")
    ap.add_argument(
        "--size", type=SIZE, help="payload bytes per point (default: sized for steady state)"
    )
    ap.add_argument("--seed", type=SEED, default=1, help="payload and line seed (default 1)")
    ap.add_argument(
        "--jobs", type=JOBS, default=min(2, cpu_count()), help="worker processes (default 2)"
    )
    ap.add_argument("--json", action="store_true", help="print the rows as a JSON array only")
    ap.add_argument("--output", type=Path, metavar="FILE", help="also write the rows here")
    ap.add_argument(
        "--summary", action="store_true", help="print the summary tables (markdown) instead"
    )
    ap.add_argument(
        "--plot", type=Path, metavar="FILE.png", help="efficiency vs delay and vs error rate"
    )
    ap.add_argument("--plot-delay", type=Path, metavar="FILE.png", help="the delay view alone")
    ap.add_argument("--plot-ber", type=Path, metavar="FILE.png", help="the error-rate view alone")


def _custom_grid(args: argparse.Namespace) -> list[tuple[Point, list[str]]] | None:
    """The cross product of the custom point options, or None if none was given."""
    profiles = list(args.profile or [])
    if args.eight_bit:
        profiles.append("8bit")
    given = (args.rate, args.delay, args.ber, args.window, args.max_len, args.payload)
    if not any(given) and not profiles and not args.burst:
        return None
    points: list[Point] = []
    for rate, delay, ber, window, length, kind, prof in itertools.product(
        args.rate or [BASE.baud],
        args.delay or [BASE.delay],
        args.ber or [BASE.ber],
        args.window or [BASE.window],
        args.max_len or [BASE.max_len],
        args.payload or [BASE.payload],
        profiles or [BASE.profile],
    ):
        p = replace(
            BASE,
            baud=rate,
            delay=delay,
            ber=ber,
            burst=args.burst,
            window=window,
            payload=kind,
            profile=prof,
            size=args.size,
            seed=args.seed,
        )
        if length == "auto":
            n = auto_packet_length(rate, delay, ber, window=window, profile=prof, burst=args.burst)
            p = replace(p, max_len=n, auto_len=True)
        else:
            p = replace(p, max_len=int(length))
        points.append(p)
    return [(p, ["custom"]) for p in dict.fromkeys(points)]


def _print_table(rows: Sequence[dict[str, Any]]) -> None:
    print(
        "virtual time (exact, machine-independent); goodput and limit in payload bytes/s\n"
        f"{'baud':>5} {'delay':>5} {'errors':>7} {'win':>3} {'len':>5} {'payload':>8} "
        f"{'profile':>9} {'bytes':>7} {'seconds':>8} {'goodput':>8} {'eff':>6} "
        f"{'limit':>6} {'ratio':>6} {'rtx':>4} {'tmo':>4}"
    )
    for r in rows:
        errors = "burst" if r["burst"] else f"{r['byte_error_rate']:g}"
        length = f"{r['max_packet_len']}{'a' if r['length_policy'] == 'auto' else ''}"
        window = f"{r['window']}{'*' if r['default_window'] else ''}"
        flag = "" if r["complete"] else f"  {r.get('end', 'incomplete').upper()}"
        flag += "" if r["ok"] else "  DATA MISMATCH"
        print(
            f"{r['baud']:>5} {r['one_way_delay_s']:>5g} {errors:>7} {window:>3} {length:>5} "
            f"{r['payload']:>8} {r['profile']:>9} {r['payload_bytes']:>7} {r['seconds']:>8.1f} "
            f"{r['goodput_Bps']:>8.1f} {r['efficiency']:>6.3f} {r['limit_efficiency']:>6.3f} "
            f"{r['ratio_to_limit']:>6.3f} {r['retransmissions']:>4} {r['timeouts']:>4}{flag}"
        )
    print("* default window; a: automatic packet length; eff = goodput / line bytes/s")


def main(args: argparse.Namespace) -> int:
    """Entry point of ``linksim bench goodput``."""
    if args.from_json is not None:
        rows: list[dict[str, Any]] = json.loads(args.from_json.read_text())
    else:
        grid = _custom_grid(args)
        if grid is None:
            if args.quick:
                sweeps: Sequence[Any] = [("quick", QUICK[1])]
            else:
                sweeps = args.sweep or list(SWEEPS)
            grid = build_grid(sweeps, size=args.size, seed=args.seed)
        rows = run_grid(grid, jobs=args.jobs, progress=not args.json and sys.stderr.isatty())
    missing = [k for k in ROW_KEYS if rows and k not in rows[0]]
    if missing:
        print(f"rows lack required keys: {', '.join(missing)}", file=sys.stderr)
        return 2
    if args.output is not None:
        args.output.write_text(json.dumps(rows, indent=1) + "\n")
    if args.json:
        json.dump(rows, sys.stdout)
        sys.stdout.write("\n")
    elif args.summary:
        from ._bench_summary import summarize

        sys.stdout.write(summarize(rows))
    else:
        _print_table(rows)
    if args.plot or args.plot_delay or args.plot_ber:
        from ._plot import PlotUnavailable, plot_ber, plot_both, plot_delay

        try:
            if args.plot:
                plot_both(rows, args.plot)
            if args.plot_delay:
                plot_delay(rows, args.plot_delay)
            if args.plot_ber:
                plot_ber(rows, args.plot_ber)
        except PlotUnavailable as exc:
            print(f"linksim bench goodput: {exc}", file=sys.stderr)
            return 2
    return 0 if all(r["ok"] for r in rows) else 1
