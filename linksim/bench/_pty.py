"""``linksim bench pty``: SerialSocket goodput over a raw pty pair, no impairments
(``--port socket``: over pyserial's ``socket://``; ``--port loop``: raw ``loop://`` I/O;
``--port memory``: the two endpoints alone, no port).

Two serial sockets talk over the master and slave side of one pty
(``serialsocket.open_pty_pair``), in one process and one trio run on the wall
clock.  Each run connects, sends ``--size`` bytes of random binary one way,
reads them all on the other side (checked byte for byte), and closes.  The
time is from the first ``send_all`` to the last byte read; the report gives
the median of ``--runs`` runs for each packet length (MB/s = 10^6 bytes per
second of application data).  This is a benchmark, not a test.

``--port memory`` hands each endpoint's output straight to the other
(sans-I/O, no trio, no port) and times the transfer in process CPU time:
what the ARQ and the codec cost, both sides together, apart from the I/O
and the machine's other load.

``--profile FILE`` runs one extra transfer per packet length under cProfile
and writes the statistics (``python -m pstats FILE``).
"""

from __future__ import annotations

import cProfile
import os
import statistics
import time
from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager

import trio

from serialsocket import (
    ConnectionRequested,
    Endpoint,
    EndpointConfig,
    SerialSocket,
    State,
    accept,
    connect,
    open_port,
    open_pty_pair,
)
from serialsocket.packets import PRINTABLE, Encoding

__all__ = ["DEFAULT_LENGTHS", "PORTS", "measure", "run_bench_pty"]

DEFAULT_LENGTHS = (128, 4096)
_DEAD_AFTER = 60.0
"""Silence (s) before the link is declared dead: generous, so that a busy
machine starving one side for a moment costs time, not the run."""
_LIMIT = 300.0
"""Hang guard per transfer (s): 1 MB at a pathological 10 KB/s still fits."""


PORTS = ("pty", "socket", "loop", "memory")
"""What ``--port`` measures: the two sides of a raw pty pair; pyserial's
``socket://`` backend (the client's port) to a loopback TCP socket; pyserial's
``loop://``, one port that echoes itself, so only raw port I/O (no ARQ: two
endpoints cannot share one port); two endpoints with no port between them
(the ARQ's CPU time alone)."""

_HANDSHAKE_STEPS = 20
"""Exchanges allowed for the in-memory handshake (it takes two)."""


@asynccontextmanager
async def _port_pair(kind: str) -> AsyncIterator[tuple[trio.abc.Stream, trio.abc.Stream]]:
    """Two connected ports of ``kind`` ("pty" or "socket"); closed on exit."""
    if kind == "pty":
        pty_a, pty_b = open_pty_pair()
        async with pty_a, pty_b:
            yield pty_a, pty_b
        return
    listeners = await trio.open_tcp_listeners(0, host="127.0.0.1")
    host, tcp_port = listeners[0].socket.getsockname()[:2]
    async with listeners[0] as listener:
        port_a = await open_port(f"socket://{host}:{tcp_port}")
        async with port_a, await listener.accept() as port_b:
            yield port_a, port_b


async def _echo(data: bytes) -> float:
    """Seconds to write ``data`` to ``loop://`` and read it all back (raw port I/O)."""
    received = bytearray()
    with trio.fail_after(_LIMIT):
        async with await open_port("loop://") as port, trio.open_nursery() as nursery:
            t0 = time.perf_counter()

            async def writer() -> None:
                for i in range(0, len(data), 4096):
                    await port.send_all(data[i : i + 4096])

            nursery.start_soon(writer)
            while len(received) < len(data):
                received += await port.receive_some(len(data) - len(received))
            elapsed = time.perf_counter() - t0
    if bytes(received) != data:
        raise AssertionError("loop:// returned other bytes than were written")
    return elapsed


async def _transfer(data: bytes, config: EndpointConfig, kind: str = "pty") -> float:
    """Seconds to move ``data`` from one socket to the other over a ``kind`` port pair."""
    received = bytearray()
    with trio.fail_after(_LIMIT):
        async with _port_pair(kind) as (port_a, port_b), trio.open_nursery() as nursery:
            accepted: list[SerialSocket] = []

            async def do_accept() -> None:
                accepted.append(await accept(port_b, config, nursery=nursery))

            async with trio.open_nursery() as handshake:
                handshake.start_soon(do_accept)
                client = await connect(port_a, config, nursery=nursery)
            server = accepted[0]

            async def reader() -> None:
                while chunk := await server.receive_some():
                    received.extend(chunk)

            t0 = time.perf_counter()
            async with trio.open_nursery() as transfer:
                transfer.start_soon(reader)
                await client.send_all(data)
                await client.send_eof()
            elapsed = time.perf_counter() - t0
            async with trio.open_nursery() as closing:
                closing.start_soon(client.aclose)
                closing.start_soon(server.aclose)
            nursery.cancel_scope.cancel()
    if bytes(received) != data:
        raise AssertionError(f"SerialSocket corrupted data on a clean {kind} line")
    return elapsed


def _in_memory(data: bytes, config: EndpointConfig) -> float:
    """Process CPU seconds to move ``data`` from one endpoint to another, each
    one's output handed to the other at once (no port, no trio): the client
    sends, the server reads everything, both run their timers."""
    clock = time.perf_counter
    client, server = Endpoint(config), Endpoint(config)
    server.listen()
    client.connect(clock())
    for _ in range(_HANDSHAKE_STEPS):
        if wire := client.data_to_send(clock()):
            server.receive_data(wire, clock())
        if any(isinstance(ev, ConnectionRequested) for ev in server.events()):
            server.accept(clock())
        if wire := server.data_to_send(clock()):
            client.receive_data(wire, clock())
        client.events()
        if client.state is State.ESTABLISHED and server.state is State.ESTABLISHED:
            break
    else:
        raise AssertionError("the in-memory handshake did not complete")
    view = memoryview(data)
    received = bytearray()
    at = 0
    t0 = time.process_time()
    while len(received) < len(data):
        now = clock()
        if at < len(data):
            at += client.send(view[at:], now)
        if wire := client.data_to_send(now):
            server.receive_data(wire, clock())
        if wire := server.data_to_send(clock()):
            client.receive_data(wire, clock())
        received += server.read(None, clock())
        now = clock()
        for ep in (client, server):
            deadline = ep.get_timer()
            if deadline is not None and deadline <= now:
                ep.handle_timer(now)
    elapsed = time.process_time() - t0
    if bytes(received) != data:
        raise AssertionError("the endpoints corrupted data in memory")
    return elapsed


def measure(
    size: int,
    runs: int,
    max_len: int,
    window: int,
    port: str = "pty",
    encoding: Encoding = PRINTABLE,
) -> dict[str, object]:
    """Median goodput of ``runs`` transfers of ``size`` bytes with ``max_len``
    packets over ``port`` (one of :data:`PORTS`; ``loop`` is raw port I/O),
    both sockets configured with ``encoding`` (the printable profile by default;
    ``EIGHT_BIT_CLEAN`` for what an 8-bit pty allows)."""
    data = os.urandom(size)
    config = EndpointConfig(
        max_packet_length=max_len, window=window, dead_after=_DEAD_AFTER, encoding=encoding
    )
    if port == "loop":
        times = [trio.run(_echo, data) for _ in range(runs)]
    elif port == "memory":
        times = [_in_memory(data, config) for _ in range(runs)]
    else:
        times = [trio.run(_transfer, data, config, port) for _ in range(runs)]
    median = statistics.median(times)
    return {
        "port": port,
        "arq": port != "loop",
        "clock": "process" if port == "memory" else "wall",
        "encoding": "printable" if encoding.printable else "8bit",
        "max_packet_length": max_len,
        "window": window,
        "bytes": size,
        "runs": runs,
        "seconds": [round(t, 4) for t in times],
        "median_seconds": round(median, 4),
        "MBps": round(size / median / 1e6, 3),
    }


def run_bench_pty(
    *,
    size: int = 1 << 20,
    runs: int = 5,
    lengths: Sequence[int] = DEFAULT_LENGTHS,
    window: int = 16,
    profile: str | None = None,
    ports: Sequence[str] = ("pty",),
    encoding: Encoding = PRINTABLE,
) -> dict[str, object]:
    """Run the benchmark for each port kind and packet length; returns the JSON record.

    ``encoding`` is the prefix profile of both sockets (``EIGHT_BIT_CLEAN``:
    no 8th-bit prefixing, 1.27 instead of 1.78 wire characters per random byte).
    """
    results = []
    for port in ports:
        if port not in PORTS:
            raise ValueError(f"port must be one of {', '.join(PORTS)}, got {port!r}")
        # loop:// moves raw bytes: the packet length does not apply, one row.
        for n in lengths[:1] if port == "loop" else lengths:
            results.append(measure(size, runs, n, window, port, encoding))
    if profile is not None:
        prof = cProfile.Profile()
        data = os.urandom(size)
        for n in lengths:
            cfg = EndpointConfig(
                max_packet_length=n, window=window, dead_after=_DEAD_AFTER, encoding=encoding
            )
            prof.runcall(trio.run, _transfer, data, cfg, "pty")
        prof.dump_stats(profile)
    return {"benchmark": "pty", "cpus": os.cpu_count(), "results": results}
