"""Trajectories: seed 000's quintic joint moves and seed 003's Level-2 blended paths.

Pure numpy, time in seconds, quantised to control samples of ``1 / rate_hz``.

Joint moves (seed 000, "Planning")
    "All links begin and end motion simultaneously, with the duration of
    motion determined by scaling with respect to the maximum allowed velocity
    for the slowest link ... All joints are then moved according to a single
    normalized polynomial": theta(u) = theta0 + dtheta g(u), u: 0 -> 1, with
    g monotonic and zero first and second derivatives at both ends.  Here g
    is the quintic 10u^3 - 15u^4 + 6u^5, whose peak slope is 15/8: a joint
    that moves dtheta in time T peaks at 15/8 dtheta/T, so T = 15/8 *
    max_j |dtheta_j| / v_j makes the slowest joint touch its allowed velocity
    v_j and every other joint stay below its own.

Via-point paths (seed 003, section 5, "Remote - Level 2")
    Straight segments joined by parabolic blends of constant acceleration
    (v_{i+1} - v_i) / (2 tau), zero-length segments added at both ends so the
    hand starts and stops at rest, integrated as the paper's sampled-data
    equations p(k+1) = p(k) + v(k) dt + 1/2 a(k) dt^2, v(k+1) = v(k) + a(k) dt,
    with position and velocity reset to their exact values at the start of
    every straight segment (the paper's drift correction).  Every segment and
    blend boundary falls on a sample, so the acceleration is constant within
    each sample and the integration is exact up to round-off.  As in Paul's
    method the blends round the corners: the hand passes within
    |v_{i+1} - v_i| tau / 4 of an intermediate via point, and reaches the last
    one exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._kinematics import Array

__all__ = [
    "CHECKPOINTS",
    "QUINTIC_PEAK_RATE",
    "BlendedPath",
    "JointMove",
    "checkpoint_samples",
    "integrate_path",
    "plan_joint_move",
    "plan_path",
    "quintic",
    "quintic_acceleration",
    "quintic_rate",
]

CHECKPOINTS = 20
"""Seed 000: "we check for collisions at twenty points along the trajectory"."""

QUINTIC_PEAK_RATE = 15.0 / 8.0
"""max over u of g'(u) for the quintic g, reached at u = 1/2."""


def quintic(u: Array | float) -> Array:
    """g(u) = 10u^3 - 15u^4 + 6u^5: 0 -> 1, g' = g'' = 0 at both ends, monotonic."""
    return np.asarray(u * u * u * (10.0 + u * (-15.0 + 6.0 * u)), dtype=np.float64)


def quintic_rate(u: Array | float) -> Array:
    """g'(u) = 30u^2 (1 - u)^2."""
    return np.asarray(30.0 * u * u * (1.0 - u) ** 2, dtype=np.float64)


def quintic_acceleration(u: Array | float) -> Array:
    """g''(u) = 60u (1 - u)(1 - 2u)."""
    return np.asarray(60.0 * u * (1.0 - u) * (1.0 - 2.0 * u), dtype=np.float64)


@dataclass(frozen=True, slots=True)
class JointMove:
    """One seed-000 move: ``start + delta * g(k / samples)`` at sample k = 1..samples.

    The last sample is ``goal`` itself (not ``start + delta``, which may
    differ from it in the last bit).
    """

    start: Array
    goal: Array
    samples: int
    rate_hz: float

    @property
    def delta(self) -> Array:
        return np.asarray(self.goal - self.start, dtype=np.float64)

    @property
    def duration(self) -> float:
        """Seconds from start to rest (a whole number of samples)."""
        return self.samples / self.rate_hz

    def at(self, k: int) -> Array:
        """The joint vector at sample ``k`` (0 is the start, ``samples`` the goal)."""
        if self.samples == 0 or k >= self.samples:
            return self.goal
        u = k / self.samples
        g = u * u * u * (10.0 + u * (-15.0 + 6.0 * u))
        return np.asarray(self.start + g * self.delta, dtype=np.float64)

    def at_fraction(self, u: Array) -> Array:
        """Joint vectors (len(u), n) at normalised times ``u`` in [0, 1]."""
        return np.asarray(self.start + np.outer(quintic(u), self.delta), dtype=np.float64)


def plan_joint_move(
    start: Array, goal: Array, max_velocity: Array, speed: float, rate_hz: float
) -> JointMove:
    """Time a move so the slowest joint peaks at ``speed`` times its allowed velocity.

    The duration is rounded up to whole samples (so no joint exceeds its
    allowed velocity); a move of zero length takes zero samples.
    """
    if not 0.0 < speed <= 1.0:
        raise ValueError(f"speed must be in (0, 1], got {speed}")
    delta = np.asarray(goal - start, dtype=np.float64)
    seconds = QUINTIC_PEAK_RATE * float(np.max(np.abs(delta) / (speed * max_velocity)))
    # 1e-9: a duration that is a whole number of samples up to round-off
    # must not gain a sample.
    samples = math.ceil(seconds * rate_hz - 1e-9) if seconds > 0 else 0
    if seconds > 0:
        samples = max(samples, 1)
    return JointMove(
        np.asarray(start, dtype=np.float64), np.asarray(goal, dtype=np.float64), samples, rate_hz
    )


def checkpoint_samples(total: int, count: int = CHECKPOINTS) -> list[int]:
    """The sample index of each of ``count`` evenly spaced checkpoints (the last is the goal).

    Checkpoint i (1-based) is at ``round(i * total / count)``; a short move
    has fewer distinct samples than checkpoints, so indices may repeat.
    """
    return [round(i * total / count) for i in range(1, count + 1)]


@dataclass(frozen=True, slots=True)
class BlendedPath:
    """A Level-2 path; ``points[0]`` is the start and ``points[-1]`` the goal.

    ``junction`` holds the sample at which the nominal straight lines meet at
    each point (junction j joins segment j and j + 1, segment 0 and the last
    being the added zero-length ones); ``velocity[j]`` is segment j's
    constant velocity (m/s); blends last ``2 * tau`` samples around each
    junction.
    """

    points: Array
    junction: tuple[int, ...]
    velocity: Array
    tau: int
    rate_hz: float

    @property
    def samples(self) -> int:
        """Samples from start to rest: the last junction plus half a blend."""
        return self.junction[-1] + self.tau

    @property
    def duration(self) -> float:
        return self.samples / self.rate_hz

    def _phase(self, k: float) -> tuple[int, bool]:
        """(j, in_blend): in junction j's blend, or on the straight part of segment j."""
        for j, tj in enumerate(self.junction):
            if k <= tj + self.tau:
                return j, k >= tj - self.tau
        return len(self.junction) - 1, True

    def acceleration(self, j: int) -> Array:
        """The constant acceleration (m/s^2) of blend j."""
        dt2tau = 2.0 * self.tau / self.rate_hz
        return np.asarray((self.velocity[j + 1] - self.velocity[j]) / dt2tau, dtype=np.float64)

    def position(self, k: float) -> Array:
        """The exact position at sample time ``k``."""
        k = min(max(k, 0.0), float(self.samples))
        j, blend = self._phase(k)
        dt = 1.0 / self.rate_hz
        t = (k - self.junction[j]) * dt
        if blend:
            since = (k - self.junction[j] + self.tau) * dt
            return np.asarray(
                self.points[j] + self.velocity[j] * t + 0.5 * self.acceleration(j) * since**2,
                dtype=np.float64,
            )
        # Before junction j's blend: on segment j, which ends at points[j].
        return np.asarray(self.points[j] + self.velocity[j] * t, dtype=np.float64)

    def speed(self, k: float) -> Array:
        """The exact velocity (m/s) at sample time ``k``."""
        k = min(max(k, 0.0), float(self.samples))
        j, blend = self._phase(k)
        if blend:
            since = (k - self.junction[j] + self.tau) / self.rate_hz
            return np.asarray(self.velocity[j] + self.acceleration(j) * since, dtype=np.float64)
        return np.asarray(self.velocity[j], dtype=np.float64)


def plan_path(
    start: Array, vias: Array, speed: float, blend_time: float, rate_hz: float
) -> BlendedPath:
    """Plan straight segments ``start -> vias[0] -> ... -> vias[-1]`` at ``speed`` m/s.

    Each blend lasts ``blend_time`` seconds (2 tau, at least two samples);
    each segment lasts long enough to keep the hand at or below ``speed`` and
    at least one blend time, so neighbouring blends never overlap.
    """
    if speed <= 0 or blend_time <= 0:
        raise ValueError("speed and blend time must be > 0")
    points = np.vstack([np.asarray(start, dtype=np.float64)[None, :], vias])
    tau = max(1, round(blend_time * rate_hz / 2.0))
    per_sample = speed / rate_hz
    n = len(points) - 1
    durations = []
    for i in range(1, n + 1):
        length = float(np.linalg.norm(points[i] - points[i - 1]))
        durations.append(max(math.ceil(length / per_sample - 1e-9), 2 * tau))
    junction = [tau]
    for d in durations:
        junction.append(junction[-1] + d)
    velocity = np.zeros((n + 2, points.shape[1]))
    for i, d in enumerate(durations, start=1):
        velocity[i] = (points[i] - points[i - 1]) * rate_hz / d
    return BlendedPath(points, tuple(junction), velocity, tau, rate_hz)


def integrate_path(path: BlendedPath) -> tuple[Array, Array, int]:
    """Seed 003's sampled-data integration with drift correction.

    Returns ``(positions, velocities, corrections)``: arrays of shape
    (samples + 1, dim) for samples 0..samples, and how many times the state
    was reset to its exact value at the start of a straight segment.
    """
    dt = 1.0 / path.rate_hz
    n = path.samples
    dim = path.points.shape[1]
    pos = np.empty((n + 1, dim))
    vel = np.empty((n + 1, dim))
    pos[0] = path.points[0]
    vel[0] = 0.0
    # The sample at which each straight segment starts (a blend ends).
    straight_start = {tj + path.tau: j for j, tj in enumerate(path.junction)}
    blend_of = np.full(n, -1)
    for j, tj in enumerate(path.junction):
        blend_of[max(0, tj - path.tau) : min(n, tj + path.tau)] = j
    accel = [path.acceleration(j) for j in range(len(path.junction))]
    corrections = 0
    for k in range(n):
        a = accel[blend_of[k]] if blend_of[k] >= 0 else 0.0
        pos[k + 1] = pos[k] + vel[k] * dt + 0.5 * a * dt * dt
        vel[k + 1] = vel[k] + a * dt
        if k + 1 in straight_start:
            j = straight_start[k + 1]
            pos[k + 1] = path.points[j] + path.velocity[j + 1] * path.tau * dt
            vel[k + 1] = path.velocity[j + 1]
            corrections += 1
    return pos, vel, corrections
