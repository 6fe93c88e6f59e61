"""Issue 21's real-time table: the serialsocket netcat through ``linksim relay``.

For each line (bit/s, one-way delay, byte corruption) a relay runs as a
subprocess and ``python -m serialsocket listen`` / ``connect`` move a file of
random binary (8 KiB at 2400 bit/s, 32 KiB at 9600) from connect to listen,
as a user runs them: the netcat's defaults (``--profile auto``: the pty is
8N1, so the 8-bit profile; the dense encodings offered), with or without the
line's hints.  The figure is the issue's: file bytes over the wall time from
starting the sender to both exits, as a share of the line (bit/s / 10 bytes
a second).  Rows run at once (each waits on its own line almost all the time).

    .venv/bin/python bench/results/netcat-table.py [--seeds 1 2 3] [--hints] [--json]

Wall-clock: the figures depend on the machine and its load.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROWS = [
    # (bit/s, one-way s, byte corruption, profile, issue target)
    (2400, 0.0, 0.0, "auto", 0.93),
    (2400, 1.3, 0.0, "auto", 0.85),
    (2400, 1.3, 1e-4, "auto", 0.80),
    (2400, 1.3, 1e-3, "auto", 0.65),
    (9600, 1.3, 1e-3, "auto", 0.60),
    (2400, 1.3, 1e-4, "printable", 0.70),
]
GUARD = 900.0


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "serialsocket", *args]


def _wait_until_open(proc: subprocess.Popen[bytes], path: str) -> None:
    """Return once ``proc`` has the tty ``path`` open (Linux's /proc), so the
    clock starts with a listener that is there; bounded by GUARD."""
    target = os.path.realpath(path)
    deadline = time.monotonic() + GUARD
    fds = Path(f"/proc/{proc.pid}/fd")
    while time.monotonic() < deadline and proc.poll() is None:
        with contextlib.suppress(OSError):
            if any(os.path.realpath(fd) == target for fd in fds.iterdir()):
                return
        time.sleep(0.01)
    raise RuntimeError(f"{proc.args!r} did not open {path}")


def run_row(rate: int, delay: float, ber: float, profile: str, seed: int, hints: bool) -> dict:
    size = 8192 if rate == 2400 else 32768
    data = random.Random(seed).randbytes(size)
    relay = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "linksim",
            "relay",
            "--json",
            "--seed",
            str(seed),
            "--rate",
            str(rate),
            "--delay",
            str(delay),
            "--ber",
            str(ber),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    options = [] if profile == "auto" else ["--profile", profile]  # auto: the default
    if hints:
        options += ["--baud", str(rate), "--delay", str(delay)]
    row = {
        "rate": rate,
        "delay": delay,
        "ber": ber,
        "profile": profile,
        "seed": seed,
        "hints": hints,
        "bytes": size,
    }
    try:
        assert relay.stdout is not None
        paths = json.loads(relay.stdout.readline())
        with tempfile.TemporaryDirectory() as tmp:
            src, out = Path(tmp) / "src", Path(tmp) / "out"
            src.write_bytes(data)
            with (
                open(out, "wb") as sink,
                open(src, "rb") as source,
                open(Path(tmp) / "empty", "wb+") as empty,
            ):
                listener = subprocess.Popen(
                    _cli("listen", paths["b"], *options),
                    stdin=empty,
                    stdout=sink,
                    stderr=subprocess.PIPE,
                )
                _wait_until_open(listener, paths["b"])
                start = time.monotonic()
                connect = subprocess.Popen(
                    _cli("connect", paths["a"], *options, "--stats", "--json"),
                    stdin=source,
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.PIPE,
                )
                _, cerr = connect.communicate(timeout=GUARD)
                _, lerr = listener.communicate(timeout=GUARD)
                seconds = time.monotonic() - start
            got = out.read_bytes()
        ok = got == data and connect.returncode == 0 and listener.returncode == 0
        row.update(
            ok=ok,
            seconds=round(seconds, 1),
            line_share=round(size / seconds / (rate / 10), 3),
            connect_exit=connect.returncode,
            listen_exit=listener.returncode,
        )
        if not ok:
            row["connect_stderr"] = cerr.decode(errors="replace")[-1500:]
            row["listen_stderr"] = lerr.decode(errors="replace")[-600:]
    finally:
        relay.terminate()
        relay.wait(timeout=30)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--hints", action="store_true", help="give both ends --baud and --delay")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    jobs = [(r, d, b, p, s, args.hints) for (r, d, b, p, _t) in ROWS for s in args.seeds]
    with ThreadPoolExecutor(len(jobs)) as pool:
        rows = list(pool.map(lambda j: run_row(*j), jobs))
    targets = {(r, d, b, p): t for (r, d, b, p, t) in ROWS}
    for row in rows:
        row["target"] = targets[(row["rate"], row["delay"], row["ber"], row["profile"])]
        if args.json:
            print(json.dumps(row))
        else:
            result = (
                f"{row['line_share']:.3f} ({row['seconds']} s)" if row["ok"] else f"FAILED {row}"
            )
            print(
                f"{row['rate']:>5} {row['delay']:>4} {row['ber']:>7} {row['profile']:>9} "
                f"seed {row['seed']}  {result}  target {row['target']}"
            )


if __name__ == "__main__":
    main()
