"""The remote site of seed 004: the PUMA following hand-controller samples, feeling contact.

Every control tick (:meth:`RemoteArm.step`) the arm takes the newest sample
(if one arrived), turns it into a commanded hand pose by mode, runs the hand's
servo against the contact model, solves the joints, and answers with a
:class:`tcpstream.teleop.Reply`:

* **JOINT**: the hand controller's joint increments, scaled per joint, set a
  joint target (no singularity check: seed 004 uses joint mode "to move the
  robot out of kinematic singular positions").  Without SHARED_COMPLIANCE the
  joints are driven straight to it at full joint speed (a rigid press).  With
  SHARED_COMPLIANCE the local compliant force control acts as in the other
  modes: the target's forward kinematics is the commanded hand pose, the
  compliant servo below yields to contact, and the joints are solved from the
  target itself (in free space they land on it exactly; in contact only the
  yielded position differs).
* **CARTESIAN / INDEX**: dX_h, rotated into the robot's frame by the 6x6
  block rotation ``[[R, 0], [0, R]]`` (constant, or turning with a moving
  base), scaled, added to the commanded pose in the world or the tool frame.
* **RATE**: the deflection sets a hand velocity; it stops when no sample has
  arrived for the deadman time (derived from the line: :func:`rate_deadman`).
* The index clutch (ENGAGED clear) holds the arm; the trigger drives the gripper.
* **Singularities**: a step that enters a singular region is refused and the
  command snaps back to the actual pose ("bounces off") unless POSE_CHANGE is
  held.  **Joint limits** clip.
* **Force**: the hand is a mass on a servo spring; the wrist sensor reads the
  contact model.  With SHARED_COMPLIANCE the arm yields to contact itself (an
  admittance whose commanding force is capped below the limit, so contact
  force settles at the cap whatever the operator asks); without it the servo
  is stiff and the contact force is whatever the operator's position implies.
  A force beyond the limit stops the arm until the index button is released
  and pressed again.

Pure numpy and plain arithmetic on a ``now`` the caller gives: no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from linksim.arm import PUMA560, ArmModel, hand_frame
from tcpstream.teleop import Buttons, ContactFlags, Reply, ReplyStatus, Sample, TeleopMode

from ._contact import Array, ContactModel, Wrench
from ._frhc import rotvec

__all__ = [
    "RemoteArm",
    "RemoteConfig",
    "RemoteStatistics",
    "rate_deadman",
    "rotation",
    "solve_hand",
]

_SINGULAR = (0.05, 0.05, 0.05)
"""Shoulder (m), elbow (rad), wrist (rad) margins: linksim.arm's singular regions."""
_SUBSTEPS = 8
"""Servo integration steps per control tick: 1 ms at 125 Hz, well inside the
contact's 2/omega stability bound (omega = sqrt(20 kN/m / 2 kg) = 100 rad/s)."""
_SEED_ITERATIONS = 10
"""Solver steps from JOINT mode's target: the servo's hand may lag it by centimetres."""


def rotation(v: Array) -> Array:
    """Rodrigues: the rotation matrix of a rotation vector."""
    angle = float(np.linalg.norm(v))
    if angle == 0.0:
        return np.eye(3)
    k = v / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.asarray(np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx)


def rate_deadman(one_way_delay: float, sample_interval: float) -> float:
    """How long rate mode keeps moving without a new sample.

    A lost sample is repaired by the transport one round trip later, so a
    deadman shorter than the round trip would stop a healthy link; four sample
    intervals on top absorb the pacing's gaps, and 0.1 s the scheduling.
    """
    return 2.0 * one_way_delay + 4.0 * sample_interval + 0.1


@dataclass(frozen=True, slots=True)
class RemoteConfig:
    control_rate: float = 125.0
    force_limit: float = 50.0
    """N: the arm stops beyond this contact force."""
    force_stop: bool = True
    compliance_force: float = 30.0
    """N: shared compliance never pushes harder than this (60 % of the limit)."""
    mass: float = 2.0
    servo_stiffness: float = 5000.0
    servo_damping: float = 200.0
    admittance_stiffness: float = 4000.0
    admittance_damping: float = 800.0
    approach_speed: float = 0.1
    """m/s: shared compliance moves the reference no faster (an impact at it adds ~20 N)."""
    position_scale: float = 1.0
    rotation_scale: float = 1.0
    joint_scale: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    """Hand-controller joint to arm joint; the slide (m) maps to joint 3 at 2 rad/m."""
    rate_gain: float = 1.0
    """(m/s)/m and (rad/s)/rad of deflection."""
    rate_deadband: float = 0.002
    hand_to_robot: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Rotation vector of the constant hand-controller -> robot base rotation R."""
    base_rate: float = 0.0
    """rad/s about z: a moving base (the transformation is then not constant)."""
    rate_deadman: float = 1.0
    model: ArmModel = PUMA560


@dataclass
class RemoteStatistics:
    samples_applied: int = 0
    ages: list[float] = field(default_factory=list)
    max_force: float = 0.0
    force_trace: list[tuple[float, float]] = field(default_factory=list)
    force_limit_stops: int = 0
    bounces: int = 0
    pose_changes: int = 0
    deadman_trips: int = 0
    joint_limit_hits: int = 0
    emergency_stops: int = 0
    samples_after_stop: int = 0
    """Samples that arrived after the stop (ignored)."""
    moved_after_stop: float = 0.0
    """The farthest the hand went from where the stop caught it (m)."""


def _dh(a: float, alpha: float, d: float, theta: float) -> Array:
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def _jacobian(model: ArmModel, q: Array) -> Array:
    """Geometric Jacobian at the hand point (standard DH, the model's parameters)."""
    frames = [np.eye(4)]
    for j in range(6):
        frames.append(frames[-1] @ _dh(model.a[j], model.alpha[j], model.d[j], float(q[j])))
    p = frames[6][:3, 3] + model.tool_length * frames[6][:3, 2]
    jac = np.empty((6, 6))
    for j in range(6):
        z = frames[j][:3, 2]
        jac[:3, j] = np.cross(z, p - frames[j][:3, 3])
        jac[3:, j] = z
    return jac


def solve_hand(
    model: ArmModel,
    q: Array,
    p: Array,
    r: Array,
    *,
    iterations: int = 3,
    damping: float = 1e-4,
    tolerance: float = 1e-10,
) -> Array:
    """The arm's damped-least-squares solver: joints that put the hand at ``p`` (m, base
    frame) turned ``r`` (3x3), starting from ``q``.

    At most ``iterations`` steps, stopping once every position (m) and rotation (rad)
    error is below ``tolerance``; the defaults are the control tick's (a few steps from
    last tick's joints, never far from the answer).  Returns new joints and leaves ``q``
    alone; no joint limits, no singularity check, no convergence check: a caller that
    needs the exact answer checks :func:`linksim.arm.hand_frame` of the result.
    """
    q = np.array(q, dtype=np.float64)
    for _ in range(iterations):
        frame = hand_frame(model, q)
        err = np.concatenate([p - frame[:3, 3], rotvec(r @ frame[:3, :3].T)])
        if float(np.max(np.abs(err))) < tolerance:
            break
        jac = _jacobian(model, q)
        q = q + jac.T @ np.linalg.solve(jac @ jac.T + damping * np.eye(6), err)
    return q


def _singular(model: ArmModel, q: Array) -> int | None:
    """Which singular region (0 shoulder, 1 elbow, 2 wrist) ``q`` is in, if any."""
    a2, a3, d4 = model.a[1], model.a[2], model.d[3]
    q2, q3 = float(q[1]), float(q[2])
    r = a2 * math.cos(q2) + a3 * math.cos(q2 + q3) - d4 * math.sin(q2 + q3)
    v = a3 * math.sin(q3) + d4 * math.cos(q3)
    elbow = math.asin(max(-1.0, min(1.0, v / math.hypot(a3, d4))))
    wrist = math.asin(max(-1.0, min(1.0, math.sin(float(q[4])))))
    for i, m in enumerate((r, elbow, wrist)):
        if abs(m) < _SINGULAR[i]:
            return i
    return None


def _six(v: Array) -> tuple[float, float, float, float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]), float(v[3]), float(v[4]), float(v[5]))


class RemoteArm:
    """The arm at the remote site; ``step(now, latest)`` once per control tick."""

    def __init__(self, config: RemoteConfig, contact: ContactModel, q0: Array) -> None:
        self.config = config
        self.contact = contact
        self.model = config.model
        self.q = np.array(q0, dtype=np.float64)
        frame = hand_frame(self.model, self.q)
        self.p = frame[:3, 3].copy()
        self.r = frame[:3, :3].copy()
        self.v = np.zeros(3)
        self.p_cmd = self.p.copy()
        self.r_cmd = self.r.copy()
        self.p_ref = self.p.copy()
        self.q_target = self.q.copy()
        self.reference = np.zeros(6)
        self.mode: TeleopMode | None = None
        self.buttons = Buttons(0)
        self.rate = np.zeros(6)
        self.status = ReplyStatus.FOLLOWING
        self.flags = ContactFlags(0)
        self.gripper = 0
        self.trigger = 0
        self.last: Sample | None = None
        self.last_arrival: float | None = None
        self.stopped = False
        self._stopped_at = self.p.copy()
        self.wrench = contact.wrench(self.p, self.v, self._wrist())
        self.stats = RemoteStatistics()

    # -- frames ------------------------------------------------------------------------

    def _hand_to_robot(self, now: float) -> Array:
        base = rotation(np.array([0.0, 0.0, -self.config.base_rate * now]))
        return base @ rotation(np.array(self.config.hand_to_robot))

    def _wrist(self) -> Array:
        return np.asarray(self.p - self.model.tool_length * self.r[:, 2])

    # -- samples -----------------------------------------------------------------------

    def emergency_stop(self) -> None:
        """STOP (or the command session's emergency stop): hold here for good."""
        if not self.stopped:
            self.stats.emergency_stops += 1
            self._stopped_at = self.p.copy()
        self.stopped = True
        self._hold()

    def _hold(self) -> None:
        self.p_cmd = self.p.copy()
        self.p_ref = self.p.copy()
        self.r_cmd = self.r.copy()
        self.q_target = self.q.copy()
        self.v = np.zeros(3)
        self.rate = np.zeros(6)

    def _apply(self, s: Sample, arrived: float, now: float) -> None:
        cfg = self.config
        if self.stopped:
            self.stats.samples_after_stop += 1
            return
        words = np.array(s.words, dtype=np.float64)
        engaged = bool(s.buttons & Buttons.ENGAGED)
        was_engaged = bool(self.buttons & Buttons.ENGAGED)
        self.buttons = s.buttons
        self.trigger = s.trigger
        self.last, self.last_arrival = s, arrived
        self.stats.samples_applied += 1
        self.stats.ages.append(now - s.stamp)
        if s.mode is not self.mode:
            # The words change meaning with the mode: no motion on a switch.  The first
            # sample of the channel counts from zero (the sums start with the channel).
            first = self.mode is None
            self.mode = s.mode
            switch = s.mode is not TeleopMode.RATE and not first
            self.reference = words.copy() if switch else np.zeros(6)
            self.q_target = self.q.copy()
            self._hold()
        if self.status is ReplyStatus.FORCE_LIMIT:
            if engaged and not was_engaged:
                self.status = ReplyStatus.FOLLOWING  # re-armed by the index button
            else:
                self.reference = words.copy()
                return
        if self.status is ReplyStatus.DEADMAN:
            self.status = ReplyStatus.FOLLOWING
        if s.mode is TeleopMode.RATE:
            if not engaged:
                self.flags |= ContactFlags.CLUTCHED
                self.rate = np.zeros(6)
                return
            dead = np.where(np.abs(words) < cfg.rate_deadband, 0.0, words)
            self.rate = cfg.rate_gain * self._to_robot(dead, now, tool=False)
            return
        # The words are sums of what the hand did while ENGAGED (tcpstream
        # PROTOCOL.md 14): the difference from the last sample applied is
        # motion to make even when this sample is clutched -- the hand moved
        # before the release, in samples this arm never saw.  (Resetting the
        # reference on a clutched sample lost that motion: a joint-mode
        # surface run that never reached the table, seed 3.)  While clutched
        # the sums do not change, so the arm holds.
        delta = words - self.reference
        self.reference = words.copy()
        if not engaged:
            self.flags |= ContactFlags.CLUTCHED
            self.rate = np.zeros(6)
        if s.mode is TeleopMode.JOINT:
            self.q_target = self.q_target + np.array(cfg.joint_scale) * delta
            self.q_target = np.clip(self.q_target, self.model.lower_array, self.model.upper_array)
            return
        d = self._to_robot(delta, now, tool=bool(s.buttons & Buttons.TOOL_FRAME))
        self.p_cmd = self.p_cmd + cfg.position_scale * d[:3]
        self.r_cmd = rotation(cfg.rotation_scale * d[3:]) @ self.r_cmd

    def _to_robot(self, x: Array, now: float, *, tool: bool) -> Array:
        r = self._hand_to_robot(now)
        if tool:
            r = self.r @ r
        return np.concatenate([r @ x[:3], r @ x[3:]])

    # -- the control tick --------------------------------------------------------------

    def step(self, now: float, latest: tuple[Sample, float] | None) -> Reply:
        cfg = self.config
        dt = 1.0 / cfg.control_rate
        self.flags = ContactFlags(0)
        if latest is not None:
            self._apply(latest[0], latest[1], now)
        held = self.stopped or self.status is ReplyStatus.FORCE_LIMIT
        if self.mode is TeleopMode.RATE and not held and self.last_arrival is not None:
            if now - self.last_arrival > cfg.rate_deadman:
                if self.status is not ReplyStatus.DEADMAN:
                    self.stats.deadman_trips += 1
                self.status = ReplyStatus.DEADMAN
                self.rate = np.zeros(6)
            self.p_cmd = self.p_cmd + self.rate[:3] * dt
            self.r_cmd = rotation(self.rate[3:] * dt) @ self.r_cmd
        if self.mode is TeleopMode.JOINT and not held:
            if self.buttons & Buttons.SHARED_COMPLIANCE:
                self._compliant_joint_tick(dt)
            else:
                self._joint_tick(dt)
        else:
            self._cartesian_tick(dt)
        self._contact_tick(now)
        if self.stopped:
            moved = float(np.linalg.norm(self.p - self._stopped_at))
            self.stats.moved_after_stop = max(self.stats.moved_after_stop, moved)
        return self._reply(now)

    def _joint_tick(self, dt: float) -> None:
        vmax = np.asarray(self.model.max_velocity) * dt
        step = np.clip(self.q_target - self.q, -vmax, vmax)
        q = self.q + step
        frame = hand_frame(self.model, q)
        self.v = (frame[:3, 3] - self.p) / dt
        self.q, self.p, self.r = q, frame[:3, 3].copy(), frame[:3, :3].copy()
        self.p_cmd, self.r_cmd, self.p_ref = self.p.copy(), self.r.copy(), self.p.copy()
        self.wrench = self.contact.wrench(self.p, self.v, self._wrist())

    def _compliant_joint_tick(self, dt: float) -> None:
        """JOINT mode with shared compliance: the joint target, through its forward
        kinematics, commands the compliant Cartesian tick, which yields to contact."""
        frame = hand_frame(self.model, self.q_target)
        self.p_cmd, self.r_cmd = frame[:3, 3].copy(), frame[:3, :3].copy()
        self._cartesian_tick(dt, seed=self.q_target)

    def _cartesian_tick(self, dt: float, *, seed: Array | None = None) -> None:
        cfg = self.config
        shared = bool(self.buttons & Buttons.SHARED_COMPLIANCE)
        h = dt / _SUBSTEPS
        p, v = self.p.copy(), self.v.copy()
        wrist = self._wrist()
        for _ in range(_SUBSTEPS):
            w = self.contact.wrench(p, v, wrist)
            if shared:
                self.p_ref = self.p_ref + self._admittance(w) * h
            else:
                self.p_ref = self.p_cmd.copy()
            acc = (
                cfg.servo_stiffness * (self.p_ref - p) - cfg.servo_damping * v + w.force
            ) / cfg.mass
            v = v + acc * h
            p = p + v * h
            self._record(w)
        self._solve(p, v, dt, seed=seed)

    def _admittance(self, w: Wrench) -> Array:
        """Shared compliance: the velocity of the servo's reference.

        The reference is pulled toward the command by a spring and pushed by the
        contact force through a damper.  The spring's push *into* the contact
        (along the measured force) is capped at ``compliance_force``, so in
        contact the force settles at the cap however far the command lies
        beyond the surface; along the surface and in free space the reference
        follows the command, no faster than ``approach_speed``.
        """
        cfg = self.config
        push = cfg.admittance_stiffness * (self.p_cmd - self.p_ref)
        size = w.magnitude
        if size > 1e-9:
            n = w.force / size
            into = -float(push @ n)
            if into > cfg.compliance_force:
                push = push + (into - cfg.compliance_force) * n
        vel = (push + w.force) / cfg.admittance_damping
        speed = float(np.linalg.norm(vel))
        if speed > cfg.approach_speed:
            vel = vel * (cfg.approach_speed / speed)
        return np.asarray(vel)

    def _solve(self, p: Array, v: Array, dt: float, *, seed: Array | None = None) -> None:
        """Joints for hand position ``p`` and orientation ``r_cmd``: damped least squares.

        From last tick's joints; or, in JOINT mode (``seed``, the joint target), from the
        target, to the exact answer and with no singularity check.
        """
        if seed is None:
            q = solve_hand(self.model, self.q, p, self.r_cmd)
        else:
            q = solve_hand(self.model, seed, p, self.r_cmd, iterations=_SEED_ITERATIONS)
        vmax = np.asarray(self.model.max_velocity) * dt
        step = q - self.q
        worst = float(np.max(np.abs(step) / vmax))
        if worst > 1.0:
            step = step / worst
        q = self.q + step
        lo, hi = self.model.lower_array, self.model.upper_array
        if bool(np.any(q < lo)) or bool(np.any(q > hi)):
            self.flags |= ContactFlags.JOINT_LIMIT
            self.stats.joint_limit_hits += 1
            q = np.clip(q, lo, hi)
        region = None if seed is not None else _singular(self.model, q)
        if region is not None and _singular(self.model, self.q) != region:
            if self.buttons & Buttons.POSE_CHANGE:
                self.stats.pose_changes += 1
            else:
                # Bounce off: stay out of the region and drop the command that led in.
                self.flags |= ContactFlags.BOUNCED
                self.stats.bounces += 1
                self._hold()
                return
        frame = hand_frame(self.model, q)
        self.v = (frame[:3, 3] - self.p) / dt if worst > 1.0 else v
        self.q, self.p, self.r = q, frame[:3, 3].copy(), frame[:3, :3].copy()

    def _record(self, w: Wrench) -> None:
        self.stats.max_force = max(self.stats.max_force, w.magnitude)

    def _contact_tick(self, now: float) -> None:
        cfg = self.config
        self.wrench = self.contact.wrench(self.p, self.v, self._wrist())
        force = self.wrench.magnitude
        self.stats.max_force = max(self.stats.max_force, force)
        self.stats.force_trace.append((now, force))
        if self.wrench.contact:
            self.flags |= ContactFlags.CONTACT
        if (
            self.buttons & Buttons.SHARED_COMPLIANCE
            and float(np.linalg.norm(self.p_cmd - self.p)) > 1e-3
        ):
            self.flags |= ContactFlags.COMPLIANT
        if force > cfg.force_limit:
            self.flags |= ContactFlags.FORCE_LIMIT
            if cfg.force_stop and self.status is not ReplyStatus.FORCE_LIMIT:
                self.status = ReplyStatus.FORCE_LIMIT
                self.stats.force_limit_stops += 1
                self._hold()
        target = self.trigger
        self.gripper += max(-8, min(8, target - self.gripper))

    def _reply(self, now: float) -> Reply:
        status = ReplyStatus.STOPPED if self.stopped else self.status
        w = self.wrench
        last = self.last
        return Reply(
            sample=0 if last is None else last.sample,
            status=status,
            flags=self.flags,
            mode=0 if self.mode is None else int(self.mode),
            gripper=self.gripper,
            stamp=0.0 if last is None else last.stamp,
            held=0.0 if self.last_arrival is None else now - self.last_arrival,
            force=_six(np.concatenate([w.force, w.torque])),
            commanded=_six(np.concatenate([self.p_cmd, rotvec(self.r_cmd)])),
            actual=_six(np.concatenate([self.p, rotvec(self.r)])),
        )
