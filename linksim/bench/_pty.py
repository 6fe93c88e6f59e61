"""``linksim bench pty``: SerialSocket goodput over a raw pty pair, no impairments.

Two serial sockets talk over the master and slave side of one pty
(``serialsocket.open_pty_pair``), in one process and one trio run on the wall
clock.  Each run connects, sends ``--size`` bytes of random binary one way,
reads them all on the other side (checked byte for byte), and closes.  The
time is from the first ``send_all`` to the last byte read; the report gives
the median of ``--runs`` runs for each packet length (MB/s = 10^6 bytes per
second of application data).  This is a benchmark, not a test.

``--profile FILE`` runs one extra transfer per packet length under cProfile
and writes the statistics (``python -m pstats FILE``).
"""

from __future__ import annotations

import cProfile
import os
import statistics
import time
from collections.abc import Sequence

import trio

from serialsocket import EndpointConfig, SerialSocket, accept, connect, open_pty_pair

__all__ = ["DEFAULT_LENGTHS", "measure", "run_bench_pty"]

DEFAULT_LENGTHS = (128, 4096)
_DEAD_AFTER = 60.0
"""Silence (s) before the link is declared dead: generous, so that a busy
machine starving one side for a moment costs time, not the run."""
_LIMIT = 300.0
"""Hang guard per transfer (s): 1 MB at a pathological 10 KB/s still fits."""


async def _transfer(data: bytes, config: EndpointConfig) -> float:
    """Seconds to move ``data`` from one socket to the other over a pty pair."""
    port_a, port_b = open_pty_pair()
    received = bytearray()
    with trio.fail_after(_LIMIT):
        async with trio.open_nursery() as nursery:
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
        raise AssertionError("SerialSocket corrupted data on a clean pty")
    return elapsed


def measure(size: int, runs: int, max_len: int, window: int) -> dict[str, object]:
    """Median goodput of ``runs`` transfers of ``size`` bytes with ``max_len`` packets."""
    data = os.urandom(size)
    config = EndpointConfig(max_packet_length=max_len, window=window, dead_after=_DEAD_AFTER)
    times = [trio.run(_transfer, data, config) for _ in range(runs)]
    median = statistics.median(times)
    return {
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
) -> dict[str, object]:
    """Run the benchmark for each packet length; returns the JSON record."""
    results = [measure(size, runs, n, window) for n in lengths]
    if profile is not None:
        prof = cProfile.Profile()
        data = os.urandom(size)
        for n in lengths:
            cfg = EndpointConfig(max_packet_length=n, window=window, dead_after=_DEAD_AFTER)
            prof.runcall(trio.run, _transfer, data, cfg)
        prof.dump_stats(profile)
    return {"benchmark": "pty", "cpus": os.cpu_count(), "results": results}
