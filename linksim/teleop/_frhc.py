"""JPL's Force-Reflecting Hand Controller (FRHC): seed 004's appendix, and its encoders.

The appendix gives the FRHC in Craig's (modified) Denavit-Hartenberg form; the
scan is damaged, and this is our reading of it, checked against its link
matrices M1..M6 and its Jacobian (whose third column has no rotation part:
joint 3 slides):

====  ==========  ==========  ======================  =========  ===============
 i    alpha(i-1)  a(i-1)      d(i)                    theta(i)   initial setting
====  ==========  ==========  ======================  =========  ===============
 1     0          0           0                       theta1       0
 2     90 deg     0           0                       theta2     -90 deg
 3    -90 deg     0           d3 + dz_offset (slides)  0            d3 = 0
 4     0          0           0                       theta4       0
 5    -90 deg     0           0                       theta5     -90 deg
 6     90 deg     0           0                       theta6       0
====  ==========  ==========  ======================  =========  ===============

dz_offset = 730.25 mm.  The handle sits at the wrist centre (the origin of
frames 4-6), r = d3 + dz_offset from the shoulder.  Seed 004: "AX information
is computed by premultiplying the A-theta angular values with the hand
controller Jacobian"; the A-theta come from "differencing two successive
encoder values" (no velocity estimator), which :class:`HandController` does
with quantised encoders.  Reflected forces go back as motor torques
tau = J^T F, limited to the FRHC's 8 lb (35.6 N) and 14 in-lb (1.58 N m) per
axis.  Pure numpy; no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

__all__ = [
    "DZ_OFFSET",
    "FRHC_INITIAL",
    "WORKSPACE_REACH",
    "WORKSPACE_TURN",
    "HandController",
    "frhc_deflection",
    "frhc_frames",
    "frhc_jacobian",
    "frhc_pose",
    "in_workspace",
    "rotvec",
]

Array = npt.NDArray[np.float64]

DZ_OFFSET = 0.73025
"""m: the appendix's dz_offset."""
_ALPHA = (0.0, math.pi / 2, -math.pi / 2, 0.0, -math.pi / 2, math.pi / 2)
FRHC_INITIAL = np.array([0.0, -math.pi / 2, 0.0, 0.0, -math.pi / 2, 0.0])
"""The appendix's initial settings (theta1, theta2, d3, theta4, theta5, theta6)."""
ENCODER_COUNTS = 2**14
"""Counts per revolution of the angle encoders (the slide: 10 um a count)."""
SLIDE_COUNT = 1.0e-5
MAX_FORCE = 35.6
"""N per axis: "capable of generating 8 lbs of force ... in each DOF"."""
MAX_TORQUE = 1.58
"""N m per axis: 14 in-lb."""
WORKSPACE_REACH = 0.15
"""m: the handle stays within this of its neutral position along each base axis (a
0.30 m cube).  The appendix gives no workspace: this is our model's, about a cubic
foot in front of the operator; beyond it the operator re-centres with the index
clutch (seed 004's way of extending the workspace)."""
WORKSPACE_TURN = math.pi / 2
"""rad: the handle turns at most this far from its neutral orientation (our model's)."""


def _craig(alpha: float, d: float, theta: float) -> Array:
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st, 0.0, 0.0],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def frhc_frames(q: Array) -> list[Array]:
    """Frames 0..6 in the FRHC base frame (q = theta1, theta2, d3, theta4, theta5, theta6)."""
    frames = [np.eye(4)]
    t = np.eye(4)
    for i in range(6):
        d = float(q[2]) + DZ_OFFSET if i == 2 else 0.0
        theta = 0.0 if i == 2 else float(q[i])
        t = t @ _craig(_ALPHA[i], d, theta)
        frames.append(t)
    return frames


def frhc_pose(q: Array) -> Array:
    """The handle frame (4x4)."""
    return frhc_frames(q)[6]


def frhc_jacobian(q: Array) -> Array:
    """Geometric Jacobian (6x6) at the handle, base frame: rows vx vy vz wx wy wz."""
    f = frhc_frames(q)
    p = f[6][:3, 3]
    jac = np.zeros((6, 6))
    for j in range(6):
        z = f[j + 1][:3, 2]  # Craig: joint j+1 moves about/along z of frame j+1
        if j == 2:
            jac[:3, j] = z
        else:
            jac[:3, j] = np.cross(z, p - f[j + 1][:3, 3])
            jac[3:, j] = z
    return jac


def frhc_deflection(q: Array, neutral: Array | None = None) -> Array:
    """Where joints ``q`` put the handle, as :meth:`HandController.move_handle` takes it:
    position relative to ``neutral`` (m, base frame; default the appendix's initial
    pose) and the rotation vector (rad) that turns the neutral orientation into it."""
    pose = frhc_pose(q)
    ref = frhc_pose(FRHC_INITIAL) if neutral is None else neutral
    return np.concatenate([pose[:3, 3] - ref[:3, 3], rotvec(pose[:3, :3] @ ref[:3, :3].T)])


def in_workspace(deflection: Array) -> bool:
    """Whether a handle deflection (position m, rotation vector rad: as
    :func:`frhc_deflection` gives) is inside :data:`WORKSPACE_REACH` and
    :data:`WORKSPACE_TURN`, boundaries included."""
    reach = float(np.max(np.abs(deflection[:3])))
    turn = float(np.linalg.norm(deflection[3:]))
    return reach <= WORKSPACE_REACH and turn <= WORKSPACE_TURN


def rotvec(r: Array) -> Array:
    """The rotation vector (axis times angle) of a rotation matrix."""
    c = max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0))
    angle = math.acos(c)
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    if angle < 1e-9:
        return 0.5 * w
    if math.pi - angle < 1e-6:
        axis = np.sqrt(np.maximum(np.diag(r) + 1.0, 0.0) / 2.0)
        return angle * axis
    return angle / (2.0 * math.sin(angle)) * w


def _quantise(q: Array) -> Array:
    step = np.full(6, 2 * math.pi / ENCODER_COUNTS)
    step[2] = SLIDE_COUNT
    return np.asarray(np.round(q / step) * step)


@dataclass
class HandController:
    """The FRHC in the operator's hand: joints, encoders, buttons, reflected force.

    The operator moves the handle to a place (position in the controller's base
    frame, relative to the neutral pose; orientation as a rotation vector);
    :meth:`move_handle` solves the FRHC's joints for it (damped least squares
    from the present joints, as the mechanism would follow the hand) and reads
    the encoders.  :meth:`increment` is seed 004's dX_h = J dtheta from two
    successive encoder readings.
    """

    q: Array = field(default_factory=lambda: FRHC_INITIAL.copy())
    encoders: Array = field(default_factory=lambda: _quantise(FRHC_INITIAL))
    neutral: Array = field(default_factory=lambda: frhc_pose(FRHC_INITIAL))
    motor_torque: Array = field(default_factory=lambda: np.zeros(6))

    def handle_pose(self) -> Array:
        return frhc_pose(self.q)

    def deflection(self) -> Array:
        """Handle position and rotation vector relative to neutral (base frame)."""
        return frhc_deflection(self.q, self.neutral)

    def move_handle(self, offset: Array, rotation: Array | None = None) -> None:
        """Put the handle at neutral + ``offset`` (m), turned by ``rotation`` (rad)."""
        target_p = self.neutral[:3, 3] + offset
        rot = np.zeros(3) if rotation is None else rotation
        target_r = _rodrigues(rot) @ self.neutral[:3, :3]
        q = self.q.copy()
        for _ in range(8):
            pose = frhc_pose(q)
            err = np.concatenate([target_p - pose[:3, 3], rotvec(target_r @ pose[:3, :3].T)])
            if float(np.max(np.abs(err))) < 1e-9:
                break
            jac = frhc_jacobian(q)
            lam = 1e-6
            q = q + jac.T @ np.linalg.solve(jac @ jac.T + lam * np.eye(6), err)
        self.q = q

    def increment(self) -> tuple[Array, Array]:
        """(dX_h, dtheta) since the last call: encoder differences and J dtheta."""
        now = _quantise(self.q)
        dtheta = now - self.encoders
        self.encoders = now
        return frhc_jacobian(self.q) @ dtheta, dtheta

    def reflect(self, force: Array) -> Array:
        """Back-drive the motors with tau = J^T F (F: force and torque at the handle,
        base frame); returns the force the hand feels after the motor limits."""
        tau = frhc_jacobian(self.q).T @ force
        jac = frhc_jacobian(self.q)
        tau = np.clip(tau, -_tau_limits(jac), _tau_limits(jac))
        self.motor_torque = tau
        return np.asarray(np.linalg.lstsq(jac.T, tau, rcond=None)[0], dtype=np.float64)


def _tau_limits(jac: Array) -> Array:
    # A joint's limit follows from the per-DOF force limits through its lever:
    # what MAX_FORCE and MAX_TORQUE along the handle axes need at that joint.
    return np.asarray(np.abs(jac.T) @ np.array([MAX_FORCE] * 3 + [MAX_TORQUE] * 3))


def _rodrigues(v: Array) -> Array:
    angle = float(np.linalg.norm(v))
    if angle == 0.0:
        return np.eye(3)
    k = v / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.asarray(np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx)
