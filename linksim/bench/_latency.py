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

Reported per transport: p50, p99 and mean of each, in microseconds, and the
p50 ratio.  Targets (issue 6, TCP): p50 within 10x of the raw echo, p99 under 2 ms.
This is a benchmark, not a test: it measures and prints, it asserts nothing.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Sequence
from functools import partial
from typing import Any

import trio

import serialsocket
from tcpstream import (
    ArmClient,
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

__all__ = ["TRANSPORTS", "InstantArm", "run"]

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
    arm: ArmClient, echo: trio.abc.Stream, count: int, warmup: int, block: int
) -> tuple[list[float], list[float]]:
    """Command round trips and raw echoes in alternating blocks (load hits both alike)."""
    command_rtt: list[float] = []
    echo_rtt: list[float] = []
    packet = bytes(PACKET_SIZE)
    clock = time.perf_counter
    for _ in range(warmup):
        await arm.status()
        await _echo_once(echo, packet)
    done = 0
    while done < count:
        n = min(block, count - done)
        for _ in range(n):
            t0 = clock()
            await arm.status()
            command_rtt.append(clock() - t0)
        for _ in range(n):
            t0 = clock()
            await _echo_once(echo, packet)
            echo_rtt.append(clock() - t0)
        done += n
    return command_rtt, echo_rtt


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
            samples = await _alternate(arm, echo, count, warmup, block)
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
        sock = await serialsocket.connect(ctl_port, config, nursery=nursery)
        async with sock, connect_stream(sock, identity="bench", key=key) as arm:
            samples = await _alternate(arm, echo_a, count, warmup, block)
        nursery.cancel_scope.cancel()
    return samples


TRANSPORTS = {"tcp": _measure_tcp, "serial": _measure_serial}


async def _measure(
    transport: str, count: int, warmup: int, block: int, key: bytes | None
) -> dict[str, Any]:
    command_rtt, echo_rtt = await TRANSPORTS[transport](count, warmup, block, key)
    cmd, raw = _summary(command_rtt), _summary(echo_rtt)
    ratio = cmd["p50_us"] / raw["p50_us"] if raw["p50_us"] else float("inf")
    return {
        "benchmark": "latency",
        "transport": transport,
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


def run(
    count: int = 2000,
    warmup: int = 200,
    block: int = 100,
    *,
    authenticated: bool = False,
    transport: str = "tcp",
) -> dict[str, Any]:
    """Measure ``count`` command round trips and ``count`` raw echoes; the report as a dict.

    ``authenticated``: with a pre-shared key (HMAC on every packet), else without.
    ``transport``: ``"tcp"`` (loopback) or ``"serial"`` (a serial socket on a raw pty).
    """
    if count < 1 or warmup < 0 or block < 1:
        raise ValueError("count >= 1, warmup >= 0, block >= 1")
    if transport not in TRANSPORTS:
        raise ValueError(f"transport must be one of {', '.join(TRANSPORTS)}")
    key = _BENCH_KEY if authenticated else None
    result: dict[str, Any] = trio.run(_measure, transport, count, warmup, block, key)
    return result
