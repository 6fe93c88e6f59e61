"""A person at the keyboard instead of a script: keys move the hand controller's handle.

:class:`KeyboardScript` is a :class:`Script` whose intent follows keys (pure:
``press(key)``, so it is tested with strings, and a file of keys replays a
session).  :func:`read_keys` feeds it from stdin -- in cbreak mode when stdin
is a terminal, so each key counts at once.

=====  ==========================================================
key    what it does
=====  ==========================================================
w s    handle +x / -x by 5 mm          (hand-controller frame)
a d    handle +y / -y by 5 mm
r f    handle +z / -z by 5 mm
q e    turn about z by +/-0.05 rad
0      back to neutral (with the index button released: a clutch)
space  index button: engage / release (release = clutch open)
p      pose-change button: hold / let go
g      trigger: close / open the gripper
x      emergency stop (STOP on the channel)
Q      quit
=====  ==========================================================
"""

from __future__ import annotations

import contextlib
import math
import os
import termios
import tty
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
import trio

from ._contact import Array
from ._operator import Waypoint

__all__ = ["KEYS", "KeyboardScript", "read_keys"]

STEP = 0.005
"""m per key press."""
TURN = 0.05
"""rad per key press."""
KEYS = {
    "w": (0, STEP),
    "s": (0, -STEP),
    "a": (1, STEP),
    "d": (1, -STEP),
    "r": (2, STEP),
    "f": (2, -STEP),
}


@dataclass
class KeyboardScript:
    """The operator's intent, moved by keys (a :class:`Script`'s ``at`` and ``duration``)."""

    name: str = "keyboard"
    offset: Array = field(default_factory=lambda: np.zeros(3))
    rotation: Array = field(default_factory=lambda: np.zeros(3))
    engaged: bool = True
    pose_change: bool = False
    trigger: int = 0
    stop_requested: bool = False
    done: bool = False
    presses: int = 0

    @property
    def duration(self) -> float:
        return math.inf

    def press(self, key: str) -> None:
        """One key (unknown keys are ignored)."""
        self.presses += 1
        if key in KEYS:
            axis, step = KEYS[key]
            self.offset = self.offset.copy()
            self.offset[axis] += step
        elif key in ("q", "e"):
            self.rotation = self.rotation.copy()
            self.rotation[2] += TURN if key == "q" else -TURN
        elif key == "0":
            self.offset, self.rotation = np.zeros(3), np.zeros(3)
        elif key == " ":
            self.engaged = not self.engaged
        elif key == "p":
            self.pose_change = not self.pose_change
        elif key == "g":
            self.trigger = 0 if self.trigger else 255
        elif key == "x":
            self.stop_requested = True
        elif key == "Q":
            self.done = True

    def at(self, t: float) -> tuple[Array, Array, Waypoint]:
        w = Waypoint(
            t,
            (0.0, 0.0, 0.0),
            engaged=self.engaged,
            trigger=self.trigger,
            pose_change=self.pose_change,
        )
        return self.offset.copy(), self.rotation.copy(), w


@contextlib.contextmanager
def _cbreak(fd: int) -> Iterator[None]:
    if not os.isatty(fd):
        yield
        return
    saved = termios.tcgetattr(fd)
    try:
        tty.setcbreak(fd)
        yield
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)


async def read_keys(script: KeyboardScript, fd: int | None = None) -> None:
    """Feed ``script`` from stdin (or ``fd``) until ``Q`` or the end of the input."""
    fd = 0 if fd is None else fd  # the process's stdin, whatever sys.stdin is now
    stream = trio.lowlevel.FdStream(os.dup(fd))
    with _cbreak(fd):
        async with stream:
            while not script.done:
                data = await stream.receive_some(64)
                if not data:  # keys piped from a file: the run goes on to --duration or Q
                    return
                for ch in data.decode("utf-8", errors="replace"):
                    script.press(ch)
