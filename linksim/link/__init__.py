"""The impaired line: the engine, its configuration and presets, and what runs on it.

* :class:`LinkConfig` / :class:`DirectionConfig` (:data:`PRESETS`, TOML) and
  :class:`LinkDirection`, the sans-I/O impairment engine (one per direction).
* :func:`open_impaired_link`: two connected trio streams over an impaired line;
  :func:`serial_socket_pair`: two connected serial sockets over one.
* :func:`run_relay`: the same line between two real ptys (``linksim relay``);
  :func:`run_proxy`: the line in front of a real TCP server (``linksim proxy``,
  :class:`TcpDirection` its timing model, :class:`Cut` a reset at a byte offset);
  :class:`ModemPair`: two emulated Hayes modems joined by the line.
* :func:`run_virtual`: a virtual-time run that is the same run every time.
* The stack fitted to a line: :func:`endpoint_config_for`,
  :func:`endpoint_overrides`, :func:`rtt_hint_for`, :func:`server_config_for`.
"""

from __future__ import annotations

from linksim._errors import ConfigError

from ._channel import ImpairedLink, LinkEnd, LinkStatistics, open_impaired_link
from ._config import (
    PRESETS,
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
from ._pair import serial_socket_pair
from ._proxy import Cut, ProxyStatistics, TcpDirection, run_proxy
from ._relay import RelayStatistics, run_relay
from ._tuning import (
    endpoint_config_for,
    endpoint_overrides,
    handshake_timeout_for,
    rtt_hint_for,
    server_config_for,
)
from ._virtual import run_virtual

__all__ = [
    "PRESETS",
    "TRANSITIONS",
    "CallOutcome",
    "ConfigError",
    "Cut",
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
    "ProxyStatistics",
    "RelayStatistics",
    "ScriptedFault",
    "TcpDirection",
    "endpoint_config_for",
    "endpoint_overrides",
    "handshake_timeout_for",
    "open_impaired_link",
    "rtt_hint_for",
    "run_proxy",
    "run_relay",
    "run_virtual",
    "serial_socket_pair",
    "server_config_for",
]
