"""Every program in examples/ runs as written (the README points newcomers at them)."""

from __future__ import annotations

import pathlib
import subprocess
import sys

import pytest

EXAMPLES = sorted((pathlib.Path(__file__).resolve().parents[1] / "examples").glob("*.py"))

# What each example must print: proof it did its job, not just that it exited 0.
EXPECTED = {
    "async_controller.py": ["MOVE_JOINT   done, joint 1 =   20.0 deg", "refused: UNREACHABLE"],
    "asyncio_serial.py": [
        "arm: 3 commands: MOVE_JOINT 1 20deg | STATUS | OPEN_FINGERS",
        "controller: DONE OPEN_FINGERS",
        "controller: closed cleanly: True",
        "arm: closed cleanly: True",
        "trio imported: False",
    ],
    "blocking_controller.py": [
        "joints: [0.0, 90.0, -200.0, 0.0, -70.0, 0.0]",
        "refused: NOT_GRASPING",
    ],
    "moon_link.py": ["joint 6 at 0.50 rad", "retransmissions"],
}


def test_every_example_has_expectations() -> None:
    assert sorted(p.name for p in EXAMPLES) == sorted(EXPECTED)


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_example_runs(path: pathlib.Path) -> None:
    # A generous hang guard only: these take a second or two.
    done = subprocess.run(
        [sys.executable, str(path)], capture_output=True, text=True, timeout=120, check=False
    )
    assert done.returncode == 0, done.stderr
    for text in EXPECTED[path.name]:
        assert text in done.stdout, done.stdout
