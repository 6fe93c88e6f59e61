"""The local site: a scripted (replayable) operator holding the FRHC.

A :class:`Script` is a list of timed waypoints for the hand's *intent*: where
the operator means the handle to be (offset from neutral, m, and a rotation
vector, rad), whether the index button is held, the trigger, the pose-change
button.  Between waypoints the intent moves linearly.  The same script gives
the same samples every time.

Without force reflection the handle is where the hand means it to be.  With
it, the FRHC's motors push the handle with the reflected force and the hand is
an impedance (mass, stiffness, damping of a human arm holding a handle:
1.5 kg, 400 N/m, 35 N s/m) around its intent -- at seed 004's 1.6 ms loop a
stable, felt contact; behind 2.6 s of round trip a push that arrives long
after the contact that caused it.

:class:`Operator.sample` is seed 004's local loop: read the encoders, dX_h =
J dtheta, add it to the running sums (only while the index button is held),
and build a :class:`tcpstream.teleop.Sample` of the mode.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from tcpstream.teleop import Buttons, Reply, Sample, TeleopMode

from ._contact import Array
from ._frhc import HandController
from ._remote import rotation

__all__ = ["Intent", "Operator", "Script", "Waypoint", "peg_script", "surface_script"]


@dataclass(frozen=True, slots=True)
class Waypoint:
    t: float
    offset: tuple[float, float, float]
    rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    engaged: bool = True
    trigger: int = 0
    pose_change: bool = False


class Intent(Protocol):
    """Where the operator means the handle to be: a :class:`Script`, or a person's keys."""

    @property
    def duration(self) -> float: ...

    def at(self, t: float) -> tuple[Array, Array, Waypoint]: ...


@dataclass(frozen=True, slots=True)
class Script:
    """Timed waypoints of the operator's intent; the last one holds forever."""

    name: str
    waypoints: tuple[Waypoint, ...]

    @property
    def duration(self) -> float:
        return self.waypoints[-1].t

    def at(self, t: float) -> tuple[Array, Array, Waypoint]:
        """Intended offset and rotation at ``t``, and the buttons of the segment."""
        times = [w.t for w in self.waypoints]
        i = bisect.bisect_right(times, t)
        if i == 0:
            w = self.waypoints[0]
            return np.array(w.offset), np.array(w.rotation), w
        if i >= len(self.waypoints):
            w = self.waypoints[-1]
            return np.array(w.offset), np.array(w.rotation), w
        a, b = self.waypoints[i - 1], self.waypoints[i]
        f = (t - a.t) / (b.t - a.t)
        off = (1 - f) * np.array(a.offset) + f * np.array(b.offset)
        rot = (1 - f) * np.array(a.rotation) + f * np.array(b.rotation)
        return off, rot, a


def surface_script(mode: TeleopMode, *, press: float = 0.02, drop: float = 0.10) -> Script:
    """Touch the table ``drop`` below the start, press ``press`` into it, slide 0.15 m, lift.

    In INDEX mode the slide is two strokes of 0.075 m with the clutch open
    between them (the handle goes back while the arm stays); in RATE mode the
    waypoints are deflections (a 0.02 m deflection is 0.02 m/s).
    """
    z = -(drop + press)
    if mode is TeleopMode.RATE:
        return Script(
            "surface",
            (
                Waypoint(0.0, (0.0, 0.0, 0.0)),
                Waypoint(1.0, (0.0, 0.0, 0.0)),
                Waypoint(1.5, (0.0, 0.0, -0.03)),
                Waypoint(5.5, (0.0, 0.0, -0.03)),
                Waypoint(6.0, (0.03, 0.0, -0.005)),
                Waypoint(10.0, (0.03, 0.0, -0.005)),
                Waypoint(10.5, (0.0, 0.0, 0.02)),
                Waypoint(12.0, (0.0, 0.0, 0.0)),
                Waypoint(14.0, (0.0, 0.0, 0.0)),
            ),
        )
    if mode is TeleopMode.INDEX:
        return Script(
            "surface",
            (
                Waypoint(0.0, (0.0, 0.0, 0.0)),
                Waypoint(1.0, (0.0, 0.0, 0.0)),
                Waypoint(4.0, (0.0, 0.0, z)),
                Waypoint(7.0, (0.075, 0.0, z)),
                Waypoint(7.2, (0.075, 0.0, z), engaged=False),
                Waypoint(9.0, (0.0, 0.0, z), engaged=False),
                Waypoint(9.2, (0.0, 0.0, z)),
                Waypoint(12.0, (0.075, 0.0, z)),
                Waypoint(14.0, (0.075, 0.0, 0.05)),
                Waypoint(15.0, (0.075, 0.0, 0.05)),
            ),
        )
    return Script(
        "surface",
        (
            Waypoint(0.0, (0.0, 0.0, 0.0)),
            Waypoint(1.0, (0.0, 0.0, 0.0)),
            Waypoint(4.0, (0.0, 0.0, z)),
            Waypoint(10.0, (0.15, 0.0, z)),
            Waypoint(12.0, (0.15, 0.0, 0.05)),
            Waypoint(13.0, (0.15, 0.0, 0.05)),
        ),
    )


def peg_script(
    mode: TeleopMode, *, hole: tuple[float, float] = (0.05, 0.0), above: float = 0.08
) -> Script:
    """Carry the peg over the hole (3 mm off in y: the operator's error), push it down to
    the bottom of the 40 mm bore and 25 mm on in 2.5 s (the operator cannot see the
    bottom and feels it 2.6 s late at best), hold, withdraw."""
    x, y = hole[0], hole[1] + 0.003
    down = -(above + 0.065)
    if mode is TeleopMode.RATE:
        return Script(
            "peg",
            (
                Waypoint(0.0, (0.0, 0.0, 0.0)),
                Waypoint(1.0, (0.0, 0.0, 0.0)),
                Waypoint(1.3, (x / 3.0, y / 3.0, 0.0)),
                Waypoint(3.7, (x / 3.0, y / 3.0, 0.0)),
                Waypoint(4.0, (0.0, 0.0, 0.0)),
                Waypoint(4.3, (0.0, 0.0, down / 5.0)),
                Waypoint(9.7, (0.0, 0.0, down / 5.0)),
                Waypoint(10.0, (0.0, 0.0, 0.0)),
                Waypoint(12.0, (0.0, 0.0, 0.0)),
            ),
        )
    return Script(
        "peg",
        (
            Waypoint(0.0, (0.0, 0.0, 0.0), trigger=255),
            Waypoint(1.0, (0.0, 0.0, 0.0), trigger=255),
            Waypoint(4.0, (x, y, 0.0), trigger=255),
            Waypoint(6.5, (x, y, down), trigger=255),
            Waypoint(11.0, (x, y, down), trigger=255),
            Waypoint(13.0, (x, y, 0.0), trigger=255),
            Waypoint(14.0, (x, y, 0.0), trigger=255),
        ),
    )


@dataclass
class Operator:
    """The operator and the FRHC: ``sample(now, dt)`` every sampling interval."""

    script: Intent
    mode: TeleopMode
    force_reflection: bool = False
    shared_compliance: bool = False
    tool_frame: bool = False
    reflect_gain: float = 0.5
    hand_mass: float = 1.5
    hand_stiffness: float = 400.0
    hand_damping: float = 35.0
    hand_to_robot: tuple[float, float, float] = (0.0, 0.0, 0.0)
    hc: HandController = field(default_factory=HandController)
    sampled: int = 0
    felt: Array = field(default_factory=lambda: np.zeros(3))
    handle: Array = field(default_factory=lambda: np.zeros(3))
    handle_v: Array = field(default_factory=lambda: np.zeros(3))
    sums: Array = field(default_factory=lambda: np.zeros(6))
    last_reply: Reply | None = None

    def on_reply(self, reply: Reply, now: float) -> None:
        """The arm's answer: the force to reflect (robot base frame -> hand-controller frame)."""
        self.last_reply = reply
        r = rotation(np.array(self.hand_to_robot))
        self.felt = r.T @ np.array(reply.force[:3])

    def sample(self, now: float, dt: float, *, stamp: float | None = None) -> Sample:
        """The sample at script time ``now`` (stamped ``stamp``, default ``now``)."""
        intent, rot, seg = self.script.at(now)
        if self.force_reflection and self.mode is not TeleopMode.RATE:
            push = self.hc.reflect(np.concatenate([self.reflect_gain * self.felt, np.zeros(3)]))
            acc = (
                self.hand_stiffness * (intent - self.handle)
                - self.hand_damping * self.handle_v
                + push[:3]
            ) / self.hand_mass
            self.handle_v = self.handle_v + acc * dt
            self.handle = self.handle + self.handle_v * dt
        else:
            self.handle = intent
        self.hc.move_handle(self.handle, rot)
        dx, dtheta = self.hc.increment()
        buttons = Buttons(0)
        if seg.engaged:
            buttons |= Buttons.ENGAGED
            self.sums += dtheta if self.mode is TeleopMode.JOINT else dx
        if self.force_reflection:
            buttons |= Buttons.FORCE_REFLECTION
        if self.shared_compliance:
            buttons |= Buttons.SHARED_COMPLIANCE
        if self.tool_frame:
            buttons |= Buttons.TOOL_FRAME
        if seg.pose_change:
            buttons |= Buttons.POSE_CHANGE
        words = self.hc.deflection() if self.mode is TeleopMode.RATE else self.sums
        self.sampled += 1
        w = [float(x) for x in words]
        return Sample(
            self.sampled,
            self.mode,
            buttons,
            seg.trigger,
            now if stamp is None else stamp,
            (w[0], w[1], w[2], w[3], w[4], w[5]),
        )
