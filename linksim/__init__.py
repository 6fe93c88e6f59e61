"""linksim: the world around the link -- impaired lines, a pty relay, simulated modems, benchmarks.

* :class:`LinkConfig` / :class:`DirectionConfig`: impairment parameters, presets, TOML.
* :class:`LinkDirection`: the sans-I/O impairment engine (one per direction).
* :func:`open_impaired_link`: two connected trio streams over an impaired line.
* :func:`run_relay`: the same line between two real ptys (``linksim relay``).
* :class:`ModemPair`: two emulated Hayes modems joined by the line (``linksim relay --modem``).
* :func:`serial_socket_pair`: two connected serial sockets over an impaired line.
"""

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
from ._impair import DirectionStatistics, LinkDirection
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

__all__ = [
    "PRESETS",
    "TRANSITIONS",
    "CallOutcome",
    "ConfigError",
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
    "Outage",
    "RelayStatistics",
    "ScriptedFault",
    "endpoint_config_for",
    "open_impaired_link",
    "run_relay",
    "serial_socket_pair",
]
