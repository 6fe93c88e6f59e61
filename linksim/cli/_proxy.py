"""``linksim proxy``: argument parsing and exit status for the TCP impairment proxy.

Exit status: 0 when stopped (Ctrl-C, SIGTERM, ``--duration``); 1 when it
cannot listen; 2 for bad options.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys

import trio

from linksim._errors import ConfigError
from linksim.link import Cut, ProxyStatistics, run_proxy

from ._args import SECONDS
from ._link import add_link_arguments, config_from_args

__all__ = ["add_proxy_arguments", "proxy_main"]


def _address(text: str, *, default_host: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep:
        host, port = default_host, text
    try:
        number = int(port)
    except ValueError:
        raise argparse.ArgumentTypeError(f"want [HOST:]PORT, got {text!r}") from None
    if not 0 <= number <= 65535:
        raise argparse.ArgumentTypeError(f"port must be in 0..65535, got {number}")
    return host.strip("[]") or default_host, number


def _listen(text: str) -> tuple[str, int]:
    return _address(text, default_host="127.0.0.1")


def _target(text: str) -> tuple[str, int]:
    host, port = _address(text, default_host="127.0.0.1")
    if port == 0:
        raise argparse.ArgumentTypeError("--to needs the server's port, not 0")
    return host, port


def _cut(text: str) -> Cut:
    try:
        return Cut.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_proxy_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim proxy``."""
    ap.add_argument(
        "--listen",
        type=_listen,
        required=True,
        metavar="[HOST:]PORT",
        help="where clients connect (port 0: any free port; host default 127.0.0.1)",
    )
    ap.add_argument(
        "--to", type=_target, required=True, metavar="HOST:PORT", help="the server to reach"
    )
    ap.add_argument(
        "--cut",
        type=_cut,
        action="append",
        default=[],
        metavar="up|down:BYTES",
        help="reset the Nth connection after BYTES in that direction (up: client to "
        "server); repeat for the next connections",
    )
    ap.add_argument("--json", action="store_true", help='print {"host": H, "port": P} on one line')
    ap.add_argument("--stats", action="store_true", help="print the counters at the end (stderr)")
    ap.add_argument("--duration", type=SECONDS, help="stop after this many seconds")
    add_link_arguments(ap)


def proxy_main(args: argparse.Namespace) -> int:
    """``linksim proxy``: exits 0 on SIGINT, SIGTERM or after --duration."""
    try:
        config = config_from_args(args)
    except ConfigError as exc:
        print(f"linksim proxy: {exc}", file=sys.stderr)
        return 2

    def ready(host: str, port: int) -> None:
        if args.json:
            print(json.dumps({"host": host, "port": port}), flush=True)
        else:
            print(f"listening on {host}:{port}, to {args.to[0]}:{args.to[1]}", flush=True)

    async def run() -> ProxyStatistics:
        stop = trio.Event()
        async with trio.open_nursery() as nursery:

            async def watch_signals() -> None:
                with trio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
                    async for _ in signals:
                        stop.set()
                        return

            nursery.start_soon(watch_signals)
            stats = await run_proxy(
                config,
                listen=args.listen,
                target=args.to,
                cuts=args.cut,
                on_ready=ready,
                duration=args.duration,
                stop=stop,
            )
            nursery.cancel_scope.cancel()
        return stats

    try:
        stats = trio.run(run)
    except OSError as exc:
        print(
            f"linksim proxy: cannot listen on {args.listen[0]}:{args.listen[1]}: {exc}",
            file=sys.stderr,
        )
        return 1
    for error in stats.errors:
        print(f"linksim proxy: {error}", file=sys.stderr)
    if args.stats:
        print(json.dumps(stats.as_dict()), file=sys.stderr)
    return 0
