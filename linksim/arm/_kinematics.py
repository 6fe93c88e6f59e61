"""PUMA 560 kinematics: forward, closed-form inverse, Jacobian, singular regions.

Pure numpy, no clock and no I/O, so a local predictive model (the operator
console's preview) can reuse it unchanged.

Model and source
----------------
Standard Denavit-Hartenberg parameters of the Unimation PUMA 560 as given by
P. I. Corke, *Robotics Toolbox for MATLAB*, ``mdl_puma560.m`` (after Armstrong,
Khatib and Burdick, "The explicit dynamic model and inertial parameters of the
PUMA 560 arm", ICRA 1986), also in roboticstoolbox-python
``models/DH/Puma560.py``:

====  =======  ========  =========  ==================
 j     a (m)    d (m)    alpha      limits (deg)
====  =======  ========  =========  ==================
 1    0        0          pi/2      -160 .. 160
 2    0.4318   0          0          -45 .. 225
 3    0.0203   0.15005   -pi/2      -225 .. 45
 4    0        0.4318     pi/2      -110 .. 170
 5    0        0         -pi/2      -100 .. 100
 6    0        0          0         -266 .. 266
====  =======  ========  =========  ==================

The limits are the MATLAB toolbox's (``L(j).qlim``); the Python port keeps the
same numbers in comments next to symmetric placeholder ranges.  The base
frame has its origin on the shoulder (joint 1 and 2 axes), z up; the PUMA's
pedestal puts the shoulder 26.45 in = 0.672 m above its mounting surface.

The hand: the DH model ends at the wrist centre (frame 6 has d6 = 0).  Our
parallel gripper adds a tool offset of ``tool_length`` along z6 so that the
hand position **P** lies midway between the fingertips; the hand frame's
columns are seed 000's N, S (finger sliding, fingertip to fingertip) and A
(approach) vectors, with N = S x A.

Angles are radians, lengths metres, everything in the base frame.

Singular regions (seed 004: pose changes are allowed only near them)
--------------------------------------------------------------------
Three explicit measures, each zero exactly at its singularity:

* shoulder: the wrist centre's reach ``r`` in the arm plane (m), zero when the
  wrist centre lies on the axis of joint 1 (offset by d3);
* elbow: the angle (rad) between the forearm and the stretched (or fully
  folded) arm, zero when the wrist centre is at the boundary of the reach;
* wrist: the angle (rad) of joint 5 from 0 or pi, zero when joints 4 and 6
  align.

A pose is in a singular region when a measure falls below its threshold in
:data:`SINGULAR_THRESHOLDS` (0.05 m, 0.05 rad, 0.05 rad): at those margins the
joint rates needed for a 0.1 m/s hand speed stay within a few rad/s.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tcpstream import CommandFailed, FailureReason

__all__ = [
    "LINK_SEGMENTS",
    "PUMA560",
    "SINGULAR_THRESHOLDS",
    "ArmModel",
    "Array",
    "Singularity",
    "branch",
    "check_limits",
    "frame_from_psa",
    "hand_frame",
    "inverse",
    "inverse_candidates",
    "jacobian",
    "joint_frames",
    "link_points",
    "psa",
    "rotation_about",
    "singular_region",
    "singularity_measures",
    "wrap_to_limits",
]

Array = npt.NDArray[np.float64]

DEG = math.pi / 180.0


@dataclass(frozen=True, slots=True)
class ArmModel:
    """A six-joint arm in standard DH form plus a tool offset along z6.

    ``max_velocity`` (rad/s per joint) is the maximum-allowed-velocity vector
    of seed 000 on which the change-speed command acts.  The PUMA numbers
    below are a conservative choice for a simulated arm, not data-sheet values.
    """

    a: tuple[float, float, float, float, float, float]
    d: tuple[float, float, float, float, float, float]
    alpha: tuple[float, float, float, float, float, float]
    lower: tuple[float, float, float, float, float, float]
    upper: tuple[float, float, float, float, float, float]
    tool_length: float
    max_velocity: tuple[float, float, float, float, float, float]

    @property
    def lower_array(self) -> Array:
        return np.array(self.lower, dtype=np.float64)

    @property
    def upper_array(self) -> Array:
        return np.array(self.upper, dtype=np.float64)


PUMA560 = ArmModel(
    a=(0.0, 0.4318, 0.0203, 0.0, 0.0, 0.0),
    d=(0.0, 0.0, 0.15005, 0.4318, 0.0, 0.0),
    alpha=(math.pi / 2, 0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, 0.0),
    lower=(-160 * DEG, -45 * DEG, -225 * DEG, -110 * DEG, -100 * DEG, -266 * DEG),
    upper=(160 * DEG, 225 * DEG, 45 * DEG, 170 * DEG, 100 * DEG, 266 * DEG),
    # 0.056 m wrist centre to flange (Unimation) + 0.144 m flange to the
    # point between the fingertips of our simulated gripper.
    tool_length=0.20,
    max_velocity=(1.0, 1.0, 1.0, 2.0, 2.0, 2.0),
)
"""The PUMA 560 with the simulated parallel gripper."""


class Singularity(enum.IntEnum):
    """Which singular region (the SINGULAR failure's aux[0])."""

    SHOULDER = 1
    ELBOW = 2
    WRIST = 3


SINGULAR_THRESHOLDS = (0.05, 0.05, 0.05)
"""Shoulder (m), elbow (rad), wrist (rad): below these a pose is in a singular region."""

# Numerical tolerance for an IK solution's forward-kinematics residual: far
# above float64 round-off of the closed form (~1e-15 m), far below anything
# an operator can command.
_IK_RESIDUAL = 1e-7
# Joint-limit comparisons forgive this much so that a target exactly on a
# limit, after a round trip through trigonometry, still counts as inside.
_LIMIT_SLACK = 1e-9


def _dh(a: float, alpha: float, d: float, theta: float) -> Array:
    ct, st = math.cos(theta), math.sin(theta)
    ca, sa = math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def joint_frames(model: ArmModel, q: Array) -> Array:
    """Frames 0..6 in the base frame, shape (7, 4, 4); frame 0 is the identity."""
    frames = np.empty((7, 4, 4))
    frames[0] = np.eye(4)
    for j in range(6):
        frames[j + 1] = frames[j] @ _dh(model.a[j], model.alpha[j], model.d[j], float(q[j]))
    return frames


def hand_frame(model: ArmModel, q: Array) -> Array:
    """The hand frame (4x4): rotation columns N, S, A; translation P."""
    t: Array = joint_frames(model, q)[6].copy()
    t[:3, 3] += model.tool_length * t[:3, 2]
    return t


def psa(frame: Array) -> tuple[Array, Array, Array]:
    """Seed 000's P (position), S (finger sliding) and A (approach) of a hand frame."""
    return frame[:3, 3].copy(), frame[:3, 1].copy(), frame[:3, 2].copy()


def frame_from_psa(p: Array, s: Array, a: Array) -> Array:
    """The hand frame for P, S, A (S and A re-orthonormalised, A kept exact)."""
    a = a / np.linalg.norm(a)
    s = s - (s @ a) * a
    s = s / np.linalg.norm(s)
    t = np.eye(4)
    t[:3, 0] = np.cross(s, a)
    t[:3, 1] = s
    t[:3, 2] = a
    t[:3, 3] = p
    return t


LINK_SEGMENTS: tuple[tuple[int, int, int], ...] = ((1, 0, 1), (2, 1, 2), (3, 2, 3), (6, 3, 4))
"""Collision segments as (link number, back point, front point) into :func:`link_points`.

Link i is the body joint i moves.  Links 4 and 5 have zero length in the DH
model (a spherical wrist): they are the wrist-centre point shared by the
forearm (3) and hand (6) segments.  Link 1 is the shoulder's d3 offset.
"""


def link_points(model: ArmModel, q: Array) -> Array:
    """Points (5, 3) along the arm: shoulder, shoulder offset, elbow, wrist centre, hand P."""
    f = joint_frames(model, q)
    z1 = f[1][:3, 2]
    shoulder = f[1][:3, 3]
    offset = shoulder + model.d[2] * z1
    elbow = f[2][:3, 3] + model.d[2] * z1
    wrist = f[4][:3, 3]
    hand = f[6][:3, 3] + model.tool_length * f[6][:3, 2]
    return np.stack([shoulder, offset, elbow, wrist, hand])


def jacobian(model: ArmModel, q: Array) -> Array:
    """Geometric Jacobian (6x6) at the hand point P: rows vx, vy, vz, wx, wy, wz (base frame)."""
    f = joint_frames(model, q)
    p = f[6][:3, 3] + model.tool_length * f[6][:3, 2]
    jac = np.empty((6, 6))
    for j in range(6):
        z = f[j][:3, 2]
        jac[:3, j] = np.cross(z, p - f[j][:3, 3])
        jac[3:, j] = z
    return jac


def _arm_plane(model: ArmModel, q: Array) -> tuple[float, float]:
    """(r, v): the wrist centre's reach in the arm plane and the elbow's stretch term."""
    a2, a3, d4 = model.a[1], model.a[2], model.d[3]
    q2, q3 = float(q[1]), float(q[2])
    r = a2 * math.cos(q2) + a3 * math.cos(q2 + q3) - d4 * math.sin(q2 + q3)
    v = a3 * math.sin(q3) + d4 * math.cos(q3)
    return r, v


def singularity_measures(model: ArmModel, q: Array) -> Array:
    """Signed (shoulder m, elbow rad, wrist rad) measures; magnitudes are the margins."""
    r, v = _arm_plane(model, q)
    l3 = math.hypot(model.a[2], model.d[3])
    elbow = math.asin(max(-1.0, min(1.0, v / l3)))
    s5 = math.sin(float(q[4]))
    wrist = math.asin(max(-1.0, min(1.0, s5)))
    return np.array([r, elbow, wrist])


def singular_region(model: ArmModel, q: Array) -> tuple[Singularity, float] | None:
    """The first singular region ``q`` is in, with its margin, or None."""
    m = np.abs(singularity_measures(model, q))
    for kind, value, limit in zip(Singularity, m, SINGULAR_THRESHOLDS, strict=True):
        if value < limit:
            return kind, float(value)
    return None


def branch(model: ArmModel, q: Array) -> tuple[int, int, int]:
    """Configuration signs (shoulder, elbow, wrist): the closed form's eight branches."""
    m = singularity_measures(model, q)
    return (int(np.sign(m[0])), int(np.sign(m[1])), int(np.sign(m[2])))


def wrap_to_limits(model: ArmModel, joint: int, angle: float, near: float) -> float | None:
    """The angle + 2*pi*k inside joint ``joint``'s (0-based) limits nearest ``near``, or None."""
    lo, hi = model.lower[joint] - _LIMIT_SLACK, model.upper[joint] + _LIMIT_SLACK
    best: float | None = None
    for k in (-2, -1, 0, 1, 2):
        cand = angle + 2.0 * math.pi * k
        if lo <= cand <= hi and (best is None or abs(cand - near) < abs(best - near)):
            best = cand
    return best


def check_limits(model: ArmModel, q: Array) -> None:
    """Raise JOINT_LIMIT (aux: joint 1..6, angle, lower, upper) for the first joint outside."""
    for j in range(6):
        angle = float(q[j])
        if not model.lower[j] - _LIMIT_SLACK <= angle <= model.upper[j] + _LIMIT_SLACK:
            raise CommandFailed(
                FailureReason.JOINT_LIMIT,
                f"joint {j + 1} would be at {math.degrees(angle):.1f} deg, outside its range "
                f"{math.degrees(model.lower[j]):.0f}..{math.degrees(model.upper[j]):.0f} deg",
                aux=(float(j + 1), angle, model.lower[j], model.upper[j]),
            )


def _wrist_angles(r36: Array, q4_ref: float) -> list[tuple[float, float, float]]:
    """(q4, q5, q6) pairs with Rz(q4) Ry(-q5) Rz(q6) = r36 (both wrist flips)."""
    c5 = max(-1.0, min(1.0, float(r36[2, 2])))
    s5 = math.hypot(float(r36[0, 2]), float(r36[1, 2]))
    if s5 < 1e-9:
        # Joints 4 and 6 aligned: only their sum (or difference) is defined;
        # keep joint 4 where it is and give the rest to joint 6 (seed 004).
        if c5 > 0:
            return [(q4_ref, 0.0, math.atan2(float(r36[1, 0]), float(r36[0, 0])) - q4_ref)]
        return [(q4_ref, math.pi, q4_ref - math.atan2(float(r36[1, 0]), -float(r36[0, 0])))]
    q5 = math.atan2(s5, c5)
    q4 = math.atan2(-float(r36[1, 2]), -float(r36[0, 2]))
    q6 = math.atan2(-float(r36[2, 1]), float(r36[2, 0]))
    return [(q4, q5, q6), (q4 + math.pi, -q5, q6 + math.pi)]


def inverse_candidates(model: ArmModel, target: Array, q_ref: Array) -> list[Array]:
    """All closed-form solutions (up to 8, angles unwrapped) for a hand frame.

    Raises UNREACHABLE (aux: wrist-centre distance from the shoulder, the
    shortest and longest reach, the wrist centre's distance from the joint-1
    axis; metres) when the wrist centre cannot be placed.
    """
    a2, a3, d3, d4 = model.a[1], model.a[2], model.d[2], model.d[3]
    rot = target[:3, :3]
    wx, wy, wz = target[:3, 3] - model.tool_length * rot[:, 2]
    rho = math.hypot(wx, wy)
    l3 = math.hypot(a3, d4)
    reach = math.sqrt(wx * wx + wy * wy + wz * wz)
    near_reach = math.sqrt(max(0.0, (a2 - l3) ** 2 + d3 * d3))
    far_reach = math.sqrt((a2 + l3) ** 2 + d3 * d3)

    def unreachable(why: str) -> CommandFailed:
        return CommandFailed(
            FailureReason.UNREACHABLE,
            f"the hand pose is out of reach: {why}; choose a point nearer the workspace",
            aux=(reach, near_reach, far_reach, rho),
        )

    if rho < d3:
        raise unreachable(f"the wrist centre is {rho:.3f} m from the base axis (< {d3} m)")
    phi = math.atan2(wy, wx)
    alpha = math.asin(d3 / rho)
    beta = math.atan2(d4, a3)
    out: list[Array] = []
    for q1 in (phi + alpha, phi + math.pi - alpha):
        c1, s1 = math.cos(q1), math.sin(q1)
        r = wx * c1 + wy * s1
        h = float(wz)
        k = (r * r + h * h - a2 * a2 - l3 * l3) / (2.0 * a2 * l3)
        if abs(k) > 1.0 + 1e-12:
            raise unreachable(f"the wrist centre is {reach:.3f} m from the shoulder")
        gamma = math.acos(max(-1.0, min(1.0, k)))
        for q3 in (gamma - beta, -gamma - beta):
            u = a2 + a3 * math.cos(q3) - d4 * math.sin(q3)
            v = a3 * math.sin(q3) + d4 * math.cos(q3)
            q2 = math.atan2(h, r) - math.atan2(v, u)
            r03 = (
                _dh(model.a[0], model.alpha[0], model.d[0], q1)
                @ _dh(model.a[1], model.alpha[1], model.d[1], q2)
                @ _dh(model.a[2], model.alpha[2], model.d[2], q3)
            )[:3, :3]
            for q4, q5, q6 in _wrist_angles(r03.T @ rot, float(q_ref[3])):
                out.append(np.array([q1, q2, q3, q4, q5, q6]))
    return out


def inverse(
    model: ArmModel,
    target: Array,
    q_ref: Array,
    *,
    keep_branch: tuple[int, int, int] | None = None,
) -> Array:
    """The joint angles for a hand frame, nearest ``q_ref`` in time, within the limits.

    "Nearest" is the closed form's branch whose motion from ``q_ref`` is
    shortest at the joints' maximum velocities (seed 000's duration rule);
    each joint's 2*pi alternatives within its range are considered.  With
    ``keep_branch`` only solutions in that configuration (see :func:`branch`)
    qualify: the arm keeps its pose (seed 004).  Raises UNREACHABLE, or
    JOINT_LIMIT (aux of the nearest branch's first joint outside its range)
    when no solution fits the limits.
    """
    vmax = np.asarray(model.max_velocity)
    ranked: list[tuple[float, Array]] = []
    nearest_violation: tuple[float, Array] | None = None
    for raw in inverse_candidates(model, target, q_ref):
        if keep_branch is not None and branch(model, raw) != keep_branch:
            continue
        fitted = [wrap_to_limits(model, j, float(raw[j]), float(q_ref[j])) for j in range(6)]
        if any(f is None for f in fitted):
            # Remember the branch closest to the reference for the error report.
            wrapped = q_ref + np.array(
                [math.remainder(float(raw[j] - q_ref[j]), 2 * math.pi) for j in range(6)]
            )
            dist = float(np.max(np.abs(wrapped - q_ref) / vmax))
            if nearest_violation is None or dist < nearest_violation[0]:
                nearest_violation = (dist, wrapped)
            continue
        q = np.array(fitted, dtype=np.float64)
        delta = np.abs(q - q_ref)
        ranked.append((float(np.max(delta / vmax)) + 1e-6 * float(np.sum(delta)), q))
    ranked.sort(key=lambda item: item[0])
    for _cost, q in ranked:
        # The closed form is exact up to round-off; the check guards the
        # clamped acos/asin at the edges of the workspace.
        residual = hand_frame(model, q) - target
        if float(np.max(np.abs(residual[:3, :]))) <= _IK_RESIDUAL:
            return q
    if nearest_violation is not None:
        check_limits(model, nearest_violation[1])
    raise CommandFailed(
        FailureReason.UNREACHABLE,
        "no inverse-kinematics solution reproduces the hand pose; choose another orientation",
        aux=(0.0, 0.0, 0.0, 0.0),
    )


def rotation_about(rotvec: Array) -> Array:
    """The rotation matrix for a rotation vector (axis times angle, rad; Rodrigues)."""
    angle = float(np.linalg.norm(rotvec))
    if angle == 0.0:
        return np.eye(3)
    k = rotvec / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.asarray(np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx)
