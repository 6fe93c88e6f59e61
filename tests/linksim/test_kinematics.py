"""PUMA 560 kinematics: published poses, P/S/A frames, IK round trips, failures, singularities."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from linksim.arm import PUMA560, hand_frame, psa
from linksim.arm._kinematics import (
    SINGULAR_THRESHOLDS,
    Singularity,
    branch,
    check_limits,
    frame_from_psa,
    inverse,
    inverse_candidates,
    jacobian,
    link_points,
    rotation_about,
    singular_region,
    singularity_measures,
    wrap_to_limits,
)
from tcpstream import CommandFailed, FailureReason

BARE = dataclasses.replace(PUMA560, tool_length=0.0)
LO = PUMA560.lower_array
HI = PUMA560.upper_array


def joint_vectors() -> st.SearchStrategy[np.ndarray]:
    return st.tuples(
        *(st.floats(lo, hi, allow_nan=False) for lo, hi in zip(LO, HI, strict=True))
    ).map(lambda q: np.array(q, dtype=np.float64))


def away_from_singularities(q: np.ndarray) -> bool:
    return singular_region(PUMA560, q) is None


# Corke, "Robotics, Vision and Control" (2nd ed., section 7.2) and the
# toolbox's p560.fkine: the bare DH chain (no tool) at the named poses.
PUBLISHED = [
    ("qz", (0, 0, 0, 0, 0, 0), np.eye(3), (0.4521, -0.15005, 0.4318)),
    ("qr", (0, math.pi / 2, -math.pi / 2, 0, 0, 0), np.eye(3), (0.0203, -0.15005, 0.8636)),
    (
        "qn",
        (0, math.pi / 4, math.pi, 0, math.pi / 4, 0),
        np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]),
        (0.59627, -0.15005, -0.01435),
    ),
]


@pytest.mark.parametrize(("name", "q", "rot", "pos"), PUBLISHED, ids=[p[0] for p in PUBLISHED])
def test_forward_kinematics_matches_published_poses(
    name: str, q: tuple[float, ...], rot: np.ndarray, pos: tuple[float, float, float]
) -> None:
    t = hand_frame(BARE, np.array(q, dtype=np.float64))
    np.testing.assert_allclose(t[:3, :3], rot, atol=1e-12)
    np.testing.assert_allclose(t[:3, 3], pos, atol=5e-5)
    np.testing.assert_array_equal(t[3], [0.0, 0.0, 0.0, 1.0])


def test_tool_offset_puts_p_along_the_approach_vector() -> None:
    q = np.array([0.3, 0.9, -2.9, 0.4, -0.8, 1.1])
    bare = hand_frame(BARE, q)
    tool = hand_frame(PUMA560, q)
    np.testing.assert_allclose(tool[:3, 3], bare[:3, 3] + 0.20 * bare[:3, 2], atol=1e-15)
    np.testing.assert_array_equal(tool[:3, :3], bare[:3, :3])
    # The last collision point is P, the one before it the wrist centre.
    pts = link_points(PUMA560, q)
    np.testing.assert_allclose(pts[-1], tool[:3, 3], atol=1e-15)
    np.testing.assert_allclose(pts[-2], bare[:3, 3], atol=1e-15)


@given(joint_vectors())
def test_p_s_a_are_an_orthonormal_right_handed_frame(q: np.ndarray) -> None:
    t = hand_frame(PUMA560, q)
    p, s, a = psa(t)
    np.testing.assert_allclose([s @ s, a @ a, s @ a], [1.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(np.cross(s, a), t[:3, 0], atol=1e-12)
    np.testing.assert_allclose(frame_from_psa(p, s, a), t, atol=1e-12)


@given(joint_vectors())
def test_inverse_of_forward_returns_the_same_joints(q: np.ndarray) -> None:
    if not away_from_singularities(q):
        return
    np.testing.assert_allclose(inverse(PUMA560, hand_frame(PUMA560, q), q), q, atol=1e-7)


@given(joint_vectors(), joint_vectors())
def test_inverse_from_anywhere_reproduces_the_pose(q: np.ndarray, ref: np.ndarray) -> None:
    target = hand_frame(PUMA560, q)
    solved = inverse(PUMA560, target, ref)
    np.testing.assert_allclose(hand_frame(PUMA560, solved), target, atol=1e-7)
    check_limits(PUMA560, solved)
    # ... and no slower to reach from ref than the original joints (nearest branch).
    vmax = np.asarray(PUMA560.max_velocity)
    assert np.max(np.abs(solved - ref) / vmax) <= np.max(np.abs(q - ref) / vmax) + 1e-6


@given(joint_vectors())
def test_eight_closed_form_solutions_away_from_singularities(q: np.ndarray) -> None:
    if not away_from_singularities(q):
        return
    target = hand_frame(PUMA560, q)
    sols = inverse_candidates(PUMA560, target, q)
    assert len(sols) == 8
    assert len({branch(PUMA560, s) for s in sols}) == 8
    for s in sols:
        np.testing.assert_allclose(hand_frame(PUMA560, s), target, atol=1e-9)


def test_jacobian_matches_finite_differences() -> None:
    q = np.array([0.2, 1.0, -2.8, 0.5, -0.9, 0.3])
    jac = jacobian(PUMA560, q)
    h = 1e-7
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = h
        t1, t0 = hand_frame(PUMA560, q + dq), hand_frame(PUMA560, q - dq)
        np.testing.assert_allclose(jac[:3, j], (t1[:3, 3] - t0[:3, 3]) / (2 * h), atol=1e-6)
        # Angular part: the skew-symmetric part of dR R^T.
        w = (t1[:3, :3] - t0[:3, :3]) / (2 * h) @ t1[:3, :3].T
        np.testing.assert_allclose(jac[3:, j], [w[2, 1], w[0, 2], w[1, 0]], atol=1e-6)


def test_out_of_reach_is_unreachable_with_the_distances() -> None:
    target = frame_from_psa(np.array([1.5, 0.0, 0.0]), np.array([0, 1.0, 0]), np.array([1.0, 0, 0]))
    with pytest.raises(CommandFailed) as info:
        inverse(PUMA560, target, np.zeros(6))
    assert info.value.reason is FailureReason.UNREACHABLE
    reach, near, far, _rho = info.value.aux
    assert reach == pytest.approx(1.5 - 0.2)
    assert far == pytest.approx(math.hypot(0.4318 + math.hypot(0.0203, 0.4318), 0.15005))
    assert near < far < reach


def test_wrist_centre_inside_the_shoulder_offset_cylinder_is_unreachable() -> None:
    # Wrist centre 0.05 m from the joint-1 axis: closer than d3 = 0.15005 m.
    target = frame_from_psa(
        np.array([0.05, 0.0, 0.5]), np.array([0, 1.0, 0]), np.array([0, 0.0, -1.0])
    )
    with pytest.raises(CommandFailed) as info:
        inverse(PUMA560, target, np.zeros(6))
    assert info.value.reason is FailureReason.UNREACHABLE
    assert info.value.aux[3] == pytest.approx(0.05)


def test_pose_reachable_only_outside_the_limits_is_a_joint_limit() -> None:
    narrow = dataclasses.replace(
        PUMA560, lower=(-0.1, *PUMA560.lower[1:]), upper=(0.1, *PUMA560.upper[1:])
    )
    q = np.array([1.0, 1.2, -3.0, 0.2, -0.8, 0.1])
    with pytest.raises(CommandFailed) as info:
        inverse(narrow, hand_frame(narrow, q), np.zeros(6))
    assert info.value.reason is FailureReason.JOINT_LIMIT
    joint, angle, lo, hi = info.value.aux
    assert (joint, lo, hi) == (1.0, -0.1, 0.1)
    assert abs(angle) > 0.1


def test_check_limits_reports_the_first_joint_outside() -> None:
    q = np.array([0.0, 0.0, 0.0, 0.0, math.radians(101), math.radians(300)])
    with pytest.raises(CommandFailed) as info:
        check_limits(PUMA560, q)
    assert info.value.aux == (5.0, math.radians(101), PUMA560.lower[4], PUMA560.upper[4])
    assert "joint 5" in info.value.message


def test_wrap_to_limits_picks_the_nearest_turn_inside_the_range() -> None:
    # Joint 6 spans +-266 deg: 170 deg or -190 deg, whichever is nearer the reference.
    assert wrap_to_limits(PUMA560, 5, math.radians(170), math.radians(-100)) == pytest.approx(
        math.radians(-190)
    )
    assert wrap_to_limits(PUMA560, 5, math.radians(170), 0.0) == pytest.approx(math.radians(170))
    # Joint 5 spans +-100 deg: 150 deg has no turn inside.
    assert wrap_to_limits(PUMA560, 4, math.radians(150), 0.0) is None


@pytest.mark.parametrize(
    ("q", "kind"),
    [
        ((0.0, 1.0, -2.9, 0.3, 0.0, 0.2), Singularity.WRIST),
        ((0.0, 1.0, -2.9, 0.3, math.pi - 0.01, 0.2), Singularity.WRIST),
        # Forearm in line with the upper arm: q3 = -atan2(d4, a3) + pi / 2.
        ((0.0, 0.5, math.atan2(0.0203, 0.4318) - math.pi / 2, 0.0, 0.7, 0.0), Singularity.ELBOW),
        # Wrist centre straight above the shoulder: r = 0.
        ((0.0, math.pi / 2, -math.pi / 2, 0.0, 0.7, 0.0), Singularity.SHOULDER),
    ],
)
def test_singular_regions_are_named(q: tuple[float, ...], kind: Singularity) -> None:
    region = singular_region(PUMA560, np.array(q))
    assert region is not None
    assert region[0] is kind
    assert region[1] < SINGULAR_THRESHOLDS[kind - 1]


def test_wrist_singular_pose_keeps_joint_4_and_still_solves() -> None:
    q = np.array([0.1, 1.0, -2.9, 0.6, 0.0, 0.2])
    ref = q.copy()
    solved = inverse(PUMA560, hand_frame(PUMA560, q), ref)
    assert solved[3] == pytest.approx(0.6)
    np.testing.assert_allclose(solved, q, atol=1e-9)


def test_rotation_about_matches_axis_angle() -> None:
    np.testing.assert_allclose(
        rotation_about(np.array([0.0, 0.0, math.pi / 2])),
        [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
        atol=1e-15,
    )
    np.testing.assert_array_equal(rotation_about(np.zeros(3)), np.eye(3))


def test_kinematics_planning_and_world_modules_are_pure() -> None:
    """The console's predictive model reuses these without trio or I/O."""
    import ast
    import pathlib

    root = pathlib.Path(__file__).resolve().parents[2] / "linksim" / "arm"
    forbidden = {"trio", "serial", "socket", "time", "random", "threading", "asyncio", "os"}
    for module in ("_kinematics", "_trajectory", "_collision", "_world", "_tasks", "_planner"):
        names: set[str] = set()
        for node in ast.walk(ast.parse((root / f"{module}.py").read_text())):
            if isinstance(node, ast.Import):
                names |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
        assert not names & forbidden, f"linksim/arm/{module}.py imports {names & forbidden}"


@given(joint_vectors())
def test_each_singular_measure_at_zero_is_a_rank_loss_of_the_jacobian(q: np.ndarray) -> None:
    """The analytic measures are where the Jacobian really loses rank."""
    a3, d4 = PUMA560.a[2], PUMA560.d[3]
    exact = []
    wrist = q.copy()
    wrist[4] = 0.0
    exact.append(wrist)
    elbow = q.copy()
    elbow[2] = math.atan2(a3, d4) - math.pi / 2 + math.pi * (q[2] > -math.pi / 2)
    exact.append(elbow)
    # Shoulder: r = u cos q2 - v sin q2 = 0 (wrist centre on the joint-1 axis line).
    shoulder = q.copy()
    u = PUMA560.a[1] + a3 * math.cos(q[2]) - d4 * math.sin(q[2])
    v = a3 * math.sin(q[2]) + d4 * math.cos(q[2])
    shoulder[1] = math.atan2(u, v)
    exact.append(shoulder)
    for s in exact:
        m = singularity_measures(PUMA560, s)
        assert np.min(np.abs(m)) < 1e-9
        assert np.linalg.svd(jacobian(PUMA560, s), compute_uv=False)[-1] < 1e-9
    # Away from every region the Jacobian is comfortably full rank.
    if singular_region(PUMA560, q) is None:
        assert np.linalg.svd(jacobian(PUMA560, q), compute_uv=False)[-1] > 1e-4
