"""Ctrl-C ends a command with one line and status 130, never a traceback (issue 19)."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest

LIMIT = 60.0


# Where to interrupt: as soon as the run prints anything (still starting the
# server or connecting: a Ctrl-C there once corrupted trio's cancel scopes and
# ended in a traceback), once a command is on its way, once one is accepted.
# The console reprints its table, whose header also says "sent": the markers
# match the event lines only.
MOMENTS = {"starting": r"", "sent": r"#1 +sent", "accepted": r"#1 +accepted"}


@pytest.fixture
def arm_server() -> Iterator[int]:
    """A ``linksim arm-server`` on loopback TCP for the console to drive."""
    server = subprocess.Popen(
        [sys.executable, "-m", "linksim", "arm-server", "--transport", "tcp", "--tcp-port", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert server.stdout is not None
        ready = json.loads(server.stdout.readline())
        yield int(ready["tcp_port"])
    finally:
        server.terminate()
        server.wait(timeout=LIMIT)


@pytest.mark.parametrize("moment", list(MOMENTS))
@pytest.mark.parametrize("command", ["demo", "console"])
def test_sigint_midway_exits_130_with_one_line(
    command: str, moment: str, request: pytest.FixtureRequest
) -> None:
    argv = [command, "--transport", "tcp", "--plain"]
    if command == "console":
        argv += ["--tcp-port", str(request.getfixturevalue("arm_server"))]
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
    seen = ""
    deadline = time.monotonic() + LIMIT
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        seen += line
        if re.search(MOMENTS[moment], line):
            break
    assert re.search(MOMENTS[moment], seen), seen  # interrupted where meant
    proc.send_signal(signal.SIGINT)
    _out, err = proc.communicate(timeout=LIMIT)
    assert proc.returncode == 130, seen + err
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1] == f"linksim {command}: interrupted"


def test_version() -> None:
    from linksim import __version__

    done = subprocess.run(
        [sys.executable, "-m", "linksim", "--version"], capture_output=True, text=True, timeout=60
    )
    assert done.stdout.strip() == f"linksim {__version__}"
