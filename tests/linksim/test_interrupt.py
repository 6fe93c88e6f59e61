"""Ctrl-C ends a command with one line and status 130, never a traceback (issue 19)."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

LIMIT = 60.0


@pytest.mark.parametrize(
    "argv",
    [
        ["demo", "--transport", "tcp", "--plain"],
        ["console", "--transport", "tcp", "--plain"],
    ],
    ids=["demo", "console"],
)
def test_sigint_midway_exits_130_with_one_line(argv: list[str]) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "linksim", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # A test run started in the background inherits SIGINT ignored (a
        # shell does that for background jobs); a user's terminal does not.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    assert proc.stderr is not None
    # Wait until the run is under way (a command was sent), then interrupt.
    seen = ""
    deadline = time.monotonic() + LIMIT
    while " sent" not in seen and time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        seen += line
    proc.send_signal(signal.SIGINT)
    _out, err = proc.communicate(timeout=LIMIT)
    assert proc.returncode == 130, seen + err
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1] == f"linksim {argv[0]}: interrupted"


def test_version() -> None:
    from linksim import __version__

    done = subprocess.run(
        [sys.executable, "-m", "linksim", "--version"], capture_output=True, text=True, timeout=60
    )
    assert done.stdout.strip() == f"linksim {__version__}"
