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
* The operator console (``linksim console``): :func:`preview` plays commands
  on a local copy of the arm (:class:`PreviewReport`); :class:`Predictor`
  keeps the predicted state ahead of the confirmed one and records
  :class:`Divergence`; :class:`ConsoleSession` / :class:`ConsoleSnapshot`
  draw it; :class:`TelemetryLog` / :func:`read_log` write and read the
  JSON-lines log (``linksim plot``).
"""

from importlib.metadata import PackageNotFoundError as _NotInstalled
from importlib.metadata import version as _version

try:
    __version__ = _version("telelink")
    """The telelink distribution's version (pyproject.toml is the one source)."""
except _NotInstalled:  # imported from a source tree that was never installed
    __version__ = "0+unknown"


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
from ._console import ConsoleSession, ConsoleSnapshot
from ._console_run import ConsoleOptions, ConsoleResult, run_console
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
from ._predict import Divergence, Predictor
from ._preview import ModelState, PredictedOutcome, PreviewReport, preview
from ._relay import RelayStatistics, run_relay
from ._tasks import RockTask, rock_task
from ._telemetry_log import TelemetryLog, read_log
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
    "ConsoleOptions",
    "ConsoleResult",
    "ConsoleSession",
    "ConsoleSnapshot",
    "DemoOptions",
    "DemoReport",
    "DirectionConfig",
    "DirectionStatistics",
    "Divergence",
    "FaultAction",
    "GilbertElliott",
    "ImpairedLink",
    "LinkConfig",
    "LinkDirection",
    "LinkEnd",
    "LinkStatistics",
    "ModelState",
    "ModemConfig",
    "ModemPair",
    "ModemState",
    "ModemStateError",
    "ObjectSpec",
    "ObstacleSpec",
    "Outage",
    "PredictedOutcome",
    "Predictor",
    "PreviewReport",
    "RelayStatistics",
    "RockTask",
    "ScriptedFault",
    "SimulatedArm",
    "TaskRun",
    "TelemetryLog",
    "WorldConfig",
    "endpoint_config_for",
    "open_impaired_link",
    "preview",
    "read_log",
    "rock_task",
    "run_console",
    "run_demo",
    "run_relay",
    "serial_socket_pair",
]
