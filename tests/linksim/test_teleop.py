"""linksim.teleop: the FRHC, the remote arm's modes, contact and compliance (sans-I/O,
stepped by hand), and whole runs over the teleoperation channel on virtual time."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from linksim.link import DirectionConfig, FaultAction, LinkConfig, ScriptedFault, run_virtual
from linksim.teleop import (
    ContactModel,
    HandController,
    RemoteArm,
    RemoteConfig,
    TeleopOptions,
    frhc_jacobian,
    frhc_pose,
    rate_deadman,
    run_teleop,
    world_for,
)
from linksim.teleop._frhc import FRHC_INITIAL, rotvec
from linksim.teleop._remote import _jacobian, _singular
from tcpstream.teleop import Buttons, ContactFlags, ReplyStatus, Sample, TeleopMode

E = Buttons.ENGAGED
DT = 1.0 / 125.0


def six(*w: float) -> tuple[float, float, float, float, float, float]:
    v = [*w, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0][:6]
    return (v[0], v[1], v[2], v[3], v[4], v[5])


def arm(task: str = "surface", **config: object) -> RemoteArm:
    contact, q0 = world_for(task)
    return RemoteArm(RemoteConfig(**config), contact, q0)  # type: ignore[arg-type]


def run(a: RemoteArm, samples: list[Sample], ticks: int, start: float = 0.0) -> float:
    """Feed one sample per tick (then none); returns the time after the last tick."""
    now = start
    for k in range(max(ticks, len(samples))):
        now += DT
        a.step(now, (samples[k], now) if k < len(samples) else None)
    return now


# --- the FRHC (seed 004's appendix) ----------------------------------------------------


def test_frhc_jacobian_is_the_derivative_of_its_kinematics() -> None:
    q = FRHC_INITIAL + np.array([0.1, 0.2, 0.01, -0.3, 0.2, 0.4])
    jac = frhc_jacobian(q)
    eps = 1e-7
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = eps
        a, b = frhc_pose(q + dq), frhc_pose(q)
        np.testing.assert_allclose(jac[:3, j], (a[:3, 3] - b[:3, 3]) / eps, atol=1e-5)
        np.testing.assert_allclose(jac[3:, j], rotvec(a[:3, :3] @ b[:3, :3].T) / eps, atol=1e-5)
    # The appendix's initial pose: the handle 730.25 mm out, not singular.
    assert frhc_pose(FRHC_INITIAL)[0, 3] == pytest.approx(0.73025)
    assert np.linalg.matrix_rank(frhc_jacobian(FRHC_INITIAL)) == 6


def test_encoder_increments_add_up_to_the_handle_motion() -> None:
    hc = HandController()
    total = np.zeros(6)
    for k in range(1, 101):
        hc.move_handle(np.array([0.0005 * k, -0.0003 * k, 0.0002 * k]))
        total += hc.increment()[0]
    np.testing.assert_allclose(total[:3], [0.05, -0.03, 0.02], atol=2e-4)
    np.testing.assert_allclose(hc.deflection()[:3], [0.05, -0.03, 0.02], atol=1e-9)


# --- the remote arm, mode by mode -------------------------------------------------------


def test_cartesian_increments_rotated_into_the_robot_frame() -> None:
    a = arm(hand_to_robot=(0.0, 0.0, math.pi / 2))
    p0 = a.p.copy()
    samples = [Sample(n, TeleopMode.CARTESIAN, E, 0, 0.0, six(0.001 * n)) for n in range(1, 21)]
    run(a, samples, 200)
    # 20 mm along the hand controller's x is 20 mm along the robot's y.
    np.testing.assert_allclose(a.p - p0, [0.0, 0.02, 0.0], atol=1e-4)


def test_a_coalesced_sample_loses_no_motion() -> None:
    every, skipping = arm(), arm()
    samples = [Sample(n, TeleopMode.CARTESIAN, E, 0, 0.0, six(0.002 * n)) for n in range(1, 11)]
    run(every, samples, 200)
    run(skipping, [samples[0], samples[4], samples[9]], 200)
    np.testing.assert_allclose(skipping.p_cmd, every.p_cmd, atol=1e-12)
    np.testing.assert_allclose(skipping.p, every.p, atol=1e-6)


def test_tool_frame_increments_follow_the_hand() -> None:
    a = arm()
    approach = a.r[:, 2].copy()  # A: the hand points down
    p0 = a.p.copy()
    s = [Sample(1, TeleopMode.CARTESIAN, E | Buttons.TOOL_FRAME, 0, 0.0, six(0.0, 0.0, 0.01))]
    run(a, s, 100)
    np.testing.assert_allclose(a.p - p0, 0.01 * approach, atol=1e-4)


def test_a_moving_base_turns_the_transformation() -> None:
    """The robot's base turns at 0.5 rad/s about z: the same hand increment moves the arm
    along a direction that turns with it (seed 004: the 6x6 matrix is then not constant)."""
    a = arm(base_rate=0.5)
    now = 0.0
    moves = []
    for n, t in enumerate((0.0, math.pi), start=1):
        while now < t:
            now += DT
            a.step(now, None)
        before = a.p_cmd.copy()
        now += DT
        a.step(now, (Sample(n, TeleopMode.CARTESIAN, E, 0, now, six(0.001 * n)), now))
        moves.append(a.p_cmd - before)
    # 1 mm along hand x at t = 0, then at t = pi s the base has turned by -pi/2.
    np.testing.assert_allclose(moves[0], [0.001, 0.0, 0.0], atol=1e-5)
    np.testing.assert_allclose(moves[1], [0.0, -0.001, 0.0], atol=2e-5)


def test_the_trigger_drives_the_gripper() -> None:
    a = arm()
    s = [Sample(n, TeleopMode.CARTESIAN, E, 255, 0.0, six(0.0)) for n in range(1, 3)]
    run(a, s, 40)
    reply = a.step(1.0, None)
    assert reply.gripper == 255


def test_joint_mode_moves_joints_by_the_scaled_increments() -> None:
    a = arm(joint_scale=(0.5, 1.0, 2.0, 1.0, 1.0, 1.0))
    q0 = a.q.copy()
    s = [
        Sample(1, TeleopMode.JOINT, E, 0, 0.0, six(0.0)),
        Sample(2, TeleopMode.JOINT, E, 0, 0.0, six(0.2, 0.1, 0.01)),
    ]
    run(a, s, 100)
    np.testing.assert_allclose(a.q - q0, [0.1, 0.1, 0.02, 0, 0, 0], atol=1e-9)


def test_index_clutch_holds_the_arm_and_motion_resumes_from_the_new_words() -> None:
    a = arm()
    p0 = a.p.copy()
    # The sender sums only while ENGAGED (tcpstream PROTOCOL.md 14): the
    # handle's travel with the clutch open never reaches the words.
    seq = [
        Sample(1, TeleopMode.INDEX, E, 0, 0.0, six(0.01)),
        Sample(2, TeleopMode.INDEX, Buttons(0), 0, 0.0, six(0.01)),
        Sample(3, TeleopMode.INDEX, Buttons(0), 0, 0.0, six(0.01)),
        Sample(4, TeleopMode.INDEX, E, 0, 0.0, six(0.01)),
        Sample(5, TeleopMode.INDEX, E, 0, 0.0, six(0.02)),
    ]
    now = 0.0
    for s in seq[:3]:
        now += DT
        reply = a.step(now, (s, now))
    assert reply.flags & ContactFlags.CLUTCHED
    held = a.p_cmd.copy()
    run(a, [seq[2]] * 20, 20, now)
    np.testing.assert_allclose(a.p_cmd, held, atol=1e-12)  # clutched: the arm holds
    run(a, seq[3:], 200, now + 20 * DT)
    # 10 mm before the clutch, 10 mm after it.
    np.testing.assert_allclose(a.p - p0, [0.02, 0, 0], atol=1e-4)


def test_motion_made_before_the_clutch_in_unseen_samples_is_not_lost() -> None:
    # Sample 2 (engaged, the hand moved on to 30 mm) never reached the arm; the
    # first one it sees after is already clutched.  Its words still carry the
    # motion (the last found a joint-mode run that never reached the table).
    for mode in (TeleopMode.INDEX, TeleopMode.JOINT):
        a = arm()
        p0, q0 = a.p.copy(), a.q.copy()
        seq = [
            Sample(1, mode, E, 0, 0.0, six(0.0)),
            Sample(3, mode, Buttons(0), 0, 0.0, six(0.03)),
            Sample(4, mode, E, 0, 0.0, six(0.03)),
        ]
        run(a, seq, 300)
        if mode is TeleopMode.INDEX:
            np.testing.assert_allclose(a.p - p0, [0.03, 0, 0], atol=1e-4)
        else:
            np.testing.assert_allclose(a.q - q0, [0.03, 0, 0, 0, 0, 0], atol=1e-6)


def test_rate_mode_moves_and_its_deadman_stops_it() -> None:
    a = arm(rate_deadman=0.5)
    p0 = a.p.copy()
    s = Sample(1, TeleopMode.RATE, E, 0, 0.0, six(0.02))  # 20 mm deflection: 20 mm/s
    now = DT
    a.step(now, (s, now))
    for _ in range(124):
        now += DT
        reply = a.step(now, None)
    assert reply.status is ReplyStatus.DEADMAN
    assert a.stats.deadman_trips == 1
    # It moved for the deadman time (0.5 s at 20 mm/s, less the servo's lag), then stopped.
    moved = float(a.p[0] - p0[0])
    assert 0.0085 < moved <= 0.0101
    for _ in range(60):
        now += DT
        a.step(now, None)
    assert float(a.p[0] - p0[0]) == pytest.approx(moved, abs=5e-4)
    assert rate_deadman(1.3, 0.42) == pytest.approx(2.6 + 1.68 + 0.1)


def _near_wrist_singularity() -> tuple[RemoteArm, np.ndarray]:
    _, q0 = world_for("surface")
    q = q0.copy()
    q[4] = 0.09  # 0.04 rad outside the wrist's singular region
    a = RemoteArm(RemoteConfig(), ContactModel(table_z=-5.0), q)
    axis = _jacobian(a.model, q)[3:, 4]  # joint 5's axis: turning about it moves q5
    return a, axis


@pytest.mark.parametrize("pose_change", [False, True])
def test_singularity_bounce_off_and_pose_change(pose_change: bool) -> None:
    a, axis = _near_wrist_singularity()
    buttons = E | (Buttons.POSE_CHANGE if pose_change else Buttons(0))
    turn = -0.15 * axis
    s = [
        Sample(1, TeleopMode.CARTESIAN, buttons, 0, 0.0, six(0.0)),
        Sample(2, TeleopMode.CARTESIAN, buttons, 0, 0.0, six(0, 0, 0, *turn)),
    ]
    run(a, s, 100)
    if pose_change:
        assert a.q[4] < -0.05  # through the singular region to the other wrist pose
        assert a.stats.pose_changes >= 1
        assert a.stats.bounces == 0
    else:
        assert a.q[4] > 0.05  # never inside
        assert _singular(a.model, a.q) is None
        assert a.stats.bounces >= 1


def test_shared_compliance_holds_the_force_and_direct_control_hits_the_limit() -> None:
    pressed = six(0.0, 0.0, -0.15)  # 50 mm into the table
    soft, stiff = arm(), arm()
    b = E | Buttons.SHARED_COMPLIANCE
    run(
        soft,
        [
            Sample(1, TeleopMode.CARTESIAN, b, 0, 0.0, six(0.0)),
            Sample(2, TeleopMode.CARTESIAN, b, 0, 0.0, pressed),
        ],
        1000,
    )
    assert 29.0 < soft.stats.max_force <= 30.0 + 1e-6
    assert soft.flags & ContactFlags.CONTACT
    assert soft.stats.force_limit_stops == 0
    run(
        stiff,
        [
            Sample(1, TeleopMode.CARTESIAN, E, 0, 0.0, six(0.0)),
            Sample(2, TeleopMode.CARTESIAN, E, 0, 0.0, pressed),
        ],
        1000,
    )
    assert stiff.stats.force_limit_stops == 1
    assert stiff.stats.max_force > 50.0
    assert stiff.status is ReplyStatus.FORCE_LIMIT


# --- whole runs, virtual time -----------------------------------------------------------


def test_noisy_moon_shared_compliance_surface_run() -> None:
    r = run_virtual(run_teleop, TeleopOptions(task="surface", scheme="shared-compliance"))
    assert r.ok
    assert r.max_contact_force_n <= r.force_limit_n
    assert r.samples_applied > 10
    # Latest value: the line carries a few samples a second, the rest are coalesced.
    assert r.samples_coalesced > 10 * r.samples_sent
    assert r.samples_sent + r.samples_coalesced == r.samples_sampled
    # The age at execution stays near the one-way delay (1.3 s) plus one sample's line time.
    assert 1.3 < r.setpoint_age_s["p50"] < 1.8
    # Issue 22's target: p99 within one way + 0.5 s.  Samples take the serial
    # socket's latest-value lane, so a lost one holds up nothing behind it (on
    # the stream, its repair held them for a round trip: p99 2.10 s here).
    assert r.samples_on_lane == r.samples_sent
    assert r.setpoint_age_s["p99"] <= 1.3 + 0.5
    # No queue grows: never more than one sample's line time (0.40 s) plus an ACK or a
    # retransmission ahead of a sample.
    assert r.line_queue_max_s is not None
    assert r.line_queue_max_s < 1.0


def test_noisy_moon_force_reflection_surface_run_exceeds_the_limit() -> None:
    r = run_virtual(run_teleop, TeleopOptions(task="surface", scheme="force-reflection"))
    assert r.max_contact_force_n > r.force_limit_n
    assert r.force_limit_stops == 1


@pytest.mark.parametrize(
    ("preset", "bound"), [("moon", 1.3 + 0.3), ("noisy-moon", 1.3 + 2.6 + 0.5)]
)
def test_emergency_stop_during_streaming_overtakes_every_sample(preset: str, bound: float) -> None:
    """STOP waits behind at most the one sample already on the line: it reaches the arm
    one way later plus a sample's line time (on noisy-moon, plus a retransmission)."""
    r = run_virtual(run_teleop, TeleopOptions(task="surface", preset=preset, stop_at=5.0))
    assert r.ok
    assert r.emergency_stops == 1
    assert r.samples_after_stop == 0
    assert r.stop_to_arm_s is not None
    assert 1.3 < r.stop_to_arm_s < bound


@pytest.mark.long  # ~6 s of CPU
def test_without_losses_no_sample_is_applied_older_than_one_way_and_half_a_second() -> None:
    """Issue 22's age target on noisy-moon's line without its errors (2400 bit/s, 1.3 s):
    every sample waits for the line behind nothing of ours.  Regression: the run stopped
    sampling at the end of its script, and its last sample, waiting for the line with
    nothing newer to replace it, was applied 0.2-0.4 s later than the rest (max 1.93 s)."""
    line = DirectionConfig(rate=2400, delay=1.3)
    r = run_virtual(
        run_teleop, TeleopOptions(task="surface", link=LinkConfig(a_to_b=line, b_to_a=line))
    )
    assert r.ok
    assert r.setpoint_age_s["max"] <= 1.3 + 0.5


@pytest.mark.long  # ~5 s of CPU
def test_a_lost_stop_is_repaired_when_its_copy_shows_the_gap() -> None:
    """The STOP's packet is dropped on a 2400 bit/s, 1.3 s line.  Nothing else follows a
    STOP, so before its copies the serial socket's retransmission timer repaired it:
    7.26 s from the press to the arm.  The first copy leaves when the STOP has, the arm's
    socket NAKs the gap, and the resend arrives one round trip after the copy: about
    three one-way delays plus the line times of the STOP, its copy, a reply ahead of the
    NAK and the resend."""
    stop_packet = ScriptedFault(
        # MARK LEN SEQ D, the two high sequence characters (long sequence numbers
        # are offered by default), then the STOP's header: TT, version 1, kind 8.
        FaultAction.DROP,
        packet=1,
        starts_with=b"\x01??D??TT#A#H",
        wildcard=ord("?"),
    )
    line = DirectionConfig(rate=2400, delay=1.3)
    link = LinkConfig(a_to_b=replace(line, faults=(stop_packet,)), b_to_a=line)
    r = run_virtual(
        run_teleop, TeleopOptions(task="surface", link=link, stop_at=5.0, duration=12.0)
    )
    assert r.ok
    assert r.stop_to_arm_s is not None
    # Above three one-way delays: the STOP was lost (if not, the pattern above no longer
    # matches the serial socket's encoding of a STOP packet and needs updating).
    assert r.stop_to_arm_s > 3 * 1.3, "no loss: does the pattern still match a STOP packet?"
    assert r.stop_to_arm_s < 3 * 1.3 + 1.5


def test_command_session_emergency_stop_beside_the_samples_on_one_line() -> None:
    """The command session and the sample channel share the moon line through the mux;
    the session's EMERGENCY_STOP overtakes the samples and halts the arm."""
    r = run_virtual(
        run_teleop,
        TeleopOptions(
            task="surface", preset="moon", stop_at=5.0, commands=True, stop_via="command"
        ),
    )
    assert r.ok
    assert r.emergency_stops == 1
    assert r.stop_to_arm_s is not None
    assert 1.3 < r.stop_to_arm_s < 1.3 + 0.3
    assert r.moved_after_stop_m < 0.005


def test_tcp_clean_every_sample_applied_within_a_control_tick() -> None:
    r = run_virtual(run_teleop, TeleopOptions(transport="tcp", preset="clean", duration=3.0))
    assert r.ok
    assert r.samples_coalesced == 0
    assert r.samples_sent == r.samples_sampled
    assert r.setpoint_age_s["max"] <= DT + 1e-9
