"""``linksim bench pty``: SerialSocket goodput over a raw pty pair, no impairments
(``--port socket``: over pyserial's ``socket://``; ``--port loop``: raw ``loop://`` I/O;
``--port memory``: the two endpoints alone, no port).

Two serial sockets talk over the master and slave side of one pty
(``serialsocket.open_pty_pair``) on the wall clock.  The receiving end runs in
a process of its own, as the other end of a line always does (``--one-process``:
both ends in one trio run, so on one core, which measures what the two
together cost).  Each run connects, sends ``--size`` bytes of random binary
one way, reads them all on the other side (checked by SHA-256), and closes.
The time is from the first ``send_all`` to the last byte read (both ends read
``CLOCK_MONOTONIC``, which is one clock for every process); the report gives
the median of ``--runs`` runs for each packet length (MB/s = 10^6 bytes per
second of application data).  This is a benchmark, not a test.

Both ends are configured as the netcat configures them (``serialsocket
listen/connect``): the library's window (31, long sequence numbers), a dense
encoding offered, the sums offered (they go on only after a loss, so never
here), the profile from the line (``--profile auto``: a pty and ``socket://``
are 8N1, so 8-bit clean).

``--port memory`` hands each endpoint's output straight to the other
(sans-I/O, no trio, no port) and times the transfer in process CPU time:
what the ARQ and the codec cost, both sides together, apart from the I/O
and the machine's other load.

``--cprofile FILE`` runs one extra one-process transfer per packet length
under cProfile and writes the statistics (``python -m pstats FILE``).
"""

from __future__ import annotations

import cProfile
import hashlib
import multiprocessing
import os
import signal
import statistics
import time
from collections.abc import AsyncIterator, Sequence
from contextlib import AsyncExitStack, asynccontextmanager
from multiprocessing import resource_tracker
from multiprocessing.connection import Connection

import trio

from serialsocket import (
    MAX_WINDOW,
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
from serialsocket.packets import EIGHT_BIT_CLEAN, Encoding

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

_CHILD_GRACE = 10.0
"""Seconds the receiving process has to report and exit after the transfer."""

_SPAWN = multiprocessing.get_context("spawn")
"""The receiving process starts fresh: a fork would copy trio's state."""

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


def _clock() -> float:
    """``CLOCK_MONOTONIC``: one clock for every process of the machine, so the
    sender's start and the receiving process's last byte can be subtracted."""
    return time.clock_gettime(time.CLOCK_MONOTONIC)


async def _receive_all(port_name: str, config: EndpointConfig) -> tuple[int, str, float]:
    """Open ``port_name``, accept one connection and read until the sender's
    EOF; returns (bytes, their SHA-256, clock at the last byte)."""
    digest = hashlib.sha256()
    count = 0
    last = _clock()
    with trio.fail_after(_LIMIT):
        async with await open_port(port_name) as port, trio.open_nursery() as nursery:
            server = await accept(port, config, nursery=nursery)
            while chunk := await server.receive_some():
                digest.update(chunk)
                count += len(chunk)
                last = _clock()
            await server.aclose()
            nursery.cancel_scope.cancel()
    return count, digest.hexdigest(), last


def _receiver_process(port_name: str, config: EndpointConfig, report: Connection) -> None:
    """The receiving end's process: sends ``("ok", bytes, sha256, end)`` or
    ``("error", message)`` on ``report``."""
    try:
        count, digest, end = trio.run(_receive_all, port_name, config)
    except Exception as exc:  # the parent raises it, in the receiver's words
        report.send(("error", f"{type(exc).__name__}: {exc}"))
    else:
        report.send(("ok", count, digest, end))
    finally:
        report.close()


@asynccontextmanager
async def _with_receiver(
    kind: str, config: EndpointConfig, report: Connection
) -> AsyncIterator[trio.abc.Stream]:
    """Start :func:`_receiver_process` on the far end of a ``kind`` pair
    ("pty" or "socket") and yield this process's end; on exit, wait for the
    process (at most ``_CHILD_GRACE`` s, then kill it)."""
    async with AsyncExitStack() as stack:
        listener: trio.SocketListener | None = None
        near: trio.abc.Stream
        if kind == "pty":
            # The slave stays open here, never read, while the far end opens
            # it by name: a master whose slave nobody holds reads EIO.
            near, far = open_pty_pair()
            await stack.enter_async_context(near)
            await stack.enter_async_context(far)
            far_name = far.name
        else:
            listener = (await trio.open_tcp_listeners(0, host="127.0.0.1"))[0]
            await stack.enter_async_context(listener)
            host, tcp_port = listener.socket.getsockname()[:2]
            far_name = f"socket://{host}:{tcp_port}"
        process = _SPAWN.Process(
            target=_receiver_process, args=(far_name, config, report), daemon=True
        )
        # Started with Ctrl-C blocked, which it inherits and keeps: the
        # terminal sends it to the whole process group, and an interrupted
        # run is this process's to report (the child, killed below, would
        # print a traceback from wherever it was, its imports included).
        # Blocked here, not ignored: one that comes meanwhile waits, then
        # interrupts us.
        # (multiprocessing's resource tracker, started by the first start,
        # unblocks the signals it blocks around its own start: start it first.)
        resource_tracker.ensure_running()
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            process.start()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        report.close()  # the child's copy is the only writer: its death reads as EOF
        done = False
        try:
            if listener is not None:
                # (Bounded by the caller's _LIMIT, should the child never connect.)
                near = await stack.enter_async_context(await listener.accept())
            yield near
            done = True
        finally:
            if done:
                with trio.CancelScope(shield=True):
                    await trio.to_thread.run_sync(process.join, _CHILD_GRACE)
            if process.is_alive():
                process.kill()
                process.join()


def _read_report(reports: Connection) -> tuple[int, str, float]:
    """The receiving process's report: (bytes, SHA-256, clock at the last byte)."""
    try:
        report = reports.recv() if reports.poll(_CHILD_GRACE) else None
    except EOFError:
        report = None
    if report is None:
        raise AssertionError("the receiving process ended without a report")
    if report[0] != "ok":
        raise AssertionError(f"the receiving process failed: {report[1]}")
    return report[1], report[2], report[3]


async def _transfer_to_process(data: bytes, config: EndpointConfig, kind: str) -> float:
    """Seconds to move ``data`` to a serial socket in another process over a
    ``kind`` pair, from the first ``send_all`` to the last byte read there."""
    reports, report_end = _SPAWN.Pipe(duplex=False)
    with reports:
        with trio.fail_after(_LIMIT):
            async with (
                _with_receiver(kind, config, report_end) as port,
                trio.open_nursery() as nursery,
            ):
                client = await connect(port, config, nursery=nursery)
                t0 = _clock()
                await client.send_all(data)
                await client.send_eof()
                await client.aclose()
                nursery.cancel_scope.cancel()
        count, digest, end = _read_report(reports)
    if count != len(data) or digest != hashlib.sha256(data).hexdigest():
        raise AssertionError(
            f"SerialSocket delivered {count} bytes of other content than the {len(data)} sent"
            f" on a clean {kind} line"
        )
    return end - t0


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


def bench_config(
    max_len: int, window: int = MAX_WINDOW, encoding: Encoding | None = None, dense: bool = True
) -> EndpointConfig:
    """Both ends' configuration: the netcat's (dense, sums, the library's
    window), at ``max_len`` and ``window``; ``encoding`` None is the
    profile an 8N1 port chooses, a pty's or ``socket://``'s (8-bit clean)."""
    return EndpointConfig(
        max_packet_length=max_len,
        window=window,
        dead_after=_DEAD_AFTER,
        encoding=EIGHT_BIT_CLEAN if encoding is None else encoding,
        dense=dense,
        correction=True,
    )


def measure(
    size: int,
    runs: int,
    max_len: int,
    window: int = MAX_WINDOW,
    port: str = "pty",
    encoding: Encoding | None = None,
    *,
    dense: bool = True,
    one_process: bool = False,
) -> dict[str, object]:
    """Median goodput of ``runs`` transfers of ``size`` bytes with ``max_len``
    packets over ``port`` (one of :data:`PORTS`; ``loop`` is raw port I/O),
    both ends configured by :func:`bench_config`.  Over ``pty`` and
    ``socket`` the receiving end runs in a process of its own unless
    ``one_process``."""
    data = os.urandom(size)
    config = bench_config(max_len, window, encoding, dense)
    processes = 1
    if port == "loop":
        times = [trio.run(_echo, data) for _ in range(runs)]
    elif port == "memory":
        times = [_in_memory(data, config) for _ in range(runs)]
    elif one_process:
        times = [trio.run(_transfer, data, config, port) for _ in range(runs)]
    else:
        processes = 2
        times = [trio.run(_transfer_to_process, data, config, port) for _ in range(runs)]
    median = statistics.median(times)
    return {
        "port": port,
        "arq": port != "loop",
        "processes": processes,
        "clock": "process" if port == "memory" else "wall",
        "encoding": "printable" if config.line_encoding().printable else "8bit",
        "dense": dense,
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
    window: int = MAX_WINDOW,
    cprofile: str | None = None,
    ports: Sequence[str] = ("pty",),
    encoding: Encoding | None = None,
    dense: bool = True,
    one_process: bool = False,
) -> dict[str, object]:
    """Run the benchmark for each port kind and packet length; returns the JSON record.

    ``encoding`` is the prefix profile of both ends (None: the line's, 8-bit
    clean); ``dense`` offers the dense encodings (1.01 wire characters per
    random byte on an 8-bit line, 1.23 on a printable one; without them 1.27
    and 1.78).  ``cprofile`` names a file for the statistics of one more
    one-process transfer per length under cProfile.
    """
    results = []
    for port in ports:
        if port not in PORTS:
            raise ValueError(f"port must be one of {', '.join(PORTS)}, got {port!r}")
        # loop:// moves raw bytes: the packet length does not apply, one row.
        for n in lengths[:1] if port == "loop" else lengths:
            results.append(
                measure(size, runs, n, window, port, encoding, dense=dense, one_process=one_process)
            )
    if cprofile is not None:
        prof = cProfile.Profile()
        data = os.urandom(size)
        for n in lengths:
            prof.runcall(trio.run, _transfer, data, bench_config(n, window, encoding, dense), "pty")
        prof.dump_stats(cprofile)
    return {"benchmark": "pty", "cpus": os.cpu_count(), "results": results}
