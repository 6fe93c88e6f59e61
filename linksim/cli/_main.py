"""The ``linksim`` command: ``demo``, ``arm-server``, ``control``, ``console``, ``plot``,
``relay``, ``bench``, ``soak`` and ``teleop``."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import signal
import sys
from collections.abc import Sequence
from typing import Any

import trio

from linksim import __version__
from linksim._errors import ConfigError
from linksim.link import CallOutcome, ModemConfig, ModemPair, RelayStatistics, run_relay
from serialsocket.argtypes import parse_args
from serialsocket.capture import CaptureFile
from tcpstream import write_key_file

from . import _armserver, _bench, _console, _demo, _proxy, _soak, _teleop
from ._args import SECONDS, SECONDS_OR_ZERO, SERIAL_PORT, write_template
from ._link import add_link_arguments, config_from_args

__all__ = ["build_parser", "main"]


def _relay_arguments(ap: argparse.ArgumentParser) -> None:
    add_link_arguments(ap)
    ap.add_argument(
        "--device",
        type=SERIAL_PORT,
        action="append",
        dest="devices",
        help="attach to this tty (give two)",
    )
    ap.add_argument("--json", action="store_true", help='print {"a": PATH, "b": PATH} on one line')
    ap.add_argument("--stats", action="store_true", help="print live counters to stderr")
    ap.add_argument("--stats-interval", type=SECONDS, default=1.0, help="seconds between counters")
    ap.add_argument("--duration", type=SECONDS, help="stop after this many seconds")
    ap.add_argument(
        "--capture",
        metavar="FILE",
        help="write both ttys' traffic to FILE.pcapng with timestamps (one interface per "
        "tty; open it with contrib/wireshark/telelink.lua)",
    )
    ap.add_argument(
        "--write-config",
        metavar="FILE",
        help="write the line the options describe as a commented TOML file (- for stdout) "
        "and exit; edit it and pass it back with --config FILE",
    )
    m = ap.add_argument_group("modems")
    m.add_argument("--modem", action="store_true", help="put both ends behind Hayes modems")
    m.add_argument("--busy", action="append", default=[], help="number that answers BUSY")
    m.add_argument("--no-answer", action="append", default=[], help="number that never answers")
    m.add_argument("--dial-time", type=SECONDS_OR_ZERO, default=2.0, help="ATD to first RING, s")
    m.add_argument("--ring-interval", type=SECONDS, default=6.0, help="between RINGs, s")
    m.add_argument(
        "--handshake-time", type=SECONDS_OR_ZERO, default=1.5, help="answer to CONNECT, s"
    )


def _stats_record(stats: RelayStatistics) -> dict[str, Any]:
    return {
        "elapsed": round(stats.elapsed, 3),
        "a_to_b": dataclasses.asdict(stats.a_to_b),
        "b_to_a": dataclasses.asdict(stats.b_to_a),
    }


def _print_stats(stats: RelayStatistics, as_json: bool) -> None:
    if as_json:
        print(json.dumps(_stats_record(stats)), file=sys.stderr, flush=True)
        return
    parts = []
    for name, d in (("a->b", stats.a_to_b), ("b->a", stats.b_to_a)):
        parts.append(
            f"{name} sent {d.bytes_sent} delivered {d.bytes_delivered} dropped {d.bytes_dropped}"
            f" corrupted {d.bytes_corrupted} inserted {d.bytes_inserted}"
            f" in-flight {d.bytes_in_flight}"
        )
    print(f"[{stats.elapsed:9.1f}s] " + " | ".join(parts), file=sys.stderr, flush=True)


def _first_leaf(group: BaseExceptionGroup[BaseException]) -> BaseException:
    """The first real exception in a (nested) nursery exception group."""
    exc: BaseException = group
    while isinstance(exc, BaseExceptionGroup):
        exc = exc.exceptions[0]
    return exc


def relay_main(args: argparse.Namespace) -> int:
    """``linksim relay``: exits 0 on SIGINT, SIGTERM or after --duration."""
    try:
        config = config_from_args(args)
    except ConfigError as exc:
        print(f"linksim relay: {exc}", file=sys.stderr)
        return 2
    if args.write_config:
        return write_template(args.write_config, config.to_toml(), "linksim relay")
    modems = None
    if args.modem:
        book = dict.fromkeys(args.busy, CallOutcome.BUSY)
        book |= dict.fromkeys(args.no_answer, CallOutcome.NO_ANSWER)
        rates = [d.rate for d in (config.a_to_b, config.b_to_a) if d.rate is not None]
        modems = ModemPair(
            ModemConfig(
                dial_time=args.dial_time,
                ring_interval=args.ring_interval,
                handshake_time=args.handshake_time,
                connect_rate=int(min(rates)) if rates else 2400,
                phone_book=book,
            )
        )

    def ready(a: str, b: str) -> None:
        if args.json:
            print(json.dumps({"a": a, "b": b}), flush=True)
        else:
            print(a, b, sep="\n", flush=True)

    def stats(s: RelayStatistics) -> None:
        _print_stats(s, args.json)

    capture: CaptureFile | None = None
    if args.capture:
        try:
            capture = CaptureFile(args.capture)
        except OSError as exc:
            print(f"linksim relay: cannot write {args.capture}: {exc.strerror}", file=sys.stderr)
            return 1

    async def run() -> RelayStatistics:
        stop = trio.Event()
        async with trio.open_nursery() as nursery:

            async def watch_signals() -> None:
                with trio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
                    async for _ in signals:
                        stop.set()
                        return

            nursery.start_soon(watch_signals)
            result = await run_relay(
                config,
                devices=args.devices,
                modems=modems,
                duration=args.duration,
                stop=stop,
                on_ready=ready,
                on_stats=stats if args.stats else None,
                stats_interval=args.stats_interval,
                capture=capture,
            )
            nursery.cancel_scope.cancel()
        return result

    try:
        try:
            final = trio.run(run)
        except BaseExceptionGroup as group:
            raise _first_leaf(group) from None
    except (OSError, ValueError) as exc:
        # A --device that cannot be opened arrives from inside the relay's nursery.
        print(f"linksim relay: {exc}", file=sys.stderr)
        return 1
    finally:
        if capture is not None:
            capture.close()
    if args.stats:
        _print_stats(final, args.json)
    return 0


def keygen_main(args: argparse.Namespace) -> int:
    """``linksim keygen FILE``: 0 when written, 1 when the file exists or cannot be made."""
    try:
        write_key_file(args.file)
    except FileExistsError:
        print(
            f"linksim keygen: {args.file} exists; not overwriting a key (remove it first "
            "if you mean to replace it)",
            file=sys.stderr,
        )
        return 1
    except OSError as exc:
        print(f"linksim keygen: cannot write {args.file}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    print(
        f"wrote a new pre-shared key to {args.file} (mode 0600): pass --key-file {args.file} "
        "to both the arm server and the controller",
        file=sys.stderr,
    )
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser; subcommands register here."""
    ap = argparse.ArgumentParser(prog="linksim", description="Impaired links and benchmarks.")
    ap.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    relay = sub.add_parser("relay", help="impaired relay between two ptys (or given ttys)")
    _relay_arguments(relay)
    relay.set_defaults(func=relay_main)
    bench = sub.add_parser("bench", help="benchmarks (measure speed; not tests)")
    bench_sub = bench.add_subparsers(dest="bench", required=True)
    codec = bench_sub.add_parser("codec", help="Kermit encode/decode speed")
    _bench.add_codec_arguments(codec)
    codec.set_defaults(func=_bench.codec_main)
    goodput = bench_sub.add_parser("goodput", help="ARQ goodput against the theoretical limit")
    _bench.add_goodput_arguments(goodput)
    goodput.set_defaults(func=_bench.goodput_main)
    brelay = bench_sub.add_parser("relay", help="pty relay throughput on a clean link")
    _bench.add_relay_arguments(brelay)
    brelay.set_defaults(func=_bench.relay_main)
    bpty = bench_sub.add_parser(
        "pty", help="serial socket goodput over a raw pty pair (wall clock)"
    )
    _bench.add_pty_arguments(bpty)
    bpty.set_defaults(func=_bench.pty_main)
    bkermit = bench_sub.add_parser(
        "kermit", help="Kermit file transfer: ours vs C-Kermit through the relay (wall clock)"
    )
    _bench.add_kermit_arguments(bkermit)
    bkermit.set_defaults(func=_bench.kermit_main)
    btransfer = bench_sub.add_parser(
        "transfer",
        help="issue 21's table: the netcat through the relay, beside the limit (wall clock)",
        description="Issue 21's real-time table: serialsocket listen/connect move a file of\n"
        "random binary through linksim relay (wall time from starting the sender to\n"
        "both exits, as a share of the line), beside the theoretical limit for the\n"
        "encoding and packet length the two ends agree on.  Exit 0: every transfer\n"
        "delivered, byte-exact.",
    )
    _bench.add_transfer_arguments(btransfer)
    btransfer.set_defaults(func=_bench.transfer_main)
    latency = bench_sub.add_parser(
        "latency", help="command round trip over loopback TCP beside a raw echo (wall clock)"
    )
    _bench.add_latency_arguments(latency)
    latency.set_defaults(func=_bench.latency_main)
    flood = bench_sub.add_parser(
        "flood", help="server CPU under a flooding controller, with and without the rate limit"
    )
    _bench.add_flood_arguments(flood)
    flood.set_defaults(func=_bench.flood_main)
    demo = sub.add_parser(
        "demo", help="a controller commands the simulated arm through the whole stack"
    )
    _demo.add_demo_arguments(demo)
    demo.set_defaults(func=_demo.demo_main)
    server = sub.add_parser("arm-server", help="the simulated arm behind a command server")
    _armserver.add_arguments(server)
    server.set_defaults(func=_armserver.arm_server_main)
    control = sub.add_parser(
        "control", help="run the rock task or a task file against a linksim arm-server"
    )
    _console.add_control_arguments(control)
    control.set_defaults(func=_console.control_main)
    console = sub.add_parser(
        "console",
        help="operator console: preview, predicted vs confirmed state, queue, link, log",
    )
    _console.add_console_arguments(console)
    console.set_defaults(func=_console.console_main)
    plot = sub.add_parser("plot", help="joint trajectories of a console --log file (PNG)")
    _console.add_plot_arguments(plot)
    plot.set_defaults(func=_console.plot_main)
    proxy = sub.add_parser(
        "proxy",
        help="a real TCP proxy with the line's rate, delay, stalls, outages and cuts",
        description="Carry TCP connections through an impaired line in real time: rate, "
        "delay and jitter as configured; loss, errors and bursts as TCP would see them "
        "(a stall of one retransmission timeout); outages; resets at byte offsets.",
    )
    _proxy.add_proxy_arguments(proxy)
    proxy.set_defaults(func=_proxy.proxy_main)
    keygen = sub.add_parser(
        "keygen",
        help="write a new pre-shared key file (mode 0600) for --key-file",
        description="Write a new random pre-shared key (32 bytes, hex) to FILE, readable by "
        "its owner only; give the same file to the arm server and the controller "
        "(--key-file FILE).  Never overwrites.",
    )
    keygen.add_argument("file", metavar="FILE", help="the key file to create")
    keygen.set_defaults(func=keygen_main)
    soak_help = "hours of commands and bulk data over noisy-moon with outages (virtual time)"
    soak = sub.add_parser("soak", help=soak_help, description=f"The soak: {soak_help}.")
    _soak.add_soak_arguments(soak)
    soak.set_defaults(func=_soak.soak_main)
    teleop = sub.add_parser(
        "teleop",
        help="seed 004's streaming teleoperation: hand controller, line, arm, contact force",
        description="A scripted operator streams FRHC samples through the teleoperation "
        "channel to the simulated arm in joint, cartesian, rate or index mode, on a table "
        "(surface) or at a hole (peg), with direct force reflection or shared compliance.",
    )
    _teleop.add_teleop_arguments(teleop)
    teleop.set_defaults(func=_teleop.teleop_main)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    """Run the linksim command line; returns the exit status.

    Ctrl-C ends any command with one line and status 130 (the sessions it
    interrupts still say BYE on the way out); a closed pipe on stdout ends
    it quietly with 141.
    """
    args = parse_args(build_parser(), argv)
    try:
        status: int = args.func(args)
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return 141
    except BaseException as exc:
        if not _interrupted(exc):
            raise
        print(f"linksim {args.command}: interrupted", file=sys.stderr)
        return 130
    return status


def _interrupted(exc: BaseException) -> bool:
    """A Ctrl-C, alone or anywhere inside trio's exception groups.

    The other members of such a group are its consequences (cancellations;
    a child process in the same process group got the SIGINT too and its
    connection broke), so the run ends as interrupted, not with them."""
    if isinstance(exc, KeyboardInterrupt):
        return True
    if isinstance(exc, BaseExceptionGroup):
        return any(_interrupted(e) for e in exc.exceptions)
    return False
