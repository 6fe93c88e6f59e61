"""The simulated PUMA 560: kinematics, trajectories, planner, collision, world, arm, tasks.

* :class:`SimulatedArm`: a PUMA 560 with a gripper in a world of boxes and
  objects (:class:`WorldConfig`, :data:`DEFAULT_WORLD`), the
  :class:`tcpstream.Executor` the command server calls.
* :class:`ArmModel` / :data:`PUMA560` and the forward kinematics the
  control station's preview draws with (:func:`hand_frame`, :func:`psa`).
* :func:`rock_task`: seed 000's task script (:class:`RockTask`).
"""

from __future__ import annotations

from ._arm import ArmStatistics, SimulatedArm
from ._kinematics import PUMA560, ArmModel, hand_frame, psa
from ._tasks import RockTask, rock_task
from ._world import DEFAULT_WORLD, ObjectSpec, ObstacleSpec, WorldConfig

__all__ = [
    "DEFAULT_WORLD",
    "PUMA560",
    "ArmModel",
    "ArmStatistics",
    "ObjectSpec",
    "ObstacleSpec",
    "RockTask",
    "SimulatedArm",
    "WorldConfig",
    "hand_frame",
    "psa",
    "rock_task",
]
