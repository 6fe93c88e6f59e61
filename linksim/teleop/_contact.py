"""The wrist force/torque sensor's world: a table, boxes and a block with a hole.

Penalty contact: where the tool point has gone ``depth`` into a surface with
outward normal ``n`` at speed ``v``, the surface pushes back with
``(k depth - b v.n) n`` (never pulling).  The hand carries a peg of radius
``peg_radius`` whose tip is the hand point P; the sensor sits at the wrist
centre, so the torque it reads is (P - wrist) x F.  Pure numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["ContactModel", "Hole", "Wrench"]

Array = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class Hole:
    """A block on the table with a round, chamfered hole (the peg task)."""

    centre: tuple[float, float]
    """x, y of the hole's axis (m, base frame)."""
    top: float
    """z of the block's top face (m)."""
    radius: float = 0.011
    depth: float = 0.04
    chamfer: float = 0.004
    """45-degree chamfer width at the mouth (m)."""
    half_width: float = 0.08
    """The block's half extent in x and y (m)."""


@dataclass(frozen=True, slots=True)
class Wrench:
    force: Array
    torque: Array
    contact: bool
    depth: float

    @property
    def magnitude(self) -> float:
        return float(np.linalg.norm(self.force))


@dataclass(frozen=True, slots=True)
class ContactModel:
    """Surfaces and their stiffness: the table plane, boxes, a hole block."""

    table_z: float
    boxes: tuple[tuple[float, float, float, float, float, float], ...] = ()
    hole: Hole | None = None
    stiffness: float = 20_000.0
    """N/m: a wooden table top against a steel peg, softened by the sensor's own compliance."""
    damping: float = 150.0
    """N s/m: dissipates impacts (about 0.2 of critical for a 2 kg hand)."""
    peg_radius: float = 0.010

    def _surfaces(self, p: Array) -> list[tuple[float, Array]]:
        """(depth, outward normal) for every surface P is inside."""
        found: list[tuple[float, Array]] = []
        up = np.array([0.0, 0.0, 1.0])
        if p[2] < self.table_z:
            found.append((self.table_z - float(p[2]), up))
        for box in self.boxes:
            lo, hi = np.array(box[:3]), np.array(box[3:])
            if bool(np.all(p > lo)) and bool(np.all(p < hi)):
                gaps = np.concatenate([p - lo, hi - p])
                k = int(np.argmin(gaps))
                n = np.zeros(3)
                n[k % 3] = -1.0 if k < 3 else 1.0
                found.append((float(gaps[k]), n))
        if self.hole is not None:
            found += self._hole(p)
        return found

    def _hole(self, p: Array) -> list[tuple[float, Array]]:
        h = self.hole
        assert h is not None
        dx, dy = float(p[0]) - h.centre[0], float(p[1]) - h.centre[1]
        if abs(dx) > h.half_width or abs(dy) > h.half_width or p[2] >= h.top:
            return []
        below = h.top - float(p[2])
        d = math.hypot(dx, dy)
        radial = np.array([dx / d, dy / d, 0.0]) if d > 1e-12 else np.array([1.0, 0.0, 0.0])
        free = h.radius - self.peg_radius  # clearance of the peg in the bore
        mouth = free + h.chamfer
        allowed = free + max(0.0, h.chamfer - below)
        up = np.array([0.0, 0.0, 1.0])
        # The block around the bore is one solid: the peg leaves it through the nearest of
        # the top face, the chamfer and the wall.  The bore's bottom is another surface at
        # a corner with the wall: both push, so no push appears or vanishes with a jump.
        solid: list[tuple[float, Array]] = []
        if d > mouth:
            solid.append((below, up))
        if d > allowed:
            if below < h.chamfer:  # the 45-degree chamfer
                solid.append(((d - allowed) / math.sqrt(2.0), (-radial + up) / math.sqrt(2.0)))
            else:
                solid.append((d - allowed, -radial))
        found = [min(solid, key=lambda f: f[0])] if solid else []
        if below >= h.depth and d <= mouth:
            found.append((below - h.depth, up))
        return found

    def wrench(self, p: Array, v: Array, wrist: Array) -> Wrench:
        """The sensor's reading with the tool point at ``p`` moving at ``v``."""
        force = np.zeros(3)
        deepest = 0.0
        for depth, n in self._surfaces(p):
            push = self.stiffness * depth - self.damping * float(v @ n)
            if push > 0.0:
                force += push * n
            deepest = max(deepest, depth)
        torque = np.cross(p - wrist, force)
        return Wrench(force, torque, bool(deepest > 0.0), deepest)
