"""Seed 000's obstacle check: links as line segments against axis-aligned boxes.

"All obstacle data are stored in an n x 6 array ... each row of the form
(Xmin, Xmax, Ymin, Ymax, Zmin, Zmax)" and each link is the line
P = B + lambda (F - B), lambda in [0, 1].  "The collision detection algorithm
works through the obstacle array dimension by dimension, and finds the
limiting values of lambda necessary for collision": on each axis the segment
is inside the box's slab for a lambda interval; a collision exists when the
three intervals and [0, 1] share a point.  Vectorised over checkpoints,
links and obstacles at once.  Pure numpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._kinematics import LINK_SEGMENTS, ArmModel, Array, hand_frame, link_points

__all__ = ["LOAD_CONTACT_SLACK", "Collision", "Load", "first_collision", "segments_hit_boxes"]


@dataclass(frozen=True, slots=True)
class Collision:
    """Where a planned motion would collide.

    ``link`` is the link number (1..6, see :data:`LINK_SEGMENTS`),
    ``obstacle`` the row of the obstacle array (0-based), ``point`` the
    trajectory checkpoint (1..20).
    """

    link: int
    obstacle: int
    point: int


def segments_hit_boxes(back: Array, front: Array, boxes: Array) -> Array:
    """Boolean (..., n) array: does segment back -> front touch each box?

    ``back`` and ``front`` have shape (..., 3); ``boxes`` shape (n, 6) in
    seed 000's row order (xmin, xmax, ymin, ymax, zmin, zmax).  Touching a
    face counts as a collision.
    """
    b = back[..., None, :]
    d = (front - back)[..., None, :]
    lo = boxes[:, 0::2]
    hi = boxes[:, 1::2]
    # Division by a zero or subnormal component gives +-inf or nan; both are
    # replaced below (parallel) or order correctly (inf).
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t1 = (lo - b) / d
        t2 = (hi - b) / d
    parallel = d == 0.0
    # A segment parallel to an axis is inside that slab for every lambda or none.
    inside = (lo <= b) & (b <= hi)
    enter = np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
    leave = np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
    lam_lo = np.maximum(enter.max(axis=-1), 0.0)
    lam_hi = np.minimum(leave.min(axis=-1), 1.0)
    return np.asarray(lam_lo <= lam_hi)


@dataclass(frozen=True, slots=True)
class Load:
    """An object held in the hand: its centre in the hand frame (m) and its size (m).

    For the collision check it is the segment through its centre along the
    approach vector A, as long as the object less :data:`LOAD_CONTACT_SLACK`
    at each end, and counts as part of link 6.
    """

    offset: Array
    size: float


LOAD_CONTACT_SLACK = 0.001
"""Metres trimmed off each end of a held object's segment, and it is checked
without the links' clearance: the object touches the surface it was picked
from (or is put down on), and that contact is not a collision."""


def first_collision(
    model: ArmModel,
    checkpoints: Array,
    obstacles: Array,
    clearance: float = 0.0,
    load: Load | None = None,
) -> Collision | None:
    """The earliest (checkpoint, link, obstacle) collision of a planned motion, or None.

    ``checkpoints`` (k, 6) are the joint vectors at the trajectory's check
    points, numbered 1..k in order; ``obstacles`` (n, 6) rows as in
    :func:`segments_hit_boxes`, grown by ``clearance`` metres on every side
    (the links' thickness).  A ``load`` in the hand is checked too, as link 6.
    """
    if len(obstacles) == 0 or len(checkpoints) == 0:
        return None
    grown = obstacles + np.array([-1.0, 1.0, -1.0, 1.0, -1.0, 1.0]) * clearance
    pts = np.stack([link_points(model, q) for q in checkpoints])  # (k, 5, 3)
    back = pts[:, [s[1] for s in LINK_SEGMENTS], :]
    front = pts[:, [s[2] for s in LINK_SEGMENTS], :]
    hits = segments_hit_boxes(back, front, grown)  # (k, links, n)
    links = [s[0] for s in LINK_SEGMENTS]
    if load is not None:
        frames = np.stack([hand_frame(model, q) for q in checkpoints])  # (k, 4, 4)
        centre = frames[:, :3, :3] @ load.offset + frames[:, :3, 3]
        half = max(0.0, load.size / 2.0 - LOAD_CONTACT_SLACK) * frames[:, :3, 2]
        held = segments_hit_boxes(centre - half, centre + half, obstacles)  # (k, n)
        hits = np.concatenate([hits, held[:, None, :]], axis=1)
        links.append(6)
    if not hits.any():
        return None
    point, link, obstacle = (int(i[0]) for i in np.nonzero(hits))
    return Collision(links[link], obstacle, point + 1)
