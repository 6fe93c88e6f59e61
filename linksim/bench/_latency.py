"""``linksim bench latency``: command -> completed round trip over loopback TCP and a pty.

A zero-duration command (STATUS, answered by an instant executor) goes
through the whole tcpstream path -- client encode, TCP, server decode,
exactly-once memory, queue, executor task, COMPLETED reply, client decode --
and is timed until its result is back.  Beside it, in the same run and the
same event loop, a raw TCP echo of one packet's worth of bytes (216) gives
the floor: what the loopback and trio cost with no protocol at all.  The two
are measured in alternating blocks, so load on the machine hits both alike.

Over a serial socket (``--transport serial``) the same session runs over a
:class:`serialsocket.SerialSocket` on a raw pty pair (no impairments, no rate
limit: the Kermit packet path, CRC, ARQ and its acknowledgements are the
cost), beside a raw echo of 216 bytes over a second pty pair.

With ``client="asyncio"`` (``--client asyncio``) the controller side is the
asyncio one -- :mod:`tcpstream.asyncio`'s client, over loopback TCP or over
:mod:`serialsocket.asyncio`'s ``open_connection`` on the pty -- and the raw
echo goes through asyncio too (its streams; the asyncio serial port).  The arm
and echo servers stay trio, so they run in a process of their own (in a
thread, the two loops fight over the GIL: 5 ms switch intervals, not
latency).  ``server="process"`` (``--server process``) runs the trio client
against that same process, for a like-for-like comparison of the clients;
by default the trio client shares its loop with the servers, as before.

Reported per transport: p50, p99 and mean of each, in microseconds, and the
p50 ratio.  Targets (issue 6, TCP): p50 within 10x of the raw echo, p99 under 2 ms.
This is a benchmark, not a test: it measures and prints, it asserts nothing.
"""

from __future__ import annotations

import asyncio
import os
import select
import statistics
import subprocess
import sys
import time
import tty
from collections.abc import Awaitable, Callable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from functools import partial
from typing import Any

import trio

import serialsocket
import serialsocket.asyncio as serial_asyncio
import tcpstream.asyncio as arm_asyncio
from tcpstream import (
    Command,
    CommandResult,
    FailureReason,
    Feedback,
    Server,
    ServerConfig,
    connect_stream,
    connect_tcp,
    serve_tcp,
)
from tcpstream.commands import PACKET_SIZE

__all__ = ["CLIENTS", "TRANSPORTS", "InstantArm", "run"]

NO_RATE_LIMIT = None
"""The bench ping-pongs as fast as the host allows (thousands of packets a
second), far past the server's default ``max_packet_rate``: it measures the
protocol path, so the arm's flood protection is off here."""

_STATE = Feedback(
    joints=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    finger_opening=0.0,
    p=(0.5, 0.0, 0.4),
    s=(0.0, 1.0, 0.0),
    a=(0.0, 0.0, 1.0),
)


class InstantArm:
    """An executor that answers every command at once (no motion, no checkpoint)."""

    control_rate_hz = 125.0

    async def execute(self, command: Command) -> CommandResult:
        return CommandResult(_STATE)

    def halt(self, reason: FailureReason) -> None:
        """Nothing moves, so nothing to stop."""

    def state(self) -> Feedback:
        return _STATE


def _port(listeners: Sequence[Any]) -> int:
    port: int = listeners[0].socket.getsockname()[1]
    return port


async def _echo_handler(stream: trio.abc.Stream) -> None:
    buf = bytearray()
    while True:
        data = await stream.receive_some(65536)
        if not data:
            return
        buf += data
        while len(buf) >= PACKET_SIZE:
            await stream.send_all(bytes(buf[:PACKET_SIZE]))
            del buf[:PACKET_SIZE]


async def _echo_once(stream: trio.abc.Stream, packet: bytes) -> None:
    await stream.send_all(packet)
    got = 0
    while got < PACKET_SIZE:
        data = await stream.receive_some(PACKET_SIZE - got)
        if not data:
            raise RuntimeError("echo server closed")
        got += len(data)


def _summary(samples: list[float]) -> dict[str, float]:
    ordered = sorted(samples)

    def pct(q: float) -> float:
        return ordered[min(len(ordered) - 1, int(q * len(ordered)))] * 1e6

    return {
        "p50_us": round(pct(0.50), 1),
        "p99_us": round(pct(0.99), 1),
        "mean_us": round(statistics.fmean(ordered) * 1e6, 1),
        "min_us": round(ordered[0] * 1e6, 1),
    }


async def _alternate(
    command: Callable[[], Awaitable[object]],
    echo: Callable[[], Awaitable[None]],
    count: int,
    warmup: int,
    block: int,
) -> tuple[list[float], list[float]]:
    """Command round trips and raw echoes in alternating blocks (load hits both alike).

    Plain awaits, no library calls: the same loop times the trio and the asyncio client.
    """
    command_rtt: list[float] = []
    echo_rtt: list[float] = []
    clock = time.perf_counter
    for _ in range(warmup):
        await command()
        await echo()
    done = 0
    while done < count:
        n = min(block, count - done)
        for _ in range(n):
            t0 = clock()
            await command()
            command_rtt.append(clock() - t0)
        for _ in range(n):
            t0 = clock()
            await echo()
            echo_rtt.append(clock() - t0)
        done += n
    return command_rtt, echo_rtt


def _trio_echo(stream: trio.abc.Stream) -> Callable[[], Awaitable[None]]:
    packet = bytes(PACKET_SIZE)
    return partial(_echo_once, stream, packet)


async def _measure_tcp(
    count: int, warmup: int, block: int, key: bytes | None
) -> tuple[list[float], list[float]]:
    async with trio.open_nursery() as nursery:
        arm_listeners = await nursery.start(
            partial(
                serve_tcp,
                InstantArm(),
                0,
                host="127.0.0.1",
                telemetry_every=0,
                key=key,
                max_packet_rate=NO_RATE_LIMIT,
            )
        )
        echo_listeners = await nursery.start(
            partial(trio.serve_tcp, _echo_handler, 0, host="127.0.0.1")
        )
        echo = await trio.open_tcp_stream("127.0.0.1", _port(echo_listeners))
        async with (
            echo,
            connect_tcp("127.0.0.1", _port(arm_listeners), identity="bench", key=key) as arm,
        ):
            samples = await _alternate(arm.status, _trio_echo(echo), count, warmup, block)
        nursery.cancel_scope.cancel()
    return samples


async def _measure_serial(
    count: int, warmup: int, block: int, key: bytes | None
) -> tuple[list[float], list[float]]:
    config = serialsocket.EndpointConfig()  # a raw pty: no delay, no rate limit
    ctl_port, arm_port = serialsocket.open_pty_pair()
    echo_a, echo_b = serialsocket.open_pty_pair()

    async def arm_side(listener: serialsocket.SerialListener) -> None:
        sock = await listener.accept()
        config = ServerConfig(telemetry_every=0, key=key, max_packet_rate=NO_RATE_LIMIT)
        async with Server(InstantArm(), config) as server:
            await server.serve_stream(sock)

    async with (
        echo_a,
        echo_b,
        trio.open_nursery() as nursery,
        serialsocket.listen(arm_port, config) as listener,
    ):
        nursery.start_soon(arm_side, listener)
        nursery.start_soon(_echo_handler, echo_b)
        sock = await serialsocket.connect(ctl_port, config, nursery=nursery, defer=True)
        async with sock, connect_stream(sock, identity="bench", key=key) as arm:
            samples = await _alternate(arm.status, _trio_echo(echo_a), count, warmup, block)
        nursery.cancel_scope.cancel()
    return samples


TRANSPORTS = {"tcp": _measure_tcp, "serial": _measure_serial}


# -- the servers in a process of their own -------------------------------------------


async def _serve_in_child(transport: str, key: bytes | None, fds: Sequence[int]) -> None:
    """The arm and the echo server (trio) until the parent closes our stdin.

    Prints one line when listening: ``ready ARM_PORT ECHO_PORT`` for TCP,
    ``ready`` for the serial transport (the ptys' master fds were passed in).
    """
    async with trio.open_nursery() as nursery:
        if transport == "tcp":
            arm_listeners = await nursery.start(
                partial(
                    serve_tcp,
                    InstantArm(),
                    0,
                    host="127.0.0.1",
                    telemetry_every=0,
                    key=key,
                    max_packet_rate=NO_RATE_LIMIT,
                )
            )
            echo_listeners = await nursery.start(
                partial(trio.serve_tcp, _echo_handler, 0, host="127.0.0.1")
            )
            print(f"ready {_port(arm_listeners)} {_port(echo_listeners)}", flush=True)
        else:
            arm_port = trio.lowlevel.FdStream(fds[0])
            echo_port = trio.lowlevel.FdStream(fds[1])
            config = serialsocket.EndpointConfig()  # a raw pty: no delay, no rate limit

            async def arm_side() -> None:
                async with serialsocket.listen(arm_port, config) as listener:
                    sock = await listener.accept()
                    server_config = ServerConfig(
                        telemetry_every=0, key=key, max_packet_rate=NO_RATE_LIMIT
                    )
                    async with Server(InstantArm(), server_config) as server:
                        await server.serve_stream(sock)
                    await trio.sleep_forever()

            nursery.start_soon(arm_side)
            nursery.start_soon(_echo_handler, echo_port)
            print("ready", flush=True)
        stdin = trio.lowlevel.FdStream(os.dup(0))
        while await stdin.receive_some():
            pass  # the parent closes our stdin (or exits) when it is done
        nursery.cancel_scope.cancel()


def _child_main() -> None:
    """Entry point of the server process: ``TRANSPORT KEY_HEX|- [ARM_FD ECHO_FD]``."""
    transport, key_hex, *fds = sys.argv[1:]
    key = None if key_hex == "-" else bytes.fromhex(key_hex)
    trio.run(_serve_in_child, transport, key, [int(fd) for fd in fds])


_CHILD_START = 30.0
"""Seconds the server process may take to start listening (a hang guard only)."""


@contextmanager
def _server_process(transport: str, key: bytes | None) -> Iterator[tuple[Any, Any]]:
    """The trio servers in a child process; yields where to reach the arm and the
    echo: two TCP ports, or the slave paths of two raw ptys."""
    with ExitStack() as stack:
        fds: list[int] = []
        paths: list[str] = []
        if transport == "serial":
            for _ in range(2):
                master, path = stack.enter_context(_raw_pty())
                fds.append(master)
                paths.append(path)
        child = subprocess.Popen(
            [
                sys.executable,
                "-c",
                "from linksim.bench import _latency; _latency._child_main()",
                transport,
                key.hex() if key is not None else "-",
                *map(str, fds),
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            pass_fds=fds,
            text=True,
        )
        try:
            assert child.stdout is not None
            readable, _, _ = select.select([child.stdout], [], [], _CHILD_START)
            line = child.stdout.readline().split() if readable else []
            if not line or line[0] != "ready":
                raise RuntimeError("the latency servers did not start")
            if transport == "tcp":
                yield int(line[1]), int(line[2])
            else:
                yield paths[0], paths[1]
        finally:
            if child.stdin is not None:
                child.stdin.close()
            try:
                child.wait(10)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()


@contextmanager
def _raw_pty() -> Iterator[tuple[int, str]]:
    """A raw pty: the master fd (for the server process) and the slave's path."""
    master, slave = os.openpty()
    try:
        tty.setraw(master)
        tty.setraw(slave)
        yield master, os.ttyname(slave)
    finally:
        os.close(master)
        os.close(slave)


async def _trio_client(
    transport: str, arm: Any, echo: Any, count: int, warmup: int, block: int, key: bytes | None
) -> tuple[list[float], list[float]]:
    """The trio client against the server process."""
    if transport == "tcp":
        echo_stream: trio.abc.Stream = await trio.open_tcp_stream("127.0.0.1", echo)
        async with (
            echo_stream,
            connect_tcp("127.0.0.1", arm, identity="bench", key=key) as client,
        ):
            return await _alternate(client.status, _trio_echo(echo_stream), count, warmup, block)
    config = serialsocket.EndpointConfig()
    echo_port = await serialsocket.open_port(echo)
    async with echo_port, trio.open_nursery() as nursery:
        sock = await serialsocket.connect(await serialsocket.open_port(arm), config, defer=True)
        async with sock, connect_stream(sock, identity="bench", key=key) as client:
            samples = await _alternate(client.status, _trio_echo(echo_port), count, warmup, block)
        nursery.cancel_scope.cancel()
    return samples


async def _asyncio_client(
    transport: str, arm: Any, echo: Any, count: int, warmup: int, block: int, key: bytes | None
) -> tuple[list[float], list[float]]:
    """The asyncio client against the server process: no trio in this process's loop."""
    packet = bytes(PACKET_SIZE)
    if transport == "tcp":
        reader, writer = await asyncio.open_connection("127.0.0.1", echo)

        async def tcp_echo() -> None:
            writer.write(packet)
            await writer.drain()
            await reader.readexactly(PACKET_SIZE)

        try:
            async with arm_asyncio.connect_tcp("127.0.0.1", arm, identity="bench", key=key) as c:
                return await _alternate(c.status, tcp_echo, count, warmup, block)
        finally:
            writer.close()
            await writer.wait_closed()
    config = serialsocket.EndpointConfig()
    echo_port = await serial_asyncio.open_port(echo)

    async def pty_echo() -> None:
        await echo_port.write(packet)
        got = 0
        while got < PACKET_SIZE:
            got += len(await echo_port.read(PACKET_SIZE - got))

    async def opener() -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        return await serial_asyncio.open_connection(arm, config)

    try:
        async with arm_asyncio.AsyncioArmClient(
            opener, identity="bench", key=key, reconnect_attempts=0
        ) as c:
            return await _alternate(c.status, pty_echo, count, warmup, block)
    finally:
        await echo_port.aclose()


def _measure_apart(
    transport: str, client: str, count: int, warmup: int, block: int, key: bytes | None
) -> tuple[list[float], list[float]]:
    with _server_process(transport, key) as (arm, echo):
        if client == "trio":
            return trio.run(_trio_client, transport, arm, echo, count, warmup, block, key)
        return asyncio.run(_asyncio_client(transport, arm, echo, count, warmup, block, key))


CLIENTS = ("trio", "asyncio")
"""The controller side: the trio client, or the asyncio one (tcpstream.asyncio,
serialsocket.asyncio)."""

SERVERS = ("loop", "process")
"""Where the arm and echo servers run: in the client's own trio loop (the trio
client only), or in a process of their own."""


def _report(
    transport: str,
    client: str,
    server: str,
    count: int,
    key: bytes | None,
    samples: tuple[list[float], list[float]],
) -> dict[str, Any]:
    command_rtt, echo_rtt = samples
    cmd, raw = _summary(command_rtt), _summary(echo_rtt)
    ratio = cmd["p50_us"] / raw["p50_us"] if raw["p50_us"] else float("inf")
    return {
        "benchmark": "latency",
        "transport": transport,
        "client": client,
        "server": server,
        "count": count,
        "authenticated": key is not None,
        "packet_bytes": PACKET_SIZE,
        "command": cmd,
        "raw_echo": raw,
        "p50_ratio": round(ratio, 2),
        "target_p50_within_10x": ratio <= 10.0,
        "target_p99_under_2ms": cmd["p99_us"] < 2000.0,
    }


_BENCH_KEY = b"latency-benchmark-key-0123456789"


async def _measure_in_loop(
    transport: str, count: int, warmup: int, block: int, key: bytes | None
) -> tuple[list[float], list[float]]:
    return await TRANSPORTS[transport](count, warmup, block, key)


def run(
    count: int = 2000,
    warmup: int = 200,
    block: int = 100,
    *,
    authenticated: bool = False,
    transport: str = "tcp",
    client: str = "trio",
    server: str | None = None,
) -> dict[str, Any]:
    """Measure ``count`` command round trips and ``count`` raw echoes; the report as a dict.

    ``authenticated``: with a pre-shared key (HMAC on every packet), else without.
    ``transport``: ``"tcp"`` (loopback) or ``"serial"`` (a serial socket on a raw pty).
    ``client``: ``"trio"`` or ``"asyncio"``; ``server``: ``"loop"`` (the trio
    client's own loop; its default) or ``"process"`` (the asyncio client's
    default and only choice).  See the module docstring.
    """
    if count < 1 or warmup < 0 or block < 1:
        raise ValueError("count >= 1, warmup >= 0, block >= 1")
    if transport not in TRANSPORTS:
        raise ValueError(f"transport must be one of {', '.join(TRANSPORTS)}")
    if client not in CLIENTS:
        raise ValueError(f"client must be one of {', '.join(CLIENTS)}")
    server = server or ("loop" if client == "trio" else "process")
    if server not in SERVERS:
        raise ValueError(f"server must be one of {', '.join(SERVERS)}")
    if client == "asyncio" and server == "loop":
        raise ValueError("the asyncio client cannot share a loop with the trio servers")
    key = _BENCH_KEY if authenticated else None
    if server == "loop":
        samples = trio.run(_measure_in_loop, transport, count, warmup, block, key)
    else:
        samples = _measure_apart(transport, client, count, warmup, block, key)
    return _report(transport, client, server, count, key, samples)
