"""``serialsocket kermit send FILE... --port PORT`` and ``kermit receive [DIR] --port PORT``.

Kermit file transfer with C-Kermit, G-Kermit or another copy of this program
on the far end of a serial line or pty.  Exit status: 0 transferred, 1 the
transfer failed (the message says whether the peer or we gave up), 2 bad
arguments or a port/file that cannot be opened.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from dataclasses import asdict

from ._checks import BlockCheck
from ._errors import LocalProtocolError
from ._port import open_port
from .argtypes import (
    BAUD,
    DELAY,
    KERMIT_LENGTH,
    KERMIT_TIMEOUT,
    KERMIT_WINDOW,
    RETRIES,
    SERIAL_PORT,
    IntRange,
)
from .interrupt import run_interruptibly
from .kermit import (
    REMOTE_COMMANDS,
    KermitConfig,
    KermitStatistics,
    KermitTransferError,
    kermit_get,
    kermit_receive,
    kermit_remote,
    kermit_send,
    kermit_server,
)

__all__ = ["add_arguments", "kermit_main"]

FILE_OFFSET = IntRange(0, 2**63 - 1)
"""A byte position in a file (PSEND's start)."""


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """The ``kermit`` subcommand's options (``send`` and ``receive``)."""
    sub = ap.add_subparsers(dest="kermit_command", required=True)
    send = sub.add_parser("send", help="send files to a Kermit receiver")
    send.add_argument("files", metavar="FILE", nargs="+", help="files to send (binary mode)")
    recv = sub.add_parser("receive", help="receive files from a Kermit sender")
    recv.add_argument("directory", metavar="DIR", nargs="?", default=".", help="default: .")
    server = sub.add_parser(
        "server",
        help="serve DIR to a Kermit client (GET, SEND, REMOTE DIR/CD/DELETE/SPACE, FINISH, BYE)",
    )
    server.add_argument(
        "directory", metavar="DIR", nargs="?", default=".", help="the served tree (default: .)"
    )
    get = sub.add_parser("get", help="ask a Kermit server for files (C-Kermit's GET)")
    get.add_argument("spec", metavar="REMOTE_FILE", help="file name or pattern on the server")
    get.add_argument("directory", metavar="DIR", nargs="?", default=".", help="default: .")
    get.add_argument(
        "--recover",
        action="store_true",
        help="REGET: the server resends only what DIR does not hold yet (C-Kermit's reget)",
    )
    remote = sub.add_parser(
        "remote", help="a REMOTE command to a Kermit server; its answer goes to stdout"
    )
    remote.add_argument("remote_command", metavar="COMMAND", choices=sorted(REMOTE_COMMANDS))
    remote.add_argument(
        "argument", metavar="ARG", nargs="?", default="", help="directory or file pattern"
    )
    send.add_argument(
        "--resend",
        action="store_true",
        help="recovery (C-Kermit's RESEND): send only what the receiver does not hold yet",
    )
    send.add_argument(
        "--start-at",
        type=FILE_OFFSET,
        default=0,
        metavar="BYTE",
        help="PSEND: send each file from this byte on (default 0)",
    )
    send.add_argument(
        "--text",
        action="store_true",
        help="text mode: LF line ends go as CR LF (the receiver restores its own)",
    )
    for p in (send, recv, server, get, remote):
        p.add_argument(
            "--port", type=SERIAL_PORT, required=True, help="device path, pty or pyserial URL"
        )
        p.add_argument(
            "--baud",
            type=BAUD,
            default=None,
            help="port speed in bit/s (default 9600); the timers and the packet length "
            "also follow it (without it they assume 9600, then measure)",
        )
        p.add_argument(
            "--delay",
            type=DELAY,
            default=0.0,
            help="one-way delay of the line in seconds (a hint for the timers and the packet "
            "length; 1.3 for the Moon)",
        )
        p.add_argument(
            "--packet-length",
            "--max-len",
            dest="packet_length",
            type=KERMIT_LENGTH,
            default=1000,
            help="longest packet, MARK through CHECK (default 1000; 96 or less = no long "
            "packets); the sender picks shorter ones when it measures errors",
        )
        p.add_argument(
            "--fixed-length",
            action="store_true",
            help="always send the longest packets the receiver accepts (no dynamic length)",
        )
        p.add_argument(
            "--streaming",
            "--reliable",
            dest="streaming",
            action="store_true",
            help="the line is reliable (a serial socket, TCP): offer streaming, no ACK per "
            "packet; any transmission error is then fatal",
        )
        p.add_argument(
            "--literal-names",
            action="store_true",
            help="file names as they are (default: common form on send, lower case on receive)",
        )
        p.add_argument(
            "--window", type=KERMIT_WINDOW, default=31, help="window slots, 1..31 (default 31)"
        )
        p.add_argument(
            "--check",
            type=int,
            choices=(1, 2, 3, 5),
            default=3,
            help="block check (default 3; 5 = FORCE-3: CRC-16 on the init packets too)",
        )
        p.add_argument(
            "--timeout",
            type=KERMIT_TIMEOUT,
            help="fixed timeout in seconds (default: from --delay and --baud, then from "
            "measured round trips)",
        )
        p.add_argument(
            "--retries",
            type=RETRIES,
            default=10,
            help="retries per packet, 0 = no limit (default 10)",
        )
        p.add_argument(
            "--seven-bit", action="store_true", help="7-bit line: require 8th-bit prefixing"
        )
        p.add_argument("--no-repeat", action="store_true", help="do not offer repeat counts")
        p.add_argument(
            "--stats", "--json", action="store_true", help="print the counters as JSON on stderr"
        )
        p.add_argument("-v", "--verbose", action="store_true", help="log each file to stderr")
        p.add_argument("--trace", action="store_true", help="log every packet, decoded, to stderr")


def _config(args: argparse.Namespace) -> KermitConfig:
    return KermitConfig(
        max_packet_length=args.packet_length,
        window=args.window,
        check=BlockCheck(3 if args.check == 5 else args.check),
        force3=args.check == 5,
        streaming=args.streaming,
        timeout=args.timeout,
        retry_limit=args.retries,
        seven_bit=args.seven_bit,
        repeat=not args.no_repeat,
        delay=args.delay,
        rate=args.baud,
        dynamic_length=not args.fixed_length,
        literal_names=args.literal_names,
        resend=getattr(args, "resend", False),
        text=getattr(args, "text", False),
    )


async def _run(args: argparse.Namespace, config: KermitConfig) -> KermitStatistics | None:
    port = await open_port(args.port, args.baud or 9600)
    async with port:
        command = args.kermit_command
        if command == "send":
            return await kermit_send(port, args.files, config, start_at=args.start_at)
        if command == "server":
            count = await kermit_server(port, args.directory, config)
            print(f"serialsocket kermit: server done after {count} requests", file=sys.stderr)
            return None
        if command == "get":
            return await kermit_get(port, args.spec, args.directory, config, recover=args.recover)
        if command == "remote":
            text = await kermit_remote(port, args.remote_command, args.argument, config)
            if text:
                sys.stdout.write(text if text.endswith("\n") else text + "\n")
            return None
        return await kermit_receive(port, args.directory, config)


def _print_stats(stats: KermitStatistics) -> None:
    record = asdict(stats)
    record["state"] = stats.state.value
    record["check"] = int(stats.check)
    print(json.dumps(record), file=sys.stderr)


def kermit_main(args: argparse.Namespace) -> int:
    """Run ``kermit send`` / ``kermit receive``; returns the exit status."""
    # Warnings (a file name shortened to fit a packet) always show; -v adds a
    # line per file.
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="kermit: %(message)s"
    )
    if args.trace:
        logging.getLogger("serialsocket.kermit").setLevel(logging.DEBUG)
    try:
        config = _config(args)
        stats = run_interruptibly(_run, args, config)
    except LocalProtocolError as exc:
        print(f"serialsocket kermit: {exc}", file=sys.stderr)
        return 2
    except EOFError as exc:
        print(f"serialsocket kermit: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"serialsocket kermit: {exc}", file=sys.stderr)
        return 2
    except KermitTransferError as exc:
        who = "the peer" if exc.by_peer else "we"
        print(f"serialsocket kermit: transfer failed ({who} gave up): {exc}", file=sys.stderr)
        if args.stats:
            _print_stats(exc.statistics)
        return 1
    if args.stats and stats is not None:
        _print_stats(stats)
    return 0
