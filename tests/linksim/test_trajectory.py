"""Seed 000's quintic joint moves and seed 003's Level-2 blended paths."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from linksim.arm._trajectory import (
    QUINTIC_PEAK_RATE,
    checkpoint_samples,
    integrate_path,
    plan_joint_move,
    plan_path,
    quintic,
    quintic_acceleration,
    quintic_rate,
)

VMAX = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])
RATE = 125.0


def test_quintic_boundary_conditions() -> None:
    ends = np.array([0.0, 1.0])
    np.testing.assert_array_equal(quintic(ends), [0.0, 1.0])
    np.testing.assert_array_equal(quintic_rate(ends), [0.0, 0.0])
    np.testing.assert_array_equal(quintic_acceleration(ends), [0.0, 0.0])


def test_quintic_is_monotonic_with_the_documented_peak_rate() -> None:
    u = np.linspace(0.0, 1.0, 10001)
    g = quintic(u)
    assert np.all(np.diff(g) > 0)
    assert np.all((g >= 0) & (g <= 1))
    assert quintic_rate(u).max() == pytest.approx(QUINTIC_PEAK_RATE, abs=1e-12)
    # The derivatives are the derivatives.
    inner = slice(1, -1)  # np.gradient is one-sided (first order) at the ends
    np.testing.assert_allclose(np.gradient(g, u)[inner], quintic_rate(u)[inner], atol=1e-6)
    np.testing.assert_allclose(
        np.gradient(quintic_rate(u), u)[inner], quintic_acceleration(u)[inner], atol=1e-5
    )


deltas = st.lists(st.floats(-4.0, 4.0, allow_nan=False), min_size=6, max_size=6).map(np.array)


@given(deltas, st.floats(0.05, 1.0))
def test_joint_move_timed_by_the_slowest_joint(delta: np.ndarray, speed: float) -> None:
    start = np.zeros(6)
    move = plan_joint_move(start, start + delta, VMAX, speed, RATE)
    worst = float(np.max(np.abs(delta) / (speed * VMAX)))
    if worst == 0:
        assert move.samples == 0
        return
    exact = QUINTIC_PEAK_RATE * worst * RATE
    assert exact - 1e-6 <= move.samples <= math.ceil(exact) + 1e-9
    u = np.arange(move.samples + 1) / move.samples
    samples = move.at_fraction(u)
    np.testing.assert_array_equal(samples[0], start)
    np.testing.assert_array_equal(move.at(move.samples), start + delta)
    for k in (1, move.samples // 2, move.samples - 1):
        np.testing.assert_allclose(move.at(k), samples[k], atol=1e-15)
    # All joints follow the one normalised polynomial: they start and stop together
    # and each moves monotonically (never outside its start..goal range).
    steps = np.diff(samples, axis=0) * np.sign(delta)
    assert np.all(steps >= -1e-12)
    # No joint exceeds speed * its maximum velocity; the analytic peak is
    # reached by the slowest joint.
    peak = QUINTIC_PEAK_RATE * np.abs(delta) / move.duration
    assert np.all(peak <= speed * VMAX * (1 + 1e-9))
    assert np.max(peak / (speed * VMAX)) == pytest.approx(exact / move.samples, rel=1e-9)


def test_halving_the_speed_doubles_the_duration() -> None:
    start = np.zeros(6)
    goal = np.array([1.6, -0.5, 0.25, 3.2, 0.0, -1.0])
    full = plan_joint_move(start, goal, VMAX, 1.0, RATE)
    half = plan_joint_move(start, goal, VMAX, 0.5, RATE)
    # 15/8 * 1.6 rad / (1 rad/s) = 3 s; joint 4's 3.2 rad at 2 rad/s ties.
    assert full.samples == 3 * RATE
    assert half.samples == 2 * full.samples
    for k in (1, 100, 374):
        np.testing.assert_allclose(half.at(2 * k), full.at(k), atol=1e-15)


def test_joint_move_boundary_velocity_and_acceleration_are_zero() -> None:
    move = plan_joint_move(np.zeros(6), np.ones(6), VMAX, 1.0, RATE)
    dt = 1 / RATE
    q = np.array([move.at(k) for k in range(move.samples + 1)])
    v = np.diff(q, axis=0) / dt
    # Finite differences of a quintic with zero rate and acceleration at the ends:
    # the first step moves by O(dt^3).
    assert np.max(np.abs(v[0])) < 1e-3
    assert np.max(np.abs(v[-1])) < 1e-3


def test_checkpoints_are_twenty_and_end_at_the_goal() -> None:
    assert checkpoint_samples(400) == list(range(20, 401, 20))
    assert checkpoint_samples(10) == [round(i / 2) for i in range(1, 21)]
    assert checkpoint_samples(10)[-1] == 10


START = np.array([0.4, -0.15, 0.05])
VIAS = np.array([[0.5, 0.1, 0.0], [0.55, 0.15, -0.2], [0.3, -0.4, -0.1]])


def test_path_integration_matches_the_exact_path_and_ends_on_the_goal() -> None:
    path = plan_path(START, VIAS, 0.25, 0.2, RATE)
    pos, vel, corrections = integrate_path(path)
    assert len(pos) == path.samples + 1
    # One correction at the start of every straight segment, the final
    # zero-length one included.
    assert corrections == len(path.junction)
    exact = np.array([path.position(k) for k in range(path.samples + 1)])
    exact_v = np.array([path.speed(k) for k in range(path.samples + 1)])
    np.testing.assert_allclose(pos, exact, atol=1e-12)
    np.testing.assert_allclose(vel, exact_v, atol=1e-12)
    np.testing.assert_array_equal(pos[0], START)
    np.testing.assert_array_equal(pos[-1], VIAS[-1])
    np.testing.assert_array_equal(vel[0], 0.0)
    np.testing.assert_array_equal(vel[-1], 0.0)


def test_path_start_up_and_stopping_take_one_blend() -> None:
    path = plan_path(START, VIAS, 0.25, 0.2, RATE)
    tau = path.tau
    assert tau == round(0.2 * RATE / 2)
    # Seed 003: "a start up time of 2 tau_1 and a stopping time of 2 tau_{m-1}".
    accel_first = path.acceleration(0)
    np.testing.assert_allclose(accel_first, path.velocity[1] * RATE / (2 * tau))
    np.testing.assert_allclose(path.speed(2 * tau), path.velocity[1], atol=1e-12)
    np.testing.assert_allclose(path.speed(path.samples - 2 * tau), path.velocity[-2], atol=1e-12)


def test_path_is_continuous_in_position_and_velocity_across_blends() -> None:
    path = plan_path(START, VIAS, 0.25, 0.3, RATE)
    eps = 1e-9
    for tj in path.junction:
        for edge in (tj - path.tau, tj + path.tau):
            np.testing.assert_allclose(
                path.position(edge - eps), path.position(edge + eps), atol=1e-9
            )
            np.testing.assert_allclose(path.speed(edge - eps), path.speed(edge + eps), atol=1e-6)


def test_straight_segments_run_at_constant_velocity_no_faster_than_asked() -> None:
    path = plan_path(START, VIAS, 0.25, 0.2, RATE)
    _, vel, _ = integrate_path(path)
    speeds = np.linalg.norm(vel, axis=1)
    assert speeds.max() <= 0.25 + 1e-12
    for j in range(len(path.junction) - 1):
        first, last = path.junction[j] + path.tau, path.junction[j + 1] - path.tau
        seg = vel[first : last + 1]
        np.testing.assert_allclose(
            seg, np.broadcast_to(path.velocity[j + 1], seg.shape), atol=1e-12
        )


def test_blends_pass_a_quarter_of_the_velocity_change_from_each_via_point() -> None:
    path = plan_path(START, VIAS, 0.25, 0.2, RATE)
    tau_s = path.tau / RATE
    for j in range(1, len(VIAS)):
        expected = VIAS[j - 1] + (path.velocity[j + 1] - path.velocity[j]) * tau_s / 4
        np.testing.assert_allclose(path.position(path.junction[j]), expected, atol=1e-12)


def test_short_segments_are_stretched_to_fit_their_blends() -> None:
    goal = START + np.array([0.001, 0.0, 0.0])
    path = plan_path(START, goal[None, :], 0.25, 0.4, RATE)
    assert path.junction[1] - path.junction[0] == 2 * path.tau
    pos, _, _ = integrate_path(path)
    np.testing.assert_array_equal(pos[-1], goal)
