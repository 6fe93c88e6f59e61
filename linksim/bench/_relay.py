"""``linksim bench relay``: how fast the pty relay moves bytes on a clean link.

Starts ``linksim relay --json`` in a subprocess (so the relay runs exactly as
users run it), writes ``--size`` MB into side a's pty from one thread and
reads them from side b's pty in another, and reports MB/s (10^6 bytes per
second) from the first write to the last byte read, best of ``--repeat``.
The data is checked byte for byte.  This is a benchmark, not a test.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time

__all__ = ["measure"]

_CHUNK = 65536


def _transfer(path_a: str, path_b: str, data: bytes) -> float:
    """Seconds to push ``data`` from ``path_a`` to ``path_b`` (verified)."""
    fa = os.open(path_a, os.O_RDWR | os.O_NOCTTY)
    fb = os.open(path_b, os.O_RDWR | os.O_NOCTTY)
    received = bytearray()
    errors: list[BaseException] = []

    def reader() -> None:
        try:
            while len(received) < len(data):
                chunk = os.read(fb, _CHUNK)
                if not chunk:
                    raise EOFError("relay closed the tty")
                received.extend(chunk)
        except BaseException as exc:  # reported by the main thread
            errors.append(exc)

    try:
        t = threading.Thread(target=reader, daemon=True)
        t0 = time.perf_counter()
        t.start()
        view = memoryview(data)
        while view:
            view = view[os.write(fa, view[:_CHUNK]) :]
        t.join(timeout=120)
        elapsed = time.perf_counter() - t0
        if t.is_alive():
            raise TimeoutError("relay benchmark stalled")
        if errors:
            raise errors[0]
        if bytes(received) != data:
            raise AssertionError("relay corrupted data on a clean link")
        return elapsed
    finally:
        os.close(fa)
        os.close(fb)


def measure(size: int, repeat: int) -> dict[str, object]:
    """Run the benchmark; returns the JSON record."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "linksim", "relay", "--json"],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        paths = json.loads(proc.stdout.readline())
        data = os.urandom(size)
        best = min(_transfer(paths["a"], paths["b"], data) for _ in range(repeat))
    finally:
        proc.send_signal(signal.SIGTERM)
        status = proc.wait(timeout=30)
    return {
        "benchmark": "relay",
        "bytes": size,
        "seconds": round(best, 4),
        "MBps": round(size / best / 1e6, 2),
        "relay_exit_status": status,
    }
