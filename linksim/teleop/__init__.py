"""Seed 004's teleoperation over the delayed link: operator, hand controller, remote arm, run.

* :class:`Operator` and :class:`Script` (:func:`surface_script`,
  :func:`peg_script`): a scripted, replayable operator holding JPL's FRHC
  (:class:`HandController`, the appendix's kinematics).
* :class:`RemoteArm` (:class:`RemoteConfig`): the PUMA following samples in
  joint, Cartesian, rate and index modes, with the wrist force/torque sensor
  (:class:`ContactModel`, :class:`Hole`), singularity bounce-off, the force
  limit, and shared compliance or direct force reflection.
* :func:`run_teleop` (:class:`TeleopOptions`, :class:`TeleopReport`): the whole
  chain over the teleoperation channel of :mod:`tcpstream.teleop`;
  :func:`run_teleop_loopback`, the loopback latency benchmark;
  :func:`plot_contact_force`, the schemes' contact force against time.
"""

from __future__ import annotations

from ._contact import ContactModel, Hole, Wrench
from ._frhc import HandController, frhc_jacobian, frhc_pose
from ._loopback import run_teleop_loopback
from ._operator import Operator, Script, Waypoint, peg_script, surface_script
from ._plot import plot_contact_force
from ._remote import RemoteArm, RemoteConfig, RemoteStatistics, rate_deadman
from ._run import TeleopOptions, TeleopReport, run_teleop, world_for

__all__ = [
    "ContactModel",
    "HandController",
    "Hole",
    "Operator",
    "RemoteArm",
    "RemoteConfig",
    "RemoteStatistics",
    "Script",
    "TeleopOptions",
    "TeleopReport",
    "Waypoint",
    "Wrench",
    "frhc_jacobian",
    "frhc_pose",
    "peg_script",
    "plot_contact_force",
    "rate_deadman",
    "run_teleop",
    "run_teleop_loopback",
    "surface_script",
    "world_for",
]
