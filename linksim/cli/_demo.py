"""``linksim demo`` and ``linksim control``: argument parsing and exit status.

Exit status: 0 when every command completed; 1 when the run failed (the link
died, the arm refused a command...: the message on stderr says which); 2 for
bad options.
"""

from __future__ import annotations

import argparse
import sys

import serialsocket
from linksim._errors import ConfigError
from linksim.arm import WorldConfig
from linksim.demo import (
    DemoOptions,
    DemoReport,
    print_report,
    run_demo,
    run_time_limit,
)
from linksim.link import endpoint_config_for, endpoint_overrides

from ._args import (
    BAUD,
    DELAY,
    ENDPOINT_LENGTH,
    SECONDS,
    SERIAL_PORT,
    TCP_PORT,
    WINDOW,
    load_world,
)
from ._link import add_link_arguments, config_from_args

__all__ = ["add_control_arguments", "add_demo_arguments", "demo_main"]


def _common(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--transport", choices=["serial", "tcp"], default="serial")
    ap.add_argument("--window", type=WINDOW, help="serial socket window, 1..31")
    ap.add_argument(
        "--max-len", type=ENDPOINT_LENGTH, help="serial packet length limit (default 128)"
    )
    ap.add_argument(
        "--world", help="world configuration (TOML; - for stdin); default: the demo's table"
    )
    ap.add_argument("--json", action="store_true", help="print the final report as JSON only")
    ap.add_argument("--plain", action="store_true", help="status lines, not a live table")
    ap.add_argument("--quiet", action="store_true", help="no progress display")
    ap.add_argument(
        "--timeout",
        type=SECONDS,
        help="give up after this many s (default: 600, or 40 round trips of a longer line)",
    )


def add_demo_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim demo``."""
    add_link_arguments(ap, default_preset="noisy-moon")
    ap.set_defaults(preset=None)
    _common(ap)
    ap.add_argument("--dial", metavar="NUMBER", help="dial through emulated Hayes modems")
    ap.add_argument(
        "--virtual",
        action="store_true",
        help="one process on a virtual clock over the in-memory link: instant, deterministic",
    )


def _world(args: argparse.Namespace) -> WorldConfig:
    return load_world(args.world)


def _finish(report: DemoReport, args: argparse.Namespace, prog: str) -> int:
    print_report(report, as_json=args.json)
    if not report.ok:
        # The human report on a terminal has just shown the error: saying it
        # again on stderr printed it twice (issue 19).  Piped or as JSON, the
        # report is for a program or a file, and stderr says what happened.
        if args.json or not sys.stdout.isatty():
            print(f"{prog}: {report.error or 'the run failed'}", file=sys.stderr)
        return 1
    return 0


def refuse_ignored_options(args: argparse.Namespace) -> None:
    """Every option takes effect or is refused: these combinations would be ignored."""
    if args.transport == "tcp" and args.dial:
        raise ConfigError("--dial needs the serial transport (a modem carries a serial line)")
    if args.virtual and args.dial:
        raise ConfigError(
            "--dial runs emulated modems between real ptys; it cannot run with --virtual"
        )
    if args.transport == "tcp" and (args.window is not None or args.max_len is not None):
        raise ConfigError(
            "--window and --max-len tune the serial socket; the tcp transport has none "
            "(drop them, or use --transport serial)"
        )


def demo_main(args: argparse.Namespace) -> int:
    """``linksim demo``."""
    try:
        preset = args.preset
        if args.config is None and preset is None:
            preset = args.preset = "noisy-moon"
        link = config_from_args(args)
        refuse_ignored_options(args)
        options = DemoOptions(
            link=link,
            preset=preset if args.config is None else str(args.config),
            transport=args.transport,
            virtual=args.virtual,
            dial=args.dial,
            window=args.window,
            max_len=args.max_len,
            world=_world(args),
            progress=not args.quiet,
            live=False if args.plain else None,
            timeout=args.timeout if args.timeout is not None else run_time_limit(link),
        )
        if args.window is not None or args.max_len is not None:
            endpoint_config_for(
                link, **endpoint_overrides(window=args.window, max_len=args.max_len)
            )  # validate early
    except (ConfigError, ValueError, OSError, serialsocket.LocalProtocolError) as exc:
        print(f"linksim demo: {exc}", file=sys.stderr)
        return 2
    try:
        report = run_demo(options)
    except KeyboardInterrupt:
        print("linksim demo: interrupted", file=sys.stderr)
        return 130  # as a shell reports SIGINT
    return _finish(report, args, "linksim demo")


def add_control_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim control``."""
    _common(ap)
    ap.add_argument("--port", type=SERIAL_PORT, help="serial device or pty path (serial transport)")
    ap.add_argument("--baud", type=BAUD, default=9600, help="line rate, bit/s (default 9600)")
    ap.add_argument("--delay", type=DELAY, default=0.0, help="one-way delay hint, s")
    ap.add_argument("--dial", metavar="NUMBER", help="dial NUMBER through a Hayes modem first")
    ap.add_argument("--host", default="127.0.0.1", help="arm server address (tcp)")
    ap.add_argument("--tcp-port", type=TCP_PORT, default=7010, help="arm server port (tcp)")
    ap.add_argument("--key-file", help="file holding the pre-shared key as hex")
