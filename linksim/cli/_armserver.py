"""``linksim arm-server``: options and exit status (the serving is :mod:`linksim.demo`'s).

Exit status: 0 after ``--sessions`` sessions or on Ctrl-C, 1 when the port
or the modem fails, 2 for bad options.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys

import serialsocket
from linksim.arm import SimulatedArm
from linksim.demo import serve_arm_serial, serve_arm_tcp
from linksim.link import (
    DirectionConfig,
    LinkConfig,
    endpoint_config_for,
    endpoint_overrides,
    server_config_for,
)
from serialsocket.capture import CaptureFile
from serialsocket.interrupt import run_interruptibly
from tcpstream import Server

from ._args import (
    BAUD,
    BIT_RATE,
    COUNT,
    DELAY,
    ENDPOINT_LENGTH,
    SERIAL_PORT,
    TCP_PORT_OR_ANY,
    WINDOW,
    FloatRange,
    load_world,
    read_key,
    write_template,
)

__all__ = ["add_arguments", "arm_server_main"]


_PACKET_RATE = FloatRange(0.0, 1e6, unit="packets a second")
"""--max-packet-rate: 0 is no limit; a million a second is more than any link carries."""


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim arm-server``."""
    ap.add_argument("--transport", choices=["serial", "tcp"], default="serial")
    ap.add_argument("--port", type=SERIAL_PORT, help="serial device or pty path (serial transport)")
    ap.add_argument("--baud", type=BAUD, default=9600, help="line rate, bit/s (default 9600)")
    ap.add_argument("--answer", action="store_true", help="answer a modem call before serving")
    ap.add_argument("--host", default="127.0.0.1", help="TCP address (default loopback)")
    ap.add_argument(
        "--tcp-port", type=TCP_PORT_OR_ANY, default=7010, help="TCP port (0: any free port)"
    )
    ap.add_argument("--delay", type=DELAY, default=0.0, help="one-way delay hint, s")
    ap.add_argument("--rate", type=BIT_RATE, help="line rate hint, bit/s (default: --baud)")
    ap.add_argument("--window", type=WINDOW, help="serial socket window (1..31)")
    ap.add_argument("--max-len", type=ENDPOINT_LENGTH, help="serial packet length limit")
    ap.add_argument(
        "--world", help="world configuration (TOML; - for stdin); default: the demo's table"
    )
    ap.add_argument(
        "--write-world",
        metavar="FILE",
        help="write the world (--world's, or the demo's table) as a commented TOML file "
        "(- for stdout) and exit; edit it and pass it back with --world FILE",
    )
    ap.add_argument("--key-file", help="file holding the pre-shared key (>= 16 bytes)")
    ap.add_argument(
        "--max-packet-rate",
        type=_PACKET_RATE,
        default=200.0,
        help="packets a second each connection may send before its reads are slowed "
        "(default 200; at least 16 at the default heartbeat; 0: no limit)",
    )
    ap.add_argument("--sessions", type=COUNT, help="exit after this many sessions (>= 1)")
    ap.add_argument(
        "--capture",
        metavar="FILE",
        help="write the traffic, both ways with timestamps, to FILE.pcapng: the serial "
        "port's Kermit packets, or each TCP connection's command packets "
        "(for Wireshark with contrib/wireshark/telelink.lua)",
    )
    ap.add_argument("-v", "--verbose", action="store_true", help="log sessions to stderr")


def arm_server_main(args: argparse.Namespace) -> int:
    """``linksim arm-server``: exits 0 after ``--sessions`` sessions or on Ctrl-C."""
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING)
    rate_limit = args.max_packet_rate
    if not (math.isfinite(rate_limit) and rate_limit >= 0):
        print(
            "linksim arm-server: --max-packet-rate must be a number of packets a second "
            f">= 0 (0: no limit), got {rate_limit}",
            file=sys.stderr,
        )
        return 2
    try:
        world = load_world(args.world)
        if args.write_world:
            return write_template(args.write_world, world.to_toml(), "linksim arm-server")
        key = read_key(args.key_file) if args.key_file else None
        rate = args.rate or (args.baud if args.transport == "serial" else None)
        link = LinkConfig.symmetric(DirectionConfig(rate=rate, delay=args.delay))
        server_cfg = server_config_for(
            link, key, max_packet_rate=rate_limit if rate_limit > 0 else None
        )
        endpoint = endpoint_config_for(
            link, **endpoint_overrides(window=args.window, max_len=args.max_len)
        )
    except (OSError, ValueError) as exc:
        print(f"linksim arm-server: {exc}", file=sys.stderr)
        return 2
    if args.transport == "serial" and not args.port:
        print("linksim arm-server: --port PATH is needed for the serial transport", file=sys.stderr)
        return 2

    capture: CaptureFile | None = None

    async def main() -> None:
        arm = SimulatedArm(world)
        async with Server(arm, server_cfg) as server:
            if args.transport == "serial":
                await serve_arm_serial(
                    server,
                    args.port,
                    endpoint,
                    baud=args.baud,
                    answer=args.answer,
                    sessions=args.sessions,
                    capture=capture,
                )
            else:
                await serve_arm_tcp(
                    server, args.tcp_port, host=args.host, sessions=args.sessions, capture=capture
                )

    try:
        if args.capture:
            capture = CaptureFile(args.capture)
        run_interruptibly(main)
    except KeyboardInterrupt:
        return 0
    except (OSError, serialsocket.DialError) as exc:
        print(f"linksim arm-server: {exc}", file=sys.stderr)
        return 1
    finally:
        if capture is not None:
            capture.close()
    return 0
