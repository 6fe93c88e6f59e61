"""Defaults on both ends, against C-Kermit, through ``linksim relay`` at a byte error rate of 1e-3.

Issue 23: "packet length and window chosen from the measured error rate so
the defaults never fail where a hand-tuned C-Kermit succeeds".  Here nobody
tunes anything: ``python -m serialsocket kermit send|receive`` gets the port,
``--baud`` and ``--delay`` (what the line is, not how to use it), and C-Kermit
gets only its line settings (``set line``, carrier watch, flow, parity, no
streaming on a raw line) -- its window 30, 4000-character packets, dynamic
timers and 10 retries, and its default file names (converted: the file
arrives lower-cased both ways).  Both directions, as a user runs them
(subprocesses: ours, ``kermit``, ``linksim relay`` with a fixed seed), at
9600 bit/s with a byte error rate of 1e-3 each way.  The test passes when
each side exits 0 and the received file is byte for byte the one sent, and
our side's exit status is 0 exactly when it is.

The default run uses 0.2 s one way and 4 KB; the Moon line (1.3 s, 16 KB)
is under ``long`` (``make test-long``).  The measured table -- our defaults
against hand-tuned C-Kermit on the Moon line -- is ``linksim bench kermit
--table`` (serialsocket/KERMIT.md).
"""

from __future__ import annotations

import random
import shutil
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest

from .test_kermit_cli import Outcome, _outcome, _stop, cli, relay, wait_until_reading
from .test_kermit_moon import _ckermit_ready, _finish, _popen

RATE = 9600
BYTE_ERROR_RATE = 1e-3
SEED = 23
LIMIT = 300.0
"""Bound on our side's run: only stops a hang."""

pytestmark = pytest.mark.skipif(
    shutil.which("kermit") is None,
    reason="ckermit not installed: .ci/run installs it (apt-get install ckermit)",
)


@dataclass
class Run:
    """One transfer: our side's outcome, C-Kermit's status and output, what arrived."""

    ours: Outcome
    ckermit_status: int | None
    ckermit_output: str
    sent: bytes
    received: bytes | None


def _ckermit_defaults(line: str, path: Path | None) -> list[str]:
    """C-Kermit with its defaults: the line's settings only, then SEND or RECEIVE."""
    commands = [
        f"set line {line}",
        "set carrier-watch off",
        "set flow none",
        "set parity none",
        "set streaming off",  # a raw, impaired line is not reliable
        f"send {path}" if path else "receive",
        "exit \\v(status)",
    ]
    return ["kermit", "-Y", "-q", "-B", "-C", ", ".join(commands)]


def _run(tmp: Path, sender: str, delay: float, size: int) -> Run:
    src, out = tmp / "src", tmp / "out"
    src.mkdir(parents=True)
    out.mkdir()
    data = random.Random(SEED).randbytes(size)
    path = src / "moon.bin"
    path.write_bytes(data)
    line_options = ["--rate", str(RATE), "--delay", str(delay)]
    line_options += ["--ber", str(BYTE_ERROR_RATE), "--seed", str(SEED)]
    ours_options = ["--baud", str(RATE), "--delay", str(delay), "--stats"]
    ours_send = sender == "ours"
    with relay(*line_options) as line:
        ours_line, their_line = (line.a, line.b) if ours_send else (line.b, line.a)
        ours_argv = (
            cli("send", str(path), "--port", ours_line, *ours_options)
            if ours_send
            else cli("receive", str(out), "--port", ours_line, *ours_options)
        )
        ckermit = ours = None
        try:
            if ours_send:
                ckermit = _popen(_ckermit_defaults(their_line, None), cwd=out)
                _ckermit_ready(ckermit, their_line)
                ours = _popen(ours_argv)
            else:
                ours = _popen(ours_argv)
                wait_until_reading(ours, ours_line)
                ckermit = _popen(_ckermit_defaults(their_line, path), cwd=src)
            _, err = ours.communicate(timeout=LIMIT)
            outcome = _outcome(ours.returncode, err)
            status, output = _finish(ckermit)
        finally:
            for proc in (ours, ckermit):
                if proc is not None:
                    _stop(proc)
    # Default names: MOON.BIN on the wire, lower-cased on arrival by either side.
    arrived = out / "moon.bin"
    return Run(outcome, status, output, data, arrived.read_bytes() if arrived.exists() else None)


def _both_ways(tmp: Path, delay: float, size: int) -> None:
    with ThreadPoolExecutor(max_workers=2) as pool:
        futures = {
            sender: pool.submit(_run, tmp / sender, sender, delay, size)
            for sender in ("ours", "ckermit")
        }
        runs = {sender: f.result() for sender, f in futures.items()}
    for sender, run in runs.items():
        what = f"{sender} sending, {delay} s, 1e-3: ours {run.ours.stderr[-800:]!r}"
        what += f"; C-Kermit {run.ckermit_status}: {run.ckermit_output[-400:]!r}"
        whole = run.received == run.sent
        assert (run.ours.returncode == 0) == whole, what  # exit 0 iff the file is identical
        assert whole, what
        assert run.ckermit_status == 0, what
        assert run.ours.stats is not None, what
        assert run.ours.stats["state"] == "done", what
        assert run.ours.stats["window"] == 30, what  # C-Kermit's 30, our 31 offered
        if sender == "ours":
            assert run.ours.stats["acknowledged_bytes"] == len(run.sent), what


def test_defaults_both_ways_at_1e_3_with_a_short_delay(tmp_path: Path) -> None:
    """0.2 s one way, 4 KB: the default run's case (a few seconds)."""
    _both_ways(tmp_path, 0.2, 4096)


@pytest.mark.long
def test_defaults_both_ways_at_1e_3_on_the_moon_line(tmp_path: Path) -> None:
    """1.3 s one way, 16 KB at 9600 bit/s (about a minute)."""
    _both_ways(tmp_path, 1.3, 16384)
