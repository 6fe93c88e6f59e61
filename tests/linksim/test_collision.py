"""Seed 000's collision check: segments against boxes, earliest checkpoint/link/obstacle."""

from __future__ import annotations

import numpy as np
from hypothesis import example, given
from hypothesis import strategies as st

from linksim.arm import PUMA560
from linksim.arm._collision import Collision, first_collision, segments_hit_boxes
from linksim.arm._kinematics import link_points

coord = st.floats(-1.0, 1.0, allow_nan=False)
point = st.tuples(coord, coord, coord).map(np.array)


def box_strategy() -> st.SearchStrategy[np.ndarray]:
    def build(lo: np.ndarray, size: np.ndarray) -> np.ndarray:
        hi = lo + size
        return np.array([lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]])

    sizes = st.tuples(*(st.floats(0.01, 1.0),) * 3).map(np.array)
    return st.builds(build, point, sizes)


def distance_to_box(points: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Chebyshev distance from each point (n, 3) to the box: 0 exactly when inside.

    Not Euclidean: squaring a gap of 1e-204 underflows to 0 and would put an
    outside point inside (hypothesis found that one).
    """
    lo, hi = box[0::2], box[1::2]
    return np.asarray(np.maximum(0.0, np.maximum(lo - points, points - hi)).max(axis=1))


@given(point, point, box_strategy())
@example(np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), np.array([0, 1, 0, 1, 0.5, 0.6]))
@example(np.array([-1.0, 0.5, 0.5]), np.array([1.0, 0.5, 0.5]), np.array([0, 1, 0, 1, 0, 1.0]))
@example(np.zeros(3), np.zeros(3), np.array([0, 1, 0, 1, 2.34820417e-204, 1.0]))
def test_slab_test_agrees_with_the_closest_point(
    back: np.ndarray, front: np.ndarray, box: np.ndarray
) -> None:
    hit = bool(segments_hit_boxes(back, front, box[None, :])[0])
    # Independent oracle: the distance from the box to 2001 points on the segment.
    lam = np.linspace(0.0, 1.0, 2001)[:, None]
    nearest = float(distance_to_box(back + lam * (front - back), box).min())
    step = float(np.linalg.norm(front - back)) / 2000
    if hit:
        assert nearest <= step  # some point of the segment is within one step of the box
    else:
        assert nearest > 0.0


def test_a_segment_touching_a_face_collides_and_one_beside_it_does_not() -> None:
    box = np.array([[0.0, 1.0, 0.0, 1.0, 0.0, 1.0]])
    touching = segments_hit_boxes(np.array([2.0, 0.5, 1.0]), np.array([-1.0, 0.5, 1.0]), box)
    beside = segments_hit_boxes(np.array([2.0, 0.5, 1.001]), np.array([-1.0, 0.5, 1.001]), box)
    short = segments_hit_boxes(np.array([2.0, 0.5, 0.5]), np.array([1.01, 0.5, 0.5]), box)
    assert touching.tolist() == [True]
    assert beside.tolist() == [False]
    assert short.tolist() == [False]


def test_first_collision_reports_earliest_point_then_link_then_obstacle() -> None:
    q0 = np.array([0.0, np.radians(90), np.radians(-200), 0.0, np.radians(-70), 0.0])
    pts = link_points(PUMA560, q0)
    hand = pts[-1]
    # Two boxes around the hand point: both hit, the lower index is reported.
    boxes = np.array(
        [
            [10, 11, 10, 11, 10, 11],
            [
                hand[0] - 0.01,
                hand[0] + 0.01,
                hand[1] - 0.01,
                hand[1] + 0.01,
                hand[2] - 0.01,
                hand[2] + 0.01,
            ],
            [
                hand[0] - 0.02,
                hand[0] + 0.02,
                hand[1] - 0.02,
                hand[1] + 0.02,
                hand[2] - 0.02,
                hand[2] + 0.02,
            ],
        ]
    )
    far = q0 + np.array([1.0, 0, 0, 0, 0, 0])
    checkpoints = np.stack([far, far, q0, q0])
    assert first_collision(PUMA560, checkpoints, boxes) == Collision(link=6, obstacle=1, point=3)
    assert first_collision(PUMA560, checkpoints[:2], boxes) is None
    assert first_collision(PUMA560, checkpoints, boxes[:0]) is None


def test_clearance_grows_every_box() -> None:
    q0 = np.array([0.0, np.radians(90), np.radians(-200), 0.0, np.radians(-70), 0.0])
    hand = link_points(PUMA560, q0)[-1]
    # A box 5 cm below the hand point.
    box = np.array(
        [[hand[0] - 0.1, hand[0] + 0.1, hand[1] - 0.1, hand[1] + 0.1, -1.0, hand[2] - 0.05]]
    )
    assert first_collision(PUMA560, q0[None, :], box, clearance=0.04) is None
    assert first_collision(PUMA560, q0[None, :], box, clearance=0.06) == Collision(6, 0, 1)
