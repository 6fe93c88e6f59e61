"""``linksim bench flood``: what a flooding controller costs the arm's server (wall clock, Linux).

A ``linksim arm-server`` runs in its own process on loopback TCP.  One
authenticated controller writes STATUS commands as fast as the host lets it
(reading the replies at the same time, as any client must) for ``--seconds``;
the server's CPU time is read from ``/proc/<pid>/stat`` before and after.
Each ``--limit`` (packets a second per connection; 0 = no limit) is one run.

It measures the server's ``max_packet_rate``: with the limit, the answers a
second settle at the limit and the server's CPU share with them; without it,
the server works as fast as the flooder can feed it.  ``max_connections``
flooders cost at most that many times one.  Speed is reported, not asserted.
"""

from __future__ import annotations

import json
import os
import pathlib
import secrets
import subprocess
import sys
import tempfile
import time
from typing import Any

import trio

from tcpstream import commands
from tcpstream.connection import ClientConnection, Completed, ControllerIdentity, SessionState

__all__ = ["run"]

_BATCH = 64
"""STATUS commands per write."""
_AHEAD = 2000
"""Commands written but not yet answered before the flooder pauses 1 ms: the
flood stays a flood without the client's own memory growing without bound."""


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` (Linux ``/proc``)."""
    stat = pathlib.Path(f"/proc/{pid}/stat").read_text()
    fields = stat.rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


async def _flood(port: int, key: bytes, seconds: float) -> tuple[int, int]:
    """Flood for ``seconds``; (commands written, commands answered)."""
    stream = await trio.open_tcp_stream("127.0.0.1", port)
    async with stream:
        conn = ClientConnection(ControllerIdentity("flood", 1), key=key, now=trio.current_time())
        conn.connect(trio.current_time())
        with trio.fail_after(30):
            while conn.state is not SessionState.OPEN:
                await stream.send_all(conn.data_to_send())
                data = await stream.receive_some()
                if not data:
                    raise RuntimeError("the arm-server closed the connection during the handshake")
                conn.receive_data(bytes(data), trio.current_time())
                while conn.next_event() is not None:
                    pass
        written = answered = 0

        async def reader() -> None:
            nonlocal answered
            while data := await stream.receive_some():
                conn.receive_data(bytes(data), trio.current_time())
                while (event := conn.next_event()) is not None:
                    answered += isinstance(event, Completed)

        async with trio.open_nursery() as nursery:
            nursery.start_soon(reader)
            end = trio.current_time() + seconds
            while trio.current_time() < end:
                for _ in range(_BATCH):
                    written += 1
                    conn.send_command(written, commands.status(), trio.current_time())
                with trio.move_on_at(end):
                    await stream.send_all(conn.data_to_send())
                if written - answered > _AHEAD:
                    await trio.sleep(0.001)
            nursery.cancel_scope.cancel()
    return written, answered


def run(limit: float, seconds: float = 8.0) -> dict[str, Any]:
    """One run against a fresh arm-server with ``--max-packet-rate limit``; the report."""
    if not pathlib.Path("/proc/self/stat").exists():
        raise RuntimeError("bench flood reads the server's CPU time from /proc (Linux only)")
    key = secrets.token_bytes(32)
    with tempfile.TemporaryDirectory() as tmp:
        key_file = pathlib.Path(tmp) / "arm.key"
        key_file.write_text(key.hex())
        key_file.chmod(0o600)
        server = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "linksim",
                "arm-server",
                "--transport",
                "tcp",
                "--tcp-port",
                "0",
                "--key-file",
                str(key_file),
                "--max-packet-rate",
                str(limit),
                "--sessions",
                "1",
            ],
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            assert server.stdout is not None
            ready = json.loads(server.stdout.readline())
            cpu0, t0 = _cpu_seconds(server.pid), time.monotonic()
            written, answered = trio.run(_flood, ready["tcp_port"], key, seconds)
            cpu1, t1 = _cpu_seconds(server.pid), time.monotonic()
        finally:
            server.kill()
            server.wait(timeout=30)
    wall, cpu = t1 - t0, cpu1 - cpu0
    return {
        "benchmark": "flood",
        "max_packet_rate": limit if limit > 0 else None,
        "seconds": round(wall, 2),
        "commands_written": written,
        "commands_answered": answered,
        "answered_per_s": round(answered / wall, 1),
        "server_cpu_s": round(cpu, 2),
        "server_cpu_share": round(cpu / wall, 3),
        "server_cpu_per_packet_us": round(1e6 * cpu / answered, 1) if answered else None,
    }
