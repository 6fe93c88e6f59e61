"""``linksim bench ...``: the benchmarks' options and output.

The measuring is :mod:`linksim.bench`'s.

Benchmarks measure speed; they are not tests.  Each ``add_NAME_arguments``
registers one subcommand's options; each ``NAME_main`` turns the parsed
options into the library call and prints the result (text, or JSON with
``--json``).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from linksim._plotting import PlotUnavailable
from linksim.bench import (
    GOODPUT_HINTS,
    GOODPUT_PROFILES,
    KERMIT_PAIRS,
    LATENCY_TRANSPORTS,
    PTY_LENGTHS,
    PTY_PORTS,
    SWEEPS,
    TRANSFER_ROWS,
    TransferRow,
    TransferSetup,
    bad_pairing,
    cpu_count,
    custom_grid,
    measure_relay,
    missing_row_keys,
    parse_transfer_row,
    plot_ber,
    plot_both,
    plot_delay,
    plot_delay_range,
    run_bench_kermit,
    run_bench_pty,
    run_codec,
    run_flood,
    run_grid,
    run_kermit_table,
    run_latency,
    run_transfer_table,
    standard_grid,
    summarize,
)
from serialsocket import MAX_WINDOW
from serialsocket.packets import DEFAULT_MAX_PACKET_LENGTH, EIGHT_BIT_CLEAN, PRINTABLE, Encoding

from ._args import (
    BAUD,
    BIT_RATE,
    COUNT,
    DELAY,
    ENDPOINT_LENGTH,
    JOBS,
    KERMIT_LENGTH,
    PROBABILITY,
    SECONDS,
    SEED,
    SIZE,
    WINDOW,
    FloatRange,
    IntRange,
)

_PTY_PROFILES: dict[str, Encoding | None] = {
    "auto": None,
    "8bit": EIGHT_BIT_CLEAN,
    "printable": PRINTABLE,
}
"""``bench pty --profile``, as the netcat's (None: the line's)."""

__all__ = [
    "add_codec_arguments",
    "add_flood_arguments",
    "add_goodput_arguments",
    "add_kermit_arguments",
    "add_latency_arguments",
    "add_pty_arguments",
    "add_relay_arguments",
    "add_transfer_arguments",
    "codec_main",
    "flood_main",
    "goodput_main",
    "kermit_main",
    "latency_main",
    "pty_main",
    "relay_main",
    "transfer_main",
]


def add_codec_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim bench codec``."""
    ap.add_argument("--size", type=SIZE, default=1 << 20, help="payload bytes (default 1 MiB)")
    ap.add_argument("--repeat", type=COUNT, default=5, help="runs per figure; the best is kept")
    ap.add_argument("--max-len", type=KERMIT_LENGTH, default=DEFAULT_MAX_PACKET_LENGTH)
    ap.add_argument("--json", action="store_true", help="print one JSON object and nothing else")


def codec_main(args: argparse.Namespace) -> int:
    """Entry point for the CLI."""
    results = run_codec(args.size, args.repeat, args.max_len)
    if args.json:
        json.dump({"benchmark": "codec", "results": results}, sys.stdout)
        sys.stdout.write("\n")
        return 0
    print(
        f"{'data':8}{'profile':11}{'expand':>7}{'encode':>9}{'decode':>9}"
        f"{'packetize':>11}{'parse':>8}   (MB/s of payload)"
    )
    for r in results:
        print(
            f"{r['data']!s:8}{r['profile']!s:11}{r['expansion']!s:>7}{r['encode_MBps']!s:>9}"
            f"{r['decode_MBps']!s:>9}{r['packetize_MBps']!s:>11}{r['parse_MBps']!s:>8}"
        )
    print(f"packet path at max_len={args.max_len} (MARK..CHECK), CRC-16")
    return 0


def add_flood_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim bench flood``."""
    ap.add_argument(
        "--limit",
        type=FloatRange(0.0, 1e6, unit="packets a second"),
        action="append",
        help="server --max-packet-rate for one run (repeatable; 0: none); default 200 and 0",
    )
    ap.add_argument("--seconds", type=SECONDS, default=8.0, help="flood length per run (default 8)")
    ap.add_argument("--json", action="store_true", help="print a JSON array and nothing else")


def flood_main(args: argparse.Namespace) -> int:
    """Run one flood per limit and print the reports."""
    limits = args.limit or [200.0, 0.0]
    if not args.seconds > 0 or any(not limit >= 0 for limit in limits):
        print("linksim bench flood: --seconds > 0 and --limit >= 0", file=sys.stderr)
        return 2
    reports = [run_flood(limit, args.seconds) for limit in limits]
    if args.json:
        json.dump(reports, sys.stdout)
        sys.stdout.write("\n")
        return 0
    print("one authenticated controller floods STATUS at a linksim arm-server (loopback TCP)")
    for r in reports:
        limit = "none" if r["max_packet_rate"] is None else f"{r['max_packet_rate']:g}/s"
        print(
            f"  limit {limit:>7}: {r['answered_per_s']:9.1f} answers/s, server CPU "
            f"{100 * r['server_cpu_share']:5.1f} % of a core "
            f"({r['server_cpu_per_packet_us']} us a packet)"
        )
    return 0


def _length(text: str) -> int | str:
    if text == "auto":
        return text
    try:
        return ENDPOINT_LENGTH(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"must be a packet length in {ENDPOINT_LENGTH.describe()} or 'auto', got {text!r}"
        ) from None


def add_goodput_arguments(ap: argparse.ArgumentParser) -> None:
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
    custom.add_argument("--profile", choices=sorted(GOODPUT_PROFILES), action="append")
    custom.add_argument("--eight-bit", action="store_true", help="same as --profile 8bit")
    custom.add_argument(
        "--hints",
        choices=GOODPUT_HINTS,
        action="append",
        help="what both ends are told about the line: the truth (exact, the default), "
        "nothing (none), or the delay or the rate 10x too low or too high; with no "
        "--max-len the packet length is what the ends derive from these hints",
    )
    ap.add_argument(
        "--size", type=SIZE, help="payload bytes per point (default: sized for steady state)"
    )
    ap.add_argument("--seed", type=SEED, default=1, help="payload and line seed (default 1)")
    ap.add_argument(
        "--dense",
        action="store_true",
        help="both ends offer the dense encodings (escape code, radix 91), as the netcat "
        "does; the limit is then computed for them (default: the library's classic "
        "Kermit prefixing)",
    )
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
    ap.add_argument(
        "--plot-delay-range",
        type=Path,
        metavar="FILE.png",
        help="ratio to the limit against delay, 0 to 1200 s (rows of --sweep delay-range)",
    )


def _print_goodput_table(rows: Sequence[dict[str, Any]]) -> None:
    print(
        "virtual time (exact, machine-independent); goodput and limit in payload bytes/s\n"
        f"{'baud':>5} {'delay':>5} {'errors':>7} {'win':>3} {'len':>5} {'payload':>8} "
        f"{'profile':>9} {'bytes':>9} {'seconds':>9} {'goodput':>8} {'eff':>6} "
        f"{'limit':>6} {'ratio':>6} {'rtx':>4} {'tmo':>4} {'hints':>16} {'1st byte':>9}"
    )
    for r in rows:
        errors = "burst" if r["burst"] else f"{r['byte_error_rate']:g}"
        policy = r["length_policy"]
        mark = {"auto": "a", "measured": "m"}.get(policy, "")
        length = f"{r['max_packet_len']}{mark}"
        first = r.get("time_to_first_byte_s")
        first_text = "-" if first is None else f"{first:.1f}"
        window = f"{r['window']}{'*' if r['default_window'] else ''}"
        flag = "" if r["complete"] else f"  {r.get('end', 'incomplete').upper()}"
        flag += "" if r["ok"] else "  DATA MISMATCH"
        print(
            f"{r['baud']:>5} {r['one_way_delay_s']:>5g} {errors:>7} {window:>3} {length:>5} "
            f"{r['payload']:>8} {r['profile']:>9} {r['payload_bytes']:>9} {r['seconds']:>9.1f} "
            f"{r['goodput_Bps']:>8.1f} {r['efficiency']:>6.3f} {r['limit_efficiency']:>6.3f} "
            f"{r['ratio_to_limit']:>6.3f} {r['retransmissions']:>4} {r['timeouts']:>4} "
            f"{r.get('hints', 'exact'):>16} {first_text:>9}{flag}"
        )
    print(
        "* default window; a: automatic packet length; m: measured by the ends (from the "
        "length the hints derive; the limit at the best length they may choose); "
        "eff = goodput / line bytes/s; 1st byte: s from connect to the first byte read"
    )


def goodput_main(args: argparse.Namespace) -> int:
    """Entry point of ``linksim bench goodput``."""
    if args.from_json is not None:
        rows: list[dict[str, Any]] = json.loads(args.from_json.read_text())
    else:
        grid = custom_grid(
            rates=args.rate,
            delays=args.delay,
            bers=args.ber,
            burst=args.burst,
            windows=args.window,
            lengths=args.max_len,
            payloads=args.payload,
            profiles=[*(args.profile or []), *(["8bit"] if args.eight_bit else [])],
            hints=args.hints,
            size=args.size,
            seed=args.seed,
        )
        if grid is None:
            grid = standard_grid(
                quick=args.quick, sweeps=args.sweep, size=args.size, seed=args.seed
            )
        if args.dense:
            grid = [(replace(p, dense=True), sweeps) for p, sweeps in grid]
        rows = run_grid(grid, jobs=args.jobs, progress=not args.json and sys.stderr.isatty())
    missing = missing_row_keys(rows)
    if missing:
        print(f"rows lack required keys: {', '.join(missing)}", file=sys.stderr)
        return 2
    if args.output is not None:
        args.output.write_text(json.dumps(rows, indent=1) + "\n")
    if args.json:
        json.dump(rows, sys.stdout)
        sys.stdout.write("\n")
    elif args.summary:
        sys.stdout.write(summarize(rows))
    else:
        _print_goodput_table(rows)
    if args.plot or args.plot_delay or args.plot_ber or args.plot_delay_range:
        try:
            if args.plot_delay_range:
                plot_delay_range(rows, args.plot_delay_range)
            if args.plot:
                plot_both(rows, args.plot)
            if args.plot_delay:
                plot_delay(rows, args.plot_delay)
            if args.plot_ber:
                plot_ber(rows, args.plot_ber)
        except PlotUnavailable as exc:
            print(f"linksim bench goodput: {exc}", file=sys.stderr)
            return 2
        except OSError as exc:
            # The rows were printed (and --output written): only the image failed.
            print(
                f"linksim bench goodput: cannot write the plot: {exc.strerror}: "
                f"{exc.filename} (check that its folder exists and is writable)",
                file=sys.stderr,
            )
            return 2
    return 0 if all(r["ok"] for r in rows) else 1


def add_kermit_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim bench kermit``."""
    ap.add_argument("--size", type=SIZE, default=200_000, help="file bytes (default 200000)")
    ap.add_argument("--runs", type=COUNT, default=3, help="runs per pairing; the median is kept")
    ap.add_argument("--window", type=WINDOW, default=8, help="window slots (default 8)")
    ap.add_argument(
        "--packet-length", type=KERMIT_LENGTH, default=1000, help="packet length (1000)"
    )
    ap.add_argument("--delay", type=DELAY, default=0.1, help="one-way delay, s (default 0.1)")
    ap.add_argument("--ber", type=PROBABILITY, default=1e-4, help="byte error rate (default 1e-4)")
    ap.add_argument("--rate", type=BIT_RATE, help="line rate, bit/s (default: pty speed)")
    ap.add_argument(
        "--timeout", type=IntRange(1, 3600), default=5, help="fixed timeout, s (default 5)"
    )
    ap.add_argument("--limit", type=SECONDS, default=300.0, help="hard limit per transfer, s")
    ap.add_argument("--seed", type=SEED, default=1, help="relay seed of the first run")
    ap.add_argument(
        "--pairs",
        nargs="+",
        default=list(KERMIT_PAIRS),
        help="SENDER->RECEIVER pairings among ours, ckermit, gkermit "
        "(default: ours->ckermit ckermit->ckermit)",
    )
    ap.add_argument(
        "--table",
        action="store_true",
        help="issue 23's table instead: 1.3 s one way, byte errors 1e-3, 2400 and 9600 "
        "bit/s, our defaults both ways against C-Kermit's and hand-tuned C-Kermit, "
        "--runs seeds from --seed (real time: several minutes)",
    )
    ap.add_argument("--json", action="store_true", help="print one JSON object and nothing else")


def kermit_main(args: argparse.Namespace) -> int:
    """Entry point (``linksim bench kermit``); exit 2 when a program is missing."""
    problem = bad_pairing(["ours->ckermit"] if args.table else args.pairs)
    if problem is not None:
        print(f"linksim bench kermit: {problem}", file=sys.stderr)
        return 2
    if args.table:
        return _kermit_table(args)
    base = TransferSetup(
        sender="ours",
        receiver="ckermit",
        window=args.window,
        packet_length=args.packet_length,
        delay=args.delay,
        byte_error_rate=args.ber,
        rate=args.rate,
        timeout=args.timeout,
        limit=args.limit,
        seed=args.seed,
    )
    record = run_bench_kermit(args.pairs, base, size=args.size, runs=args.runs)
    results = record["results"]
    assert isinstance(results, list)
    if args.json:
        print(json.dumps(record))
        return 0
    for r in results:
        print(
            f"{r['pair']:>18}: {r['goodput_Bps']} B/s (median of {r['runs']}: {r['seconds']} s);"
            f" {r['net_goodput_Bps']} B/s above the {r['fixed_seconds']} s of a 1-byte transfer"
        )
    return 0


def _kermit_table(args: argparse.Namespace) -> int:
    """``linksim bench kermit --table``: one row per transfer; exit 1 if one failed."""
    record = run_kermit_table(range(args.seed, args.seed + args.runs))
    rows = record["rows"]
    assert isinstance(rows, list)
    if args.json:
        print(json.dumps(record))
    else:
        print(f"{'bit/s':>5} {'pairing':>16} {'setting':<22} seed  result")
        for r in rows:
            result = (
                f"{r['line_share']:.3f} of the line ({r['seconds']} s)"
                if r["ok"]
                else f"FAILED: {r['error']}"
            )
            print(f"{r['rate']:>5} {r['pair']:>16} {r['setting']:<22} {r['seed']:>4}  {result}")
    return 0 if all(r["ok"] for r in rows) else 1


def add_latency_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim bench latency``."""
    ap.add_argument("--count", type=COUNT, default=2000, help="round trips of each kind")
    ap.add_argument(
        "--warmup", type=IntRange(0, 1_000_000), default=200, help="untimed round trips first"
    )
    ap.add_argument("--key", action="store_true", help="authenticate (HMAC tag on every packet)")
    ap.add_argument(
        "--transport",
        choices=[*LATENCY_TRANSPORTS, "both"],
        default="both",
        help="loopback TCP, a serial socket on a raw pty, or both (default)",
    )
    ap.add_argument(
        "--client",
        choices=["trio", "asyncio"],
        default="trio",
        help="the controller side: the trio client (default) or the asyncio one "
        "(tcpstream.asyncio over TCP, or over serialsocket.asyncio on the pty)",
    )
    ap.add_argument(
        "--server",
        choices=["loop", "process"],
        default=None,
        help="where the trio arm and echo servers run: in the trio client's own loop "
        "(its default), or in a process of their own (the asyncio client's default and "
        "only choice; give it to the trio client too to compare the two like for like)",
    )
    ap.add_argument("--json", action="store_true", help="print one JSON object and nothing else")


def latency_main(args: argparse.Namespace) -> int:
    """Run the benchmark and print the report (text, or JSON with ``--json``)."""
    if args.client == "asyncio" and args.server == "loop":
        print(
            "linksim bench latency: --server loop needs the trio client "
            "(the servers are trio); the asyncio client uses --server process",
            file=sys.stderr,
        )
        return 2
    transports = list(LATENCY_TRANSPORTS) if args.transport == "both" else [args.transport]
    reports = [
        run_latency(
            args.count,
            args.warmup,
            authenticated=args.key,
            transport=t,
            client=args.client,
            server=args.server,
        )
        for t in transports
    ]
    if args.json:
        # One object per transport, as a JSON array.
        json.dump(reports, sys.stdout)
        sys.stdout.write("\n")
        return 0
    for report in reports:
        cmd, raw = report["command"], report["raw_echo"]
        auth = "with HMAC tags" if report["authenticated"] else "no key"
        where = "loopback TCP" if report["transport"] == "tcp" else "a serial socket on a raw pty"
        server = "the client's own loop" if report["server"] == "loop" else "a process of their own"
        print(
            f"command -> completed over {where} ({report['count']} round trips, "
            f"216-byte packets, {auth})"
        )
        print(f"  client: {report['client']}; arm and echo servers (trio) in {server}")
        name = "TCP" if report["transport"] == "tcp" else "pty"
        print(f"  tcpstream STATUS : p50 {cmd['p50_us']:8.1f} us   p99 {cmd['p99_us']:8.1f} us")
        print(f"  raw {name} echo     : p50 {raw['p50_us']:8.1f} us   p99 {raw['p99_us']:8.1f} us")
        if report["transport"] != "tcp":
            # The targets (issue 6) are for loopback TCP; a serial socket adds
            # Kermit encoding, CRCs and the ARQ's own ACKs by design.
            print(f"  p50 ratio {report['p50_ratio']:.2f}x (the targets are for loopback TCP)")
            continue
        ok10 = "yes" if report["target_p50_within_10x"] else "NO"
        ok2ms = "yes" if report["target_p99_under_2ms"] else "NO"
        print(
            f"  p50 ratio {report['p50_ratio']:.2f}x (target <= 10x: {ok10}); p99 < 2 ms: {ok2ms}"
        )
    return 0


def add_pty_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim bench pty``."""
    ap.add_argument("--size", type=SIZE, default=1 << 20, help="bytes per run (default 1 MiB)")
    ap.add_argument("--runs", type=COUNT, default=5, help="runs per length; the median is kept")
    ap.add_argument(
        "--max-len",
        type=ENDPOINT_LENGTH,
        action="append",
        dest="lengths",
        help="packet length (repeatable; default 128 and 4096)",
    )
    ap.add_argument(
        "--window",
        type=WINDOW,
        default=MAX_WINDOW,
        help=f"window in packets (default {MAX_WINDOW}, the library's: long sequence numbers)",
    )
    ap.add_argument(
        "--port",
        choices=PTY_PORTS,
        action="append",
        dest="ports",
        help="pty (default): a raw pty pair; socket: pyserial's socket:// to loopback TCP; "
        "loop: pyserial's loop:// echo, raw port I/O without the ARQ; memory: the two "
        "endpoints with no port, in process CPU time (repeatable)",
    )
    ap.add_argument(
        "--profile",
        choices=tuple(_PTY_PROFILES),
        default="auto",
        help="what the line carries, as the netcat's --profile: auto (default: the port's "
        "format; a pty and socket:// are 8N1, so 8bit), 8bit or printable",
    )
    ap.add_argument(
        "--no-dense",
        dest="dense",
        action="store_false",
        help="offer no dense encoding (classic Kermit prefixing), as the netcat's --no-dense",
    )
    ap.add_argument(
        "--one-process",
        action="store_true",
        help="run both ends in one process (one trio run, so one core) instead of the "
        "receiving end in a process of its own: what the two ends cost together",
    )
    ap.add_argument(
        "--cprofile", metavar="FILE", help="also write a cProfile of one one-process run per length"
    )
    ap.add_argument("--json", action="store_true", help="print one JSON object and nothing else")


def pty_main(args: argparse.Namespace) -> int:
    """Entry point for the CLI (``linksim bench pty``)."""
    if args.size < 1 or args.runs < 1:
        print("linksim bench pty: --size and --runs must be >= 1", file=sys.stderr)
        return 2
    record = run_bench_pty(
        size=args.size,
        runs=args.runs,
        lengths=args.lengths or PTY_LENGTHS,
        window=args.window,
        cprofile=args.cprofile,
        ports=args.ports or ("pty",),
        encoding=_PTY_PROFILES[args.profile],
        dense=args.dense,
        one_process=args.one_process,
    )
    if args.json:
        print(json.dumps(record))
        return 0
    results = record["results"]
    assert isinstance(results, list)
    over = {"pty": "a raw pty", "socket": "pyserial socket:// (loopback TCP)"}
    for r in results:
        if not r["arq"]:
            print(
                f"pyserial loop:// raw port I/O (write, read back; no ARQ): {r['MBps']} MB/s"
                f" (median of {r['runs']} x {r['bytes']} bytes)"
            )
            continue
        if r["port"] == "memory":
            print(
                f"Two endpoints in memory (no port), {r['max_packet_length']}-character packets,"
                f" window {r['window']}: {r['MBps']} MB/s of process CPU time"
                f" (median of {r['runs']} x {r['bytes']} bytes)"
            )
            continue
        ends = "one process" if r["processes"] == 1 else "each end in its own process"
        print(
            f"SerialSocket over {over[r['port']]}, {r['max_packet_length']}-character packets,"
            f" window {r['window']}, {r['encoding']}{'' if r['dense'] else ' (no dense)'},"
            f" {ends}: {r['MBps']} MB/s (median of {r['runs']} x {r['bytes']} bytes)"
        )
    if args.cprofile:
        print(f"profile written to {args.cprofile} (python -m pstats {args.cprofile})")
    return 0


def add_relay_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim bench relay``."""
    ap.add_argument("--size", type=SIZE, default=64 << 20, help="bytes per run (default 64 MiB)")
    ap.add_argument("--repeat", type=COUNT, default=3, help="runs; the best is kept")
    ap.add_argument("--json", action="store_true", help="print one JSON object and nothing else")


def relay_main(args: argparse.Namespace) -> int:
    """Entry point for the CLI."""
    record = measure_relay(args.size, args.repeat)
    if args.json:
        print(json.dumps(record))
    else:
        print(
            f"pty relay, clean link: {record['MBps']} MB/s"
            f" ({args.size} bytes, best of {args.repeat})"
        )
    return 0


def _transfer_row(text: str) -> TransferRow:
    """``--rows`` converter: a row's number in the table or ``RATE/DELAY/BER[/PROFILE]``."""
    try:
        return parse_transfer_row(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


class _TransferRowChoices:
    """``--rows``'s choices: every row :func:`_transfer_row` makes (a line outside
    the issue's table included), listed as the table's numbers.  Given as choices
    so that tests/test_bad_input_cli.py's matrix knows what values to try; the
    converter refuses a bad one first, with its own message."""

    def __contains__(self, value: object) -> bool:
        return isinstance(value, TransferRow)

    def __iter__(self) -> Iterator[str]:
        return iter([str(number) for number in range(1, len(TRANSFER_ROWS) + 1)])


def _transfer_rows_listed() -> str:
    lines = ["the table (issue 21's lines and targets, as share of the line):"]
    for number, row in enumerate(TRANSFER_ROWS, 1):
        lines.append(f"  {number}  {row.spec:<24} target {row.target:.2f}")
    return "\n".join(lines)


def add_transfer_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim bench transfer``."""
    ap.formatter_class = argparse.RawDescriptionHelpFormatter
    ap.epilog = _transfer_rows_listed()
    ap.add_argument(
        "--seeds",
        type=SEED,
        nargs="+",
        default=[1],
        metavar="N",
        help="seeds of the files and of the relays' impairments; every row runs once "
        "per seed (default 1)",
    )
    ap.add_argument(
        "--hints",
        action="store_true",
        help="give both ends --baud and --delay (default: the netcat with no options)",
    )
    ap.add_argument(
        "--rows",
        type=_transfer_row,
        choices=_TransferRowChoices(),
        nargs="+",
        metavar="ROW",
        help="the rows to run: their numbers in the table below, or lines "
        "RATE/DELAY/BER[/PROFILE] (PROFILE auto, 8bit or printable; default auto), "
        "e.g. 2400/1.3/1e-4/auto; a line not in the table has no target (default: all)",
    )
    ap.add_argument(
        "--jobs",
        type=JOBS,
        help="transfers at once (default: all of them, as the issue's figures were "
        "taken); each is three Python processes, and on a small machine transfers "
        "running at once compete for the CPU, which lowers their shares",
    )
    ap.add_argument(
        "--size",
        type=SIZE,
        help="file bytes for every row, for a quick run "
        "(default: 8 KiB at 2400 bit/s or slower, 32 KiB faster)",
    )
    ap.add_argument(
        "--json", action="store_true", help="print one JSON object per transfer, nothing else"
    )


def _print_transfer_json(record: dict[str, Any]) -> None:
    print(json.dumps(record), flush=True)


def _print_transfer_row(r: dict[str, Any]) -> None:
    number = "-" if r["row"] is None else str(r["row"])
    target = "-" if r["target"] is None else f"{r['target']:.2f}"
    agreed = f"{r['encoding']}/{r['max_packet_len']}"
    if r["ok"]:
        below = "" if r["meets_target"] is not False else ", below target"
        measured = f"{r['line_share']:6.3f} {r['seconds']:6.1f}"
        ratio = f"{r['ratio_to_limit']:6.3f}"
        result = f"ok{below}"
    else:
        seconds = "-" if r["seconds"] is None else f"{r['seconds']:.1f}"
        measured, ratio = f"{'-':>6} {seconds:>6}", f"{'-':>6}"
        result = f"FAILED: {r['error']}"
    line, profile = r["spec"].rsplit("/", 1)
    print(
        f"{number:>2} {line:<15} {profile:<9} {r['seed']:>4} {measured} "
        f"{r['limit_share']:6.3f} {ratio} {target:>6} {agreed:<18} {result}",
        flush=True,
    )


def transfer_main(args: argparse.Namespace) -> int:
    """Entry point (``linksim bench transfer``): exit 0 when every transfer
    delivered, byte-exact; 1 otherwise."""
    if args.rows:
        chosen = list(dict.fromkeys(args.rows))
        numbers = {row: n for n, row in enumerate(TRANSFER_ROWS, 1)}
        rows = [(numbers.get(row), row) for row in chosen]
    else:
        rows = list(enumerate(TRANSFER_ROWS, 1))
    seeds = list(dict.fromkeys(args.seeds))
    show: Callable[[dict[str, Any]], None] = _print_transfer_row
    if args.json:
        show = _print_transfer_json
    else:
        hints = "both ends given --baud and --delay" if args.hints else "no options"
        runs = len(rows) * len(seeds)
        print(
            f"the netcat through linksim relay, {hints}; {runs} transfers, "
            f"{min(args.jobs or runs, runs)} at once (wall clock)"
        )
        print(
            f"{'#':>2} {'line':<15} {'profile':<9} {'seed':>4} {'share':>6} {'s':>6} "
            f"{'limit':>6} {'ratio':>6} {'target':>6} {'agreed':<18} result",
            flush=True,
        )
    records = run_transfer_table(
        rows, seeds, hints=args.hints, size=args.size, jobs=args.jobs, on_row=show
    )
    if not args.json:
        print(
            "line: bit/s / one-way delay, s / byte error rate; share: file bytes / seconds "
            "(sender start to both exits) / (bit/s / 10)\nlimit: the share a perfect ARQ "
            "reaches with the agreed encoding and packet length (agreed) at the line's "
            "byte error rate; ratio: share / limit"
        )
    return 0 if all(r["ok"] for r in records) else 1
