"""linksim: the world around the link -- impaired lines, a simulated arm, the control
station, whole-stack programs and benchmarks.

This face holds what a program that uses linksim most often needs; each
sub-package has its own face with the rest:

* :mod:`linksim.link`: the impaired line.  :class:`LinkConfig` /
  :class:`DirectionConfig` / :class:`Outage` (:data:`PRESETS`, TOML, a bad
  value is a :class:`ConfigError`); :func:`open_impaired_link`,
  :func:`serial_socket_pair` (endpoints fitted to the line by
  :func:`endpoint_config_for`); :func:`run_relay` between two ptys;
  :class:`ModemPair` / :class:`ModemConfig`, emulated Hayes modems.
* :mod:`linksim.arm`: :class:`SimulatedArm`, a PUMA 560 in a world of boxes
  and objects (:class:`WorldConfig`, :data:`DEFAULT_WORLD`);
  :func:`rock_task`, seed 000's task script.
* :mod:`linksim.control`: :class:`TaskRun`, a task script run pipelined
  through an arm client; the operator console's preview and prediction.
* :mod:`linksim.demo`: :func:`run_demo` (``linksim demo``,
  :class:`DemoOptions`) and :func:`run_console` (``linksim console``,
  :class:`ConsoleOptions`).
* :mod:`linksim.bench`: benchmarks and the soak.
* :mod:`linksim.cli`: the ``linksim`` command.
"""

from importlib.metadata import PackageNotFoundError as _NotInstalled
from importlib.metadata import version as _version

try:
    __version__ = _version("telelink")
    """The telelink distribution's version (pyproject.toml is the one source)."""
except _NotInstalled:  # imported from a source tree that was never installed
    __version__ = "0+unknown"


from ._errors import ConfigError
from .arm import DEFAULT_WORLD, SimulatedArm, WorldConfig, rock_task
from .control import TaskRun
from .demo import ConsoleOptions, DemoOptions, run_console, run_demo
from .link import (
    PRESETS,
    DirectionConfig,
    LinkConfig,
    ModemConfig,
    ModemPair,
    Outage,
    endpoint_config_for,
    open_impaired_link,
    run_relay,
    serial_socket_pair,
)

__all__ = [
    "DEFAULT_WORLD",
    "PRESETS",
    "ConfigError",
    "ConsoleOptions",
    "DemoOptions",
    "DirectionConfig",
    "LinkConfig",
    "ModemConfig",
    "ModemPair",
    "Outage",
    "SimulatedArm",
    "TaskRun",
    "WorldConfig",
    "endpoint_config_for",
    "open_impaired_link",
    "rock_task",
    "run_console",
    "run_demo",
    "run_relay",
    "serial_socket_pair",
]
