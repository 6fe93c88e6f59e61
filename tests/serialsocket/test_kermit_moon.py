"""Exit status against C-Kermit on a moon line: 0 if and only if the file arrived whole.

Issue 17, finding 9: ``serialsocket kermit send`` to C-Kermit through
``linksim relay`` at 1.3 s one way and a byte error rate of 1e-3 exited 0
while C-Kermit held 3875 of 8192 (2400 bit/s) and 32 389 of 32 768 bytes
(9600 bit/s, window 16): it took C-Kermit's NAK of the packet after the last
one sent as an ACK of everything outstanding.

Here both directions (our sender to C-Kermit's receiver, C-Kermit's sender
to our receiver) run as a user runs them -- ``python -m serialsocket kermit``,
``kermit`` and ``python -m linksim relay`` as subprocesses -- at 2400 and
9600 bit/s, windows 8 and 16, and our exit status is checked against the
file that arrived: 0 exactly when it is byte for byte the file sent.  Giving
up is allowed (the retry limit on a bad line), but then the exit status is 1
and the message says how far the transfer got.

The eight transfers run at once (each has its own relay), so the whole
matrix costs about as long as its slowest transfer.  They are wall-clock
runs: nothing here asserts a duration, and every wait is bounded only to
stop a hang.  The files are small (a few packets at 2400 bit/s) so that each
transfer stays well under a minute even with a few timeouts.
"""

from __future__ import annotations

import contextlib
import os
import pathlib
import random
import shutil
import subprocess
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import pytest

from .test_kermit_cli import GUARD, Outcome, _outcome, _stop, cli, relay, wait_until_reading

DELAY = 1.3
"""One way, s: the Earth-Moon path."""
BYTE_ERROR_RATE = 1e-3
TIMEOUT = 10
"""Both sides' fixed timeout, s: above the round trip (2.6 s) plus the line
time of a window's worth of packets still queued at 2400 bit/s."""
RETRIES = 20
PACKET_LENGTH = 250
"""At 1e-3 a 250-character packet arrives damaged about one time in five."""
SIZES = {2400: 1_000, 9600: 3_000}
"""File bytes per line rate: 4 and 12 data packets."""
RECEIVER_RETRIES = 6
"""Our receiver's limit on timeouts in a row with nothing new: a minute of
silence once C-Kermit has gone (its E may arrive damaged) instead of 200 s."""
GRACE = 3.0
"""Seconds C-Kermit gets to exit once our side has."""
LIMIT = 180.0
"""Bound on our side's run: only stops a hang."""
OPTIONS = {
    window: [
        "--window",
        str(window),
        "--packet-length",
        str(PACKET_LENGTH),
        "--timeout",
        str(TIMEOUT),
        "--stats",
        "--literal-names",  # C-Kermit is told "set file names literal" too
    ]
    for window in (8, 16)
}


@dataclass(frozen=True)
class Case:
    """One transfer of the matrix."""

    sender: str  # "ours" or "ckermit"
    rate: int
    window: int

    @property
    def name(self) -> str:
        receiver = "ckermit" if self.sender == "ours" else "ours"
        return f"{self.sender}->{receiver} {self.rate} bit/s window {self.window}"


CASES = [
    Case(sender, rate, window)
    for sender in ("ours", "ckermit")
    for rate in (2400, 9600)
    for window in (8, 16)
]


@dataclass
class Run:
    """What one transfer did: our side's outcome, C-Kermit's status and output,
    and what arrived."""

    case: Case
    ours: Outcome
    ckermit_status: int | None
    ckermit_output: str
    sent: bytes
    received: bytes | None


def _ckermit_ready(proc: subprocess.Popen[bytes], path: str) -> None:
    """Wait until C-Kermit has ``path`` open, then a moment for its tty setup.

    C-Kermit waits in select(), not epoll, so test_kermit_cli's /proc check
    does not see it.  An S packet that arrives too early only costs our
    sender one timeout, never a wrong result.
    """
    deadline = time.monotonic() + GUARD
    fd_dir = pathlib.Path(f"/proc/{proc.pid}/fd")
    while True:
        with contextlib.suppress(OSError):
            if any(os.readlink(fd) == path for fd in fd_dir.iterdir()):
                break
        if proc.poll() is not None or time.monotonic() > deadline:
            pytest.fail(f"C-Kermit did not open {path} (status {proc.poll()})")
        time.sleep(0.02)
    time.sleep(1.0)


def _ckermit_argv(case: Case, line: str, path: pathlib.Path | None) -> list[str]:
    """C-Kermit, non-interactive: the same window, packet length and timeout as
    ours, no streaming, binary; SEND ``path`` or RECEIVE; exit with its status."""
    commands = [
        f"set line {line}",
        "set carrier-watch off",
        "set flow none",
        "set parity none",
        "set streaming off",
        "set file type binary",
        "set transfer mode manual",
        "set file names literal",
        "set file collision overwrite",
        f"set window {case.window}",
        f"set receive packet-length {PACKET_LENGTH}",
        "set block-check 3",
        f"set send timeout {TIMEOUT} fixed",
        f"set receive timeout {TIMEOUT}",
        f"set retry-limit {RETRIES}",
        f"send {path}" if path else "receive",
        "exit \\v(status)",
    ]
    return ["kermit", "-Y", "-q", "-B", "-C", ", ".join(commands)]


def _finish(proc: subprocess.Popen[bytes]) -> tuple[int | None, str]:
    """C-Kermit's status and output, after a short grace; None if it had to be killed.

    Once our side has exited, C-Kermit may wait out its retry limit (20 x 10 s)
    for an answer that cannot come: the ACK of B it missed, or our E that
    arrived damaged.  Its status is only reported, never asserted.
    """
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=GRACE)
    status = proc.poll()
    _stop(proc)
    assert proc.stdout is not None
    return status, proc.stdout.read().decode("utf-8", "replace")


def _run(case: Case, tmp: pathlib.Path, seed: int) -> Run:
    src = tmp / "src"
    out = tmp / "out"
    src.mkdir(parents=True)
    out.mkdir()
    data = random.Random(seed).randbytes(SIZES[case.rate])
    path = src / "moon.bin"
    path.write_bytes(data)
    ours_send = case.sender == "ours"
    line_options = ["--rate", str(case.rate), "--delay", str(DELAY)]
    line_options += ["--ber", str(BYTE_ERROR_RATE), "--seed", str(seed)]
    ours_argv = (
        cli("send", str(path), "--retries", str(RETRIES), *OPTIONS[case.window])
        if ours_send
        else cli("receive", str(out), "--retries", str(RECEIVER_RETRIES), *OPTIONS[case.window])
    )
    with relay(*line_options) as line:
        ours_line, their_line = (line.a, line.b) if ours_send else (line.b, line.a)
        ours_argv += ["--port", ours_line]
        ck_argv = _ckermit_argv(case, their_line, None if ours_send else path)
        ckermit: subprocess.Popen[bytes] | None = None
        ours: subprocess.Popen[bytes] | None = None
        try:
            # The receiver first, then the sender once the receiver reads its tty.
            if ours_send:
                ckermit = _popen(ck_argv, cwd=out)
                _ckermit_ready(ckermit, their_line)
                ours = _popen(ours_argv)
            else:
                ours = _popen(ours_argv)
                wait_until_reading(ours, ours_line)
                ckermit = _popen(ck_argv, cwd=src)
            # Our side ends on its own: done, or failed after its retries.
            _, err = ours.communicate(timeout=LIMIT)
            outcome = _outcome(ours.returncode, err)
            status, ck_output = _finish(ckermit)
        finally:
            for proc in (ours, ckermit):
                if proc is not None:
                    _stop(proc)
    received = (out / path.name).read_bytes() if (out / path.name).exists() else None
    return Run(case, outcome, status, ck_output, data, received)


def _popen(argv: list[str], cwd: pathlib.Path | None = None) -> subprocess.Popen[bytes]:
    """Our side: stderr captured (the message and --stats); C-Kermit: its output."""
    ckermit = argv[0] == "kermit"
    return subprocess.Popen(
        argv,
        cwd=cwd,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE if ckermit else subprocess.DEVNULL,
        stderr=subprocess.STDOUT if ckermit else subprocess.PIPE,
    )


@pytest.mark.slow
def test_exit_status_is_0_exactly_when_the_file_arrived_whole(tmp_path: pathlib.Path) -> None:
    if shutil.which("kermit") is None:
        pytest.skip("ckermit not installed: .ci/run installs it (apt-get install ckermit)")
    with ThreadPoolExecutor(max_workers=len(CASES)) as pool:
        futures = [
            pool.submit(_run, case, tmp_path / f"case{i}", 17 + i) for i, case in enumerate(CASES)
        ]
        runs = [f.result() for f in futures]
    report = []
    for run in runs:
        whole = run.received == run.sent
        got = "nothing" if run.received is None else f"{len(run.received)} bytes"
        report.append(
            f"{run.case.name}: ours exit {run.ours.returncode}, C-Kermit exit "
            f"{run.ckermit_status}, {got} of {len(run.sent)}"
            + ("" if whole else " (not the file sent)")
        )
    summary = "\n".join(report)
    print(summary)
    for run in runs:
        assert "Traceback" not in run.ours.stderr, run.ours.stderr
        whole = run.received == run.sent
        assert (run.ours.returncode == 0) == whole, (run.case.name, summary, run.ours.stderr)
        assert run.ours.returncode in (0, 1), run.ours.stderr
        assert run.ours.stats is not None, run.ours.stderr
        if run.ours.returncode == 0:
            assert run.ours.stats["state"] == "done"
            assert run.ours.stats["acknowledged_bytes"] == len(run.sent)
            assert run.ours.stats["window"] == run.case.window
        elif run.case.sender == "ours":  # gave up, and says how far it got
            assert "bytes, " in run.ours.stderr
            assert " were acknowledged" in run.ours.stderr
        else:
            assert "files stored whole" in run.ours.stderr
    # A matrix where everything gave up would prove nothing about exit 0.
    assert sum(run.ours.returncode == 0 for run in runs) >= len(runs) // 2, summary
