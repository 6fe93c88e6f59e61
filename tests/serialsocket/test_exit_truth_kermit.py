"""Kermit's exit status tells the truth against C-Kermit, with and without hints.

Issue 17, finding 9: ``serialsocket kermit send`` to C-Kermit through
``linksim relay`` at 1.3 s one way and a byte error rate of 1e-3 exited 0
while C-Kermit held part of the file -- "2400 bit/s with defaults" among the
reproductions.  tests/serialsocket/test_kermit_moon.py checks the exit status
with fixed timers (``--timeout``) and 250-character packets on both sides;
here our side runs as a user would run it on that line:

* **hints**: ``--baud`` and ``--delay 1.3`` (the timers and the packet length
  derived from the line, then from measured round trips);
* **no hints**: nothing about the line at all (timers assume 9600 bit/s and
  no delay until they measure; the packet length is our default).

Both directions (our sender to C-Kermit's receiver, C-Kermit's sender to our
receiver), at 2400 bit/s with window 8 and 9600 bit/s with window 16.  Our
exit status must be 0 exactly when the file that arrived is byte for byte the
file sent; giving up is allowed (exit 1, saying how far it got).  C-Kermit's
side is configured as in the moon test (fixed 10 s timeout, its window, 250
characters), its status only reported.

A Kermit transfer is one file one way at a time (the protocol is half
duplex), so "both directions at once" is the netcat's case
(test_exit_truth_netcat.py), not this one's.  The eight transfers run at once
(each has its own relay); wall-clock runs, every wait bounded only to stop a
hang, hence ``long``.
"""

from __future__ import annotations

import pathlib
import random
import shutil
import subprocess
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import pytest

from .test_kermit_cli import Outcome, _outcome, _stop, cli, relay, wait_until_reading
from .test_kermit_moon import BYTE_ERROR_RATE, DELAY, LIMIT, SIZES, Case
from .test_kermit_moon import _ckermit_argv as ckermit_argv
from .test_kermit_moon import _ckermit_ready as ckermit_ready
from .test_kermit_moon import _finish as finish
from .test_kermit_moon import _popen as popen

RETRIES = 20
"""Our sender's retry limit, as in the moon test."""
RECEIVER_RETRIES = 6
"""Our receiver's limit on timeouts in a row with nothing new."""


@dataclass(frozen=True)
class HintCase:
    """One transfer: the moon test's case (sender, rate, window) and our hints."""

    case: Case
    hints: bool

    @property
    def name(self) -> str:
        return f"{self.case.name}, {'hints' if self.hints else 'no hints'}"

    def our_options(self) -> list[str]:
        options = ["--window", str(self.case.window), "--stats", "--literal-names"]
        if self.hints:
            options += ["--baud", str(self.case.rate), "--delay", str(DELAY)]
        return options


CASES = [
    HintCase(Case(sender, rate, window), hints)
    for sender in ("ours", "ckermit")
    for rate, window in ((2400, 8), (9600, 16))
    for hints in (True, False)
]


@dataclass
class Run:
    case: HintCase
    ours: Outcome
    ckermit_status: int | None
    sent: bytes
    received: bytes | None


def _run(hc: HintCase, tmp: pathlib.Path, seed: int) -> Run:
    case = hc.case
    src, out = tmp / "src", tmp / "out"
    src.mkdir(parents=True)
    out.mkdir()
    data = random.Random(seed).randbytes(SIZES[case.rate])
    path = src / "moon.bin"
    path.write_bytes(data)
    ours_send = case.sender == "ours"
    line = ["--rate", str(case.rate), "--delay", str(DELAY)]
    line += ["--ber", str(BYTE_ERROR_RATE), "--seed", str(seed)]
    ours_argv = (
        cli("send", str(path), "--retries", str(RETRIES), *hc.our_options())
        if ours_send
        else cli("receive", str(out), "--retries", str(RECEIVER_RETRIES), *hc.our_options())
    )
    with relay(*line) as r:
        ours_line, their_line = (r.a, r.b) if ours_send else (r.b, r.a)
        ours_argv += ["--port", ours_line]
        ck_argv = ckermit_argv(case, their_line, None if ours_send else path)
        ckermit: subprocess.Popen[bytes] | None = None
        ours: subprocess.Popen[bytes] | None = None
        try:
            if ours_send:  # the receiver first, the sender once it reads its tty
                ckermit = popen(ck_argv, cwd=out)
                ckermit_ready(ckermit, their_line)
                ours = popen(ours_argv)
            else:
                ours = popen(ours_argv)
                wait_until_reading(ours, ours_line)
                ckermit = popen(ck_argv, cwd=src)
            _, err = ours.communicate(timeout=LIMIT)
            outcome = _outcome(ours.returncode, err)
            status, _ = finish(ckermit)
        finally:
            for proc in (ours, ckermit):
                if proc is not None:
                    _stop(proc)
    received = (out / path.name).read_bytes() if (out / path.name).exists() else None
    return Run(hc, outcome, status, data, received)


@pytest.mark.long
def test_exit_status_is_0_exactly_when_the_file_arrived_whole_with_and_without_hints(
    tmp_path: pathlib.Path,
) -> None:
    if shutil.which("kermit") is None:
        pytest.skip("ckermit not installed: .ci/run installs it (apt-get install ckermit)")
    with ThreadPoolExecutor(max_workers=len(CASES)) as pool:
        futures = [
            pool.submit(_run, hc, tmp_path / f"case{i}", 41 + i) for i, hc in enumerate(CASES)
        ]
        runs = [f.result() for f in futures]
    summary = "\n".join(
        f"{run.case.name}: ours exit {run.ours.returncode}, C-Kermit exit {run.ckermit_status}, "
        + ("nothing" if run.received is None else f"{len(run.received)} bytes")
        + f" of {len(run.sent)}"
        + ("" if run.received == run.sent else " (not the file sent)")
        for run in runs
    )
    print("\n" + summary)
    for run in runs:
        name = run.case.name
        assert "Traceback" not in run.ours.stderr, (name, run.ours.stderr[-2000:])
        assert run.ours.returncode in (0, 1), (name, run.ours.stderr[-2000:])
        assert (run.ours.returncode == 0) == (run.received == run.sent), (
            name,
            summary,
            run.ours.stderr[-2000:],
        )
        assert run.ours.stats is not None, (name, run.ours.stderr[-2000:])
        if run.ours.returncode == 0:
            assert run.ours.stats["state"] == "done", name
            if run.case.case.sender == "ours":
                assert run.ours.stats["acknowledged_bytes"] == len(run.sent), name
        elif run.case.case.sender == "ours":  # gave up, and says how far it got
            assert " were acknowledged" in run.ours.stderr, (name, run.ours.stderr[-2000:])
        else:
            assert "files stored whole" in run.ours.stderr, (name, run.ours.stderr[-2000:])
    # A matrix where everything gave up would prove nothing about exit 0.
    assert sum(run.ours.returncode == 0 for run in runs) >= len(runs) // 2, summary
