"""linksim: the world around the link -- impaired lines, a pty relay, simulated modems, benchmarks.

* :class:`LinkConfig` / :class:`DirectionConfig`: impairment parameters, presets, TOML.
* :class:`LinkDirection`: the sans-I/O impairment engine (one per direction).
* :func:`open_impaired_link`: two connected trio streams over an impaired line.
* :func:`run_relay`: the same line between two real ptys (``linksim relay``).
* :class:`ModemPair`: two emulated Hayes modems joined by the line (``linksim relay --modem``).
* :func:`serial_socket_pair`: two connected serial sockets over an impaired line.
* :class:`SimulatedArm`: a PUMA 560 with a gripper in a world of boxes and
  objects (:class:`WorldConfig`), the :class:`tcpstream.Executor` the command
  server calls; :func:`rock_task`: seed 000's task script.
* :func:`run_demo` (``linksim demo``), :class:`TaskRun`: a task script run
  pipelined through an arm client, with a record of every command.
"""

from ._arm import ArmStatistics, SimulatedArm
from ._channel import ImpairedLink, LinkEnd, LinkStatistics, open_impaired_link
from ._config import (
    PRESETS,
    ConfigError,
    DirectionConfig,
    FaultAction,
    GilbertElliott,
    LinkConfig,
    Outage,
    ScriptedFault,
)
from ._control import CommandRecord, CommandState, TaskRun
from ._demo import DemoOptions, DemoReport, run_demo
from ._impair import DirectionStatistics, LinkDirection
from ._kinematics import PUMA560, ArmModel
from ._modem import (
    TRANSITIONS,
    CallOutcome,
    ModemConfig,
    ModemPair,
    ModemState,
    ModemStateError,
)
from ._pair import endpoint_config_for, serial_socket_pair
from ._relay import RelayStatistics, run_relay
from ._tasks import RockTask, rock_task
from ._world import DEFAULT_WORLD, ObjectSpec, ObstacleSpec, WorldConfig

__all__ = [
    "DEFAULT_WORLD",
    "PRESETS",
    "PUMA560",
    "TRANSITIONS",
    "ArmModel",
    "ArmStatistics",
    "CallOutcome",
    "CommandRecord",
    "CommandState",
    "ConfigError",
    "DemoOptions",
    "DemoReport",
    "DirectionConfig",
    "DirectionStatistics",
    "FaultAction",
    "GilbertElliott",
    "ImpairedLink",
    "LinkConfig",
    "LinkDirection",
    "LinkEnd",
    "LinkStatistics",
    "ModemConfig",
    "ModemPair",
    "ModemState",
    "ModemStateError",
    "ObjectSpec",
    "ObstacleSpec",
    "Outage",
    "RelayStatistics",
    "RockTask",
    "ScriptedFault",
    "SimulatedArm",
    "TaskRun",
    "WorldConfig",
    "endpoint_config_for",
    "open_impaired_link",
    "rock_task",
    "run_demo",
    "run_relay",
    "serial_socket_pair",
]
