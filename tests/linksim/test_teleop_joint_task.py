"""JOINT mode's task scripts: derived from where the Cartesian scripts send the arm
(``joint_script``), they keep the handle in the FRHC's workspace, move the arm along the
task's path, and bring it into contact in whole runs on virtual time."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from linksim.link import run_virtual
from linksim.teleop import (
    ContactModel,
    RemoteArm,
    RemoteConfig,
    TeleopOptions,
    TeleopReport,
    Waypoint,
    run_teleop,
    world_for,
)
from linksim.teleop._frhc import WORKSPACE_REACH, WORKSPACE_TURN, in_workspace
from linksim.teleop._operator import Operator, Script, joint_script
from linksim.teleop._run import script_for
from linksim.teleop._transport import SAMPLE_RATE
from tcpstream.teleop import TeleopMode

TASKS = ("surface", "peg")


def _path_distance(p: np.ndarray, corners: list[np.ndarray]) -> float:
    """How far ``p`` is from the polyline through ``corners``."""
    best = np.inf
    for a, b in itertools.pairwise(corners):
        d = b - a
        length = float(d @ d)
        f = 0.0 if length == 0.0 else min(1.0, max(0.0, float((p - a) @ d) / length))
        best = min(best, float(np.linalg.norm(p - (a + f * d))))
    return best


def _tool_corners(task: str, start: np.ndarray) -> list[np.ndarray]:
    """The tool's targets at the CARTESIAN script's waypoints (identity hand-to-robot
    rotation, unit scale: the default RemoteConfig; every segment engaged)."""
    cartesian = script_for(task, TeleopMode.CARTESIAN)
    assert all(w.engaged for w in cartesian.waypoints)
    return [start + np.array(w.offset) for w in cartesian.waypoints]


@pytest.mark.parametrize("task", TASKS)
def test_joint_scripts_keep_the_handle_in_the_frhc_workspace(task: str) -> None:
    script = script_for(task, TeleopMode.JOINT)
    assert script == script_for(task, TeleopMode.JOINT)  # deterministic
    # Between waypoints the intent moves on a straight line, and the workspace (a cube
    # of positions, a ball of rotation vectors) is convex: the waypoints bound the path.
    for w in script.waypoints:
        assert in_workspace(np.array(w.offset + w.rotation)), w
    # With joint_scale 1 a radian of arm joint is a radian of FRHC joint, 0.73 m of
    # handle at the FRHC's shoulder: both tasks need the index clutch to re-centre.
    assert any(not w.engaged for w in script.waypoints)
    # The handle itself (the FRHC's joints solved from the hand, then its forward
    # kinematics), sample by sample as the operator's loop moves it.
    operator = Operator(script, TeleopMode.JOINT)
    dt = 1.0 / SAMPLE_RATE
    for k in range(int(script.duration / dt) + 1):
        operator.sample(k * dt, dt)
        deflection = operator.hc.deflection()
        assert float(np.max(np.abs(deflection[:3]))) <= WORKSPACE_REACH + 1e-9, k * dt
        assert float(np.linalg.norm(deflection[3:])) <= WORKSPACE_TURN + 1e-9, k * dt


@pytest.mark.parametrize("task", TASKS)
def test_joint_script_moves_the_arm_along_the_task_path(task: str) -> None:
    """Sample by sample (no line), in free space: the arm's tool follows the CARTESIAN
    script's path, within the encoders' resolution, to its deepest point and its end."""
    _, q0 = world_for(task)
    arm = RemoteArm(RemoteConfig(), ContactModel(table_z=-10.0), q0)
    corners = _tool_corners(task, arm.p.copy())
    script = script_for(task, TeleopMode.JOINT)
    operator = Operator(script, TeleopMode.JOINT)
    dt = 1.0 / SAMPLE_RATE
    worst, lowest = 0.0, np.inf
    for k in range(int((script.duration + 1.0) / dt)):
        sample = operator.sample(k * dt, dt)
        arm.step(k * dt, (sample, k * dt))
        worst = max(worst, _path_distance(arm.p, corners))
        lowest = min(lowest, float(arm.p[2]))
    # A half count of a 14-bit encoder is 0.19 mrad, about 0.1 mm at the tool per joint.
    assert worst < 0.5e-3
    assert lowest == pytest.approx(min(float(c[2]) for c in corners), abs=0.5e-3)
    np.testing.assert_allclose(arm.p, corners[-1], atol=0.5e-3)


def test_joint_script_refuses_a_turning_base() -> None:
    with pytest.raises(ValueError, match="turning base"):
        joint_script(
            script_for("surface", TeleopMode.CARTESIAN), remote=RemoteConfig(base_rate=0.1)
        )


def test_joint_script_re_centres_with_the_clutch_and_keeps_the_buttons() -> None:
    """A 0.3 m reach down: more than one stroke of the handle.  The clutch opens on a
    still handle, the handle goes back to neutral, the stroke goes on from there."""
    handle = Script(
        "reach",
        (
            Waypoint(0.0, (0.0, 0.0, 0.0), trigger=255),
            Waypoint(8.0, (0.0, 0.0, -0.30), trigger=255),
        ),
    )
    script = joint_script(handle)
    released = [i for i, w in enumerate(script.waypoints) if not w.engaged]
    assert released, "one stroke was enough: the test no longer tests re-centring"
    for i in released[::2]:  # (release on the still handle, back at neutral) pairs
        before, release, back, press = script.waypoints[i - 1 : i + 3]
        assert release.offset == before.offset
        assert back.offset == (0.0, 0.0, 0.0) == press.offset
        assert press.engaged
    assert all(w.trigger == 255 for w in script.waypoints)
    assert script.duration > handle.duration


# --- whole runs, virtual time -------------------------------------------------------


@pytest.fixture(scope="module", params=TASKS)
def joint_run(request: pytest.FixtureRequest) -> TeleopReport:
    """The task in JOINT mode over noisy-moon with shared compliance (the defaults)."""
    task: str = request.param
    return run_virtual(run_teleop, TeleopOptions(mode=TeleopMode.JOINT, task=task))


def test_joint_mode_makes_contact_with_shared_compliance(joint_run: TeleopReport) -> None:
    r = joint_run
    assert r.error is None
    assert r.samples_applied > 10
    assert r.bounces == 0
    # The arm reaches the table (surface) or the hole (peg), pushing at least as hard as
    # shared compliance would let it (which it now settles at: a rounding's tolerance).
    assert r.max_contact_force_n >= r.compliance_force_n - 0.5


def test_joint_mode_stays_within_the_force_limit_with_shared_compliance(
    joint_run: TeleopReport,
) -> None:
    """Shared compliance acts in JOINT mode too: the joint target's forward kinematics
    commands the arm's compliant servo, which yields to contact, so the press settles at
    the compliance force, well inside the limit, and the arm is never stopped."""
    r = joint_run
    assert r.max_contact_force_n <= r.compliance_force_n + 0.5
    assert r.compliance_force_n < r.force_limit_n
    assert r.force_limit_stops == 0
    assert r.ok
