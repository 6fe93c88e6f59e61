"""The local site: a scripted (replayable) operator holding the FRHC.

A :class:`Script` is a list of timed waypoints for the hand's *intent*: where
the operator means the handle to be (offset from neutral, m, and a rotation
vector, rad), whether the index button is held, the trigger, the pose-change
button.  Between waypoints the intent moves linearly.  The same script gives
the same samples every time.

In JOINT mode the hand controller's joints drive the arm's joints one to one, so a
handle path made for the Cartesian modes sends the arm somewhere else: the
tasks' JOINT scripts are derived from where the Cartesian scripts send the
*arm* (:func:`joint_script`): the operator moves the handle so that the arm
goes where the task needs it, re-centring with the index clutch when the handle
would leave the FRHC's workspace.

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
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from linksim.arm import DEFAULT_WORLD, ArmModel, hand_frame
from tcpstream.teleop import Buttons, Reply, Sample, TeleopMode

from ._contact import Array
from ._frhc import FRHC_INITIAL, HandController, frhc_deflection, in_workspace, rotvec
from ._remote import RemoteConfig, rotation, solve_hand

__all__ = [
    "CLUTCH_HOLD",
    "CLUTCH_RETURN",
    "JOINT_STEP",
    "JOINT_TURN_STEP",
    "Intent",
    "Operator",
    "Script",
    "Waypoint",
    "joint_script",
    "peg_script",
    "surface_script",
]

JOINT_STEP = 0.005
"""m of tool travel between two waypoints of a derived JOINT script.  Between
waypoints the handle moves on a straight line, so the FRHC's joints -- and the
arm's, one to one -- move on a curve; at 5 mm the tool stays within 0.03 mm of
the task's straight lines (the encoders' counts add up to 0.4 mm more), where a
stiff contact turns every millimetre into 20 N."""
JOINT_TURN_STEP = 0.02
"""rad of tool turn between two waypoints of a derived JOINT script (as JOINT_STEP)."""
CLUTCH_HOLD = 0.2
"""s the handle rests before the index button is released and after it is pressed
again (as in the INDEX surface script): the clutch never opens or closes on a
moving handle."""
CLUTCH_RETURN = 1.0
"""s to carry the handle back to neutral with the clutch open."""


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


def surface_script(
    mode: TeleopMode,
    *,
    press: float = 0.02,
    drop: float = 0.10,
    start: Sequence[float] | Array = DEFAULT_WORLD.initial_joints,
    remote: RemoteConfig | None = None,
) -> Script:
    """Touch the table ``drop`` below the start, press ``press`` into it, slide 0.15 m, lift.

    In INDEX mode the slide is two strokes of 0.075 m with the clutch open
    between them (the handle goes back while the arm stays); in RATE mode the
    waypoints are deflections (a 0.02 m deflection is 0.02 m/s).  In JOINT mode
    the handle path that moves the arm, from joints ``start`` under ``remote``'s
    mapping (default :class:`RemoteConfig`), as the CARTESIAN script moves it
    (:func:`joint_script`); ``start`` and ``remote`` matter only there.
    """
    if mode is TeleopMode.JOINT:
        cartesian = surface_script(TeleopMode.CARTESIAN, press=press, drop=drop)
        return joint_script(cartesian, start, remote)
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
    mode: TeleopMode,
    *,
    hole: tuple[float, float] = (0.05, 0.0),
    above: float = 0.08,
    start: Sequence[float] | Array = DEFAULT_WORLD.initial_joints,
    remote: RemoteConfig | None = None,
) -> Script:
    """Carry the peg over the hole (3 mm off in y: the operator's error), push it down to
    the bottom of the 40 mm bore and 25 mm on in 2.5 s (the operator cannot see the
    bottom and feels it 2.6 s late at best), hold, withdraw.

    In JOINT mode the handle path that moves the arm as the CARTESIAN script does,
    from joints ``start`` under ``remote`` (see :func:`surface_script`).
    """
    if mode is TeleopMode.JOINT:
        cartesian = peg_script(TeleopMode.CARTESIAN, hole=hole, above=above)
        return joint_script(cartesian, start, remote)
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


def joint_script(
    handle: Script,
    start: Sequence[float] | Array = DEFAULT_WORLD.initial_joints,
    remote: RemoteConfig | None = None,
) -> Script:
    """The JOINT-mode script that moves the arm as ``handle`` does in CARTESIAN mode.

    ``handle`` is a position script (CARTESIAN or INDEX; not RATE, whose offsets
    are velocities).  Its waypoints mean tool targets by
    :class:`~linksim.teleop.RemoteArm`'s Cartesian mapping under ``remote``
    (default :class:`RemoteConfig`): the handle's motion while the index button is
    held, turned into the robot frame by ``hand_to_robot`` and scaled by
    ``position_scale`` and ``rotation_scale``, added to the tool's pose at the
    arm's joints ``start`` (world frame, as the runs send it; turns are composed
    about one axis, exact for the tasks, whose handles do not turn).  Between
    waypoints the target moves on a straight line, taken every
    :data:`JOINT_STEP` m or :data:`JOINT_TURN_STEP` rad.  For each target the
    arm's joints are solved from the previous ones (:func:`solve_hand`, so the
    arm stays on the branch it starts on), their change divided by
    ``joint_scale`` is the FRHC's joint change from :data:`FRHC_INITIAL`, and the
    FRHC's forward kinematics give the handle offset and rotation the operator
    holds (:func:`frhc_deflection`, the inverse of what
    :meth:`HandController.move_handle` solves).

    When the next handle pose would leave the FRHC's workspace
    (:func:`in_workspace`) the operator re-centres: holds :data:`CLUTCH_HOLD`,
    releases the index button, carries the handle back to neutral in
    :data:`CLUTCH_RETURN`, holds, presses it again -- the increments made with the
    clutch open are never added, so the arm holds -- and the later handle poses
    count from the arm's joints there.  Each re-centre makes the script
    ``2 * CLUTCH_HOLD + CLUTCH_RETURN`` longer than ``handle``.  Every waypoint is
    otherwise engaged; the trigger and the pose-change button follow ``handle``'s
    segments.  Deterministic: the same arguments give the same script.

    Raises :class:`ValueError` for a turning base (``base_rate``), a zero joint
    scale, a target the arm cannot reach or reaches only beyond its joint limits
    (the remote would clip), or a single step that leaves the workspace even
    from neutral.
    """
    cfg = RemoteConfig() if remote is None else remote
    if cfg.base_rate != 0.0:
        raise ValueError("joint_script: a turning base has no fixed handle-to-robot mapping")
    scale = np.array(cfg.joint_scale, dtype=np.float64)
    if scale.shape != (6,) or bool(np.any(scale == 0.0)):
        raise ValueError(f"joint_script: joint_scale must be six non-zero factors, got {scale}")
    q = np.array(start, dtype=np.float64)
    frame = hand_frame(cfg.model, q)
    p0, r0 = frame[:3, 3].copy(), frame[:3, :3].copy()
    targets = _tool_path(handle, cfg)
    out: list[Waypoint] = []
    base = q.copy()  # the arm's joints when the handle was last at neutral
    shift = 0.0  # seconds of re-centring so far
    for t, move, seg in targets:
        previous = q
        q = _reach(cfg.model, q, p0 + move[:3], rotation(move[3:]) @ r0)
        deflection = frhc_deflection(FRHC_INITIAL + (q - base) / scale)
        if not in_workspace(deflection) and out:
            shift += _recentre(out)
            base = previous
            deflection = frhc_deflection(FRHC_INITIAL + (q - base) / scale)
        if not in_workspace(deflection):
            raise ValueError(
                f"joint_script: at {t:g} s one step takes the handle out of the FRHC's "
                "workspace even from neutral"
            )
        out.append(
            Waypoint(
                t + shift,
                _three(deflection[:3]),
                _three(deflection[3:]),
                trigger=seg.trigger,
                pose_change=seg.pose_change,
            )
        )
    return Script(handle.name, tuple(out))


def _tool_path(handle: Script, cfg: RemoteConfig) -> list[tuple[float, Array, Waypoint]]:
    """The tool's targets along ``handle``, as (time, tool move from the start: position
    m and rotation vector rad, robot frame; the waypoint whose buttons hold)."""
    to_robot = rotation(np.array(cfg.hand_to_robot))
    ws = handle.waypoints
    path: list[tuple[float, Array, Waypoint]] = [(ws[0].t, np.zeros(6), ws[0])]
    move = np.zeros(6)
    for a, b in itertools.pairwise(ws):
        step = np.zeros(6)
        if a.engaged:  # the Operator adds a segment's increments only while it is engaged
            step[:3] = cfg.position_scale * (to_robot @ (np.array(b.offset) - np.array(a.offset)))
            step[3:] = cfg.rotation_scale * (
                to_robot @ (np.array(b.rotation) - np.array(a.rotation))
            )
        n = max(
            1,
            math.ceil(float(np.linalg.norm(step[:3])) / JOINT_STEP),
            math.ceil(float(np.linalg.norm(step[3:])) / JOINT_TURN_STEP),
        )
        for k in range(1, n + 1):
            # Inside a segment the script holds a's buttons; from b.t on, b's.
            t = b.t if k == n else a.t + k / n * (b.t - a.t)
            path.append((t, move + k / n * step, b if k == n else a))
        move = move + step
    return path


def _reach(model: ArmModel, q: Array, p: Array, r: Array) -> Array:
    """The arm's joints for hand position ``p`` and orientation ``r``, from ``q``: exact
    (1 nm, 1 nrad) and within the joint limits, or ValueError."""
    # The control tick's solver, run to convergence: from the previous target, a few
    # millimetres away, it converges in a handful of steps on the same branch.
    solved = solve_hand(model, q, p, r, iterations=100)
    frame = hand_frame(model, solved)
    err = np.concatenate([p - frame[:3, 3], rotvec(r @ frame[:3, :3].T)])
    if float(np.max(np.abs(err))) > 1e-9:
        raise ValueError(f"joint_script: the arm cannot reach {p} (m) from {q} (rad)")
    if bool(np.any(solved < model.lower_array)) or bool(np.any(solved > model.upper_array)):
        raise ValueError(f"joint_script: reaching {p} (m) needs joints {solved} beyond the limits")
    return solved


def _recentre(out: list[Waypoint]) -> float:
    """Append the index-clutch re-centre after ``out[-1]``; returns the seconds it takes."""
    last = out[-1]
    hold, back = last.t + CLUTCH_HOLD, last.t + CLUTCH_HOLD + CLUTCH_RETURN
    zero = (0.0, 0.0, 0.0)
    out += [
        Waypoint(hold, last.offset, last.rotation, False, last.trigger, last.pose_change),
        Waypoint(back, zero, zero, False, last.trigger, last.pose_change),
        Waypoint(back + CLUTCH_HOLD, zero, zero, True, last.trigger, last.pose_change),
    ]
    return 2 * CLUTCH_HOLD + CLUTCH_RETURN


def _three(v: Array) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


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
