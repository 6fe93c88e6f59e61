"""``linksim arm-server``: the simulated arm behind a command server, on a serial line or TCP.

Seed 003 section 9: the manipulator listens; a controlling agent connects
(over TCP, or over a serial socket after dialing its modem); when the session
is over "the manipulator will reset and listen for further connection
requests".  One :class:`tcpstream.Server` lives across sessions, so its
exactly-once memory survives a reconnect.

When it is listening it prints one JSON line on stdout, ``{"ready": true,
"transport": ..., ...}`` (with ``"tcp_port"`` for TCP), so a parent process
knows when to connect.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import pathlib
import sys
from typing import Any

import trio

import serialsocket
from tcpstream import Server, ServerConfig

from ._arm import SimulatedArm
from ._cliargs import (
    BAUD,
    BIT_RATE,
    COUNT,
    DELAY,
    ENDPOINT_LENGTH,
    SERIAL_PORT,
    TCP_PORT_OR_ANY,
    WINDOW,
    FloatRange,
)
from ._config import LinkConfig
from ._pair import endpoint_config_for
from ._world import DEFAULT_WORLD, WorldConfig

__all__ = ["add_arguments", "arm_server_main", "serve_arm_serial", "serve_arm_tcp"]

log = logging.getLogger(__name__)


def _ready(**fields: Any) -> None:
    print(json.dumps({"ready": True, **fields}), flush=True)


async def serve_arm_serial(
    server: Server,
    path: str,
    endpoint: serialsocket.EndpointConfig,
    *,
    baud: int = 9600,
    answer: bool = False,
    sessions: int | None = None,
) -> None:
    """Serve sessions over the serial port at ``path`` (answering a modem call first).

    Returns after ``sessions`` sessions (None: forever, until cancelled).
    Without a modem one listener serves every session; with one, each
    session is a call: answer, serve, hang up, answer the next.
    """
    served = 0
    while sessions is None or served < sessions:
        port = await serialsocket.open_port(path, baud)
        if answer:
            _ready(transport="serial", port=path, modem=True)
            connection = await serialsocket.answer(port, timeout=None)
            log.info("answered: %s", connection)
        async with serialsocket.listen(port, endpoint) as listener:
            if not answer:
                _ready(transport="serial", port=path, modem=False)
            while sessions is None or served < sessions:
                sock = await listener.accept()
                try:
                    await server.serve_stream(sock)
                except (trio.BrokenResourceError, trio.ClosedResourceError) as exc:
                    log.info("session ended: %s", exc)
                finally:
                    await sock.aclose()
                served += 1
                if answer:
                    break  # the call is over; the port is closed and reopened for the next


async def serve_arm_tcp(
    server: Server, port: int, *, host: str = "127.0.0.1", sessions: int | None = None
) -> None:
    """Serve sessions on ``host:port`` (0 picks a free port, printed in the ready line)."""
    listeners = await trio.open_tcp_listeners(port, host=host)
    bound = listeners[0].socket.getsockname()[1]
    _ready(transport="tcp", host=host, tcp_port=bound)
    served = 0
    try:
        async with trio.open_nursery() as nursery:
            while sessions is None or served < sessions:
                stream = await listeners[0].accept()
                served += 1
                if sessions is not None and served >= sessions:
                    # The last session: serve it here, then stop listening.
                    await server.serve_stream(stream)
                    break
                nursery.start_soon(server.serve_stream, stream)
    finally:
        for listener in listeners:
            await listener.aclose()


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
    ap.add_argument("--world", help="world configuration (TOML); default: the demo's table")
    ap.add_argument("--key-file", help="file holding the pre-shared key (>= 16 bytes)")
    ap.add_argument(
        "--max-packet-rate",
        type=_PACKET_RATE,
        default=200.0,
        help="packets a second each connection may send before its reads are slowed "
        "(default 200; at least 16 at the default heartbeat; 0: no limit)",
    )
    ap.add_argument("--sessions", type=COUNT, help="exit after this many sessions (>= 1)")
    ap.add_argument("-v", "--verbose", action="store_true", help="log sessions to stderr")


def _read_key(path: str) -> bytes:
    """A key file holds the pre-shared key as hex digits (whitespace ignored)."""
    with open(path, encoding="ascii") as f:
        text = "".join(f.read().split())
    try:
        return bytes.fromhex(text)
    except ValueError:
        raise ValueError(f"{path}: the key file must hold the key as hex digits") from None


def server_config_for(
    link: LinkConfig, key: bytes | None, *, max_packet_rate: float | None = 200.0
) -> ServerConfig:
    """Server timing derived from the line (see :func:`linksim._demo.rtt_hint_for`)."""
    from ._demo import rtt_hint_for

    return ServerConfig(key=key, rtt_hint=rtt_hint_for(link), max_packet_rate=max_packet_rate)


def arm_server_main(args: argparse.Namespace) -> int:
    """``linksim arm-server``: exits 0 after ``--sessions`` sessions or on Ctrl-C."""
    from ._config import DirectionConfig

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
        world = WorldConfig.from_toml(pathlib.Path(args.world)) if args.world else DEFAULT_WORLD
        key = _read_key(args.key_file) if args.key_file else None
        rate = args.rate or (args.baud if args.transport == "serial" else None)
        link = LinkConfig.symmetric(DirectionConfig(rate=rate, delay=args.delay))
        server_cfg = server_config_for(
            link, key, max_packet_rate=rate_limit if rate_limit > 0 else None
        )
        overrides: dict[str, Any] = {}
        if args.window is not None:
            overrides["window"] = args.window
        if args.max_len is not None:
            overrides["max_packet_length"] = args.max_len
        endpoint = endpoint_config_for(link, **overrides)
    except (OSError, ValueError) as exc:
        print(f"linksim arm-server: {exc}", file=sys.stderr)
        return 2
    if args.transport == "serial" and not args.port:
        print("linksim arm-server: --port PATH is needed for the serial transport", file=sys.stderr)
        return 2

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
                )
            else:
                await serve_arm_tcp(server, args.tcp_port, host=args.host, sessions=args.sessions)

    try:
        trio.run(main)
    except KeyboardInterrupt:
        return 0
    except (OSError, serialsocket.DialError) as exc:
        print(f"linksim arm-server: {exc}", file=sys.stderr)
        return 1
    return 0
