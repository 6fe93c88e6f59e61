"""The netcat's exit status tells the truth over an impaired ``linksim relay``.

Issue 17, finding 5: through an impaired relay (115200 bit/s, 0.2 s one way,
byte corruption 1e-3, drops 1e-4, bursts) the listener exited 1 with 258 081
of 262 144 bytes while ``connect`` exited 0 with nothing on stderr; both
directions at once (64 KiB each way, no hints) the connect side aborted at
close every run.  The contract (README, RELIABILITY.md): ``listen`` and
``connect`` exit 0 exactly when every byte read from stdin was acknowledged
by the peer and every byte the peer sent was written to stdout; any other
ending exits non-zero and says how many bytes were acknowledged, in flight
and never sent.

The matrix here is the issue's lines, one direction and both at once, with
the line's hints (``--baud``/``--delay``) on both ends and without any, plus a
line that goes silent for good mid-transfer (the relay is stopped, SIGSTOP,
once the listener has 64 KiB): there both sides must exit non-zero and say
how far they got.  In every case what arrived is a prefix of what was sent
(nothing invented, nothing reordered).  Both netcats' stdout is read while
they run (a full pipe would stall the transfer).

Everything runs as a user runs it -- ``python -m linksim relay`` and
``python -m serialsocket listen|connect`` as subprocesses -- so these are
wall-clock runs: nothing asserts a duration, every wait is bounded only to
stop a hang.  The cases run at once (each has its own relay); the whole test
costs about as long as its slowest case (about 2.5 min: the 256 KiB upload
without hints), hence ``long``.
"""

from __future__ import annotations

import contextlib
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import pytest

from .test_kermit_cli import wait_until_reading

GUARD = 300.0
"""Bound on any one process: only stops a hang."""
ISSUE_LINE = ("--rate", "115200", "--delay", "0.2", "--ber", "1e-3", "--loss", "1e-4")
ISSUE_BURSTS = ("--burst", "1e-5:0.02")
"""About one burst per 8.7 s of line time, 50 characters long on average,
half of its bytes corrupted (Gilbert-Elliott's default in the bad state)."""
BOTH_WAYS_LINE = ("--rate", "115200", "--delay", "0.2", "--ber", "1e-4", "--loss", "1e-4")
HINTS = ("--baud", "115200", "--delay", "0.2")


@dataclass(frozen=True)
class Case:
    """One transfer: the relay's line, the bytes each way, the netcat options."""

    name: str
    line: tuple[str, ...]
    up: int  # connect -> listen
    down: int  # listen -> connect
    options: tuple[str, ...]
    silent_after: int | None = None
    """The line goes silent for good (the relay stopped) once the listener has
    written this many bytes; None: it stays up and everything must arrive."""


CASES = [
    Case("one way, hints", ISSUE_LINE + ISSUE_BURSTS, 262_144, 0, HINTS),
    Case("one way, no hints", ISSUE_LINE + ISSUE_BURSTS, 262_144, 0, ()),
    Case("both ways, hints", BOTH_WAYS_LINE, 65_536, 65_536, HINTS),
    Case("both ways, no hints", BOTH_WAYS_LINE, 65_536, 65_536, ()),
    # Silent a quarter of the way through the upload (over 20 s of line time):
    # both ends connected and mid-transfer, whatever the machine's load.
    Case(
        "both ways, the line dies",
        BOTH_WAYS_LINE,
        262_144,
        65_536,
        (*HINTS, "--dead-after", "5"),
        silent_after=65_536,
    ),
]


@dataclass
class Side:
    """One netcat's ending: exit status, what it wrote to stdout, its stderr."""

    returncode: int
    stdout: bytes
    stderr: str


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "serialsocket", *args]


def _reap(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.kill()
    proc.wait(timeout=GUARD)


def _drain(proc: subprocess.Popen[bytes], sink: bytearray, then: Callable[[], None]) -> None:
    """Read ``proc``'s stdout into ``sink`` until EOF; ``then()`` after each chunk."""
    assert proc.stdout is not None
    while chunk := os.read(proc.stdout.fileno(), 65_536):
        sink.extend(chunk)
        then()


def _run(case: Case, seed: int) -> tuple[bytes, bytes, Side, Side]:
    """The transfer; (up, down, connect's ending, listen's ending)."""
    up = random.Random(seed).randbytes(case.up)
    down = random.Random(seed + 1000).randbytes(case.down)
    relay = subprocess.Popen(
        [sys.executable, "-m", "linksim", "relay", "--json", "--seed", str(seed), *case.line],
        stdout=subprocess.PIPE,
        text=True,
    )
    got_up = bytearray()
    listen_err: list[bytes] = []
    stopped = threading.Event()

    def maybe_silence() -> None:
        due = case.silent_after is not None and len(got_up) >= case.silent_after
        if due and not stopped.is_set():
            stopped.set()
            relay.send_signal(signal.SIGSTOP)  # no byte moves either way from now

    try:
        assert relay.stdout is not None
        paths = json.loads(relay.stdout.readline())
        with tempfile.TemporaryFile() as down_in, tempfile.TemporaryFile() as up_in:
            down_in.write(down)
            down_in.seek(0)
            up_in.write(up)
            up_in.seek(0)
            listener = subprocess.Popen(
                _cli("listen", paths["b"], *case.options, "--stats"),
                stdin=down_in,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
            )
            readers: list[threading.Thread] = []
            try:
                wait_until_reading(listener, paths["b"])
                assert listener.stderr is not None
                err = listener.stderr
                readers = [
                    threading.Thread(target=_drain, args=(listener, got_up, maybe_silence)),
                    threading.Thread(target=lambda: listen_err.append(err.read())),
                ]
                for reader in readers:
                    reader.start()
                connect = subprocess.Popen(
                    _cli(
                        "connect", paths["a"], *case.options, "--stats", "--connect-timeout", "60"
                    ),
                    stdin=up_in,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.PIPE,
                )
                try:
                    got_down, connect_err = connect.communicate(timeout=GUARD)
                except subprocess.TimeoutExpired:  # a hang: reported with the rest
                    connect.kill()
                    got_down, connect_err = connect.communicate()
                    connect_err += b"\n(killed: still running after the guard)"
                with contextlib.suppress(subprocess.TimeoutExpired):
                    listener.wait(timeout=GUARD)
            finally:
                _reap(listener)
                for reader in readers:
                    reader.join(timeout=GUARD)
    finally:
        if stopped.is_set():
            relay.send_signal(signal.SIGCONT)
        relay.send_signal(signal.SIGTERM)
        relay.wait(timeout=GUARD)
    return (
        up,
        down,
        Side(connect.returncode, got_down, connect_err.decode(errors="replace")),
        Side(listener.returncode, bytes(got_up), b"".join(listen_err).decode(errors="replace")),
    )


@pytest.mark.long
def test_exit_status_is_0_exactly_when_every_byte_was_delivered() -> None:
    with ThreadPoolExecutor(max_workers=len(CASES)) as pool:
        futures = [pool.submit(_run, case, 17 + i) for i, case in enumerate(CASES)]
        runs = [f.result() for f in futures]
    summary = "\n".join(
        f"{case.name}: connect exit {conn.returncode} with {len(conn.stdout)} of {len(down)}, "
        f"listen exit {lis.returncode} with {len(lis.stdout)} of {len(up)}"
        for case, (up, down, conn, lis) in zip(CASES, runs, strict=True)
    )
    print("\n" + summary)
    for case, (up, down, conn, lis) in zip(CASES, runs, strict=True):
        for side, received, sent in ((conn, down, up), (lis, up, down)):
            assert "Traceback" not in side.stderr, (case.name, side.stderr[-1500:])
            # What arrived is a prefix of what was sent: never invented or reordered.
            assert received.startswith(side.stdout), (case.name, summary)
            if side.returncode == 0:
                # Exit 0: every byte the peer sent is on our stdout, and every
                # byte we read was acknowledged -- so the peer has it all too.
                assert side.stdout == received, (case.name, summary)
                peer = lis if side is conn else conn
                assert peer.stdout == sent, (case.name, summary)
            else:
                assert side.returncode == 1, (case.name, side.stderr[-1500:])
                # Not delivered: it says how far each direction got.
                assert "acknowledged by the peer" in side.stderr, (case.name, side.stderr[-1500:])
                assert "in flight" in side.stderr, (case.name, side.stderr[-1500:])
                assert "never sent" in side.stderr, (case.name, side.stderr[-1500:])
        if case.silent_after is None:
            assert (conn.returncode, lis.returncode) == (0, 0), (
                case.name,
                summary,
                conn.stderr[-1500:],
                lis.stderr[-1500:],
            )
        else:
            # The line died mid-transfer: neither side may claim delivery.
            assert conn.returncode != 0, (case.name, summary)
            assert lis.returncode != 0, (case.name, summary)
            assert len(lis.stdout) < len(up), (case.name, summary)
