"""The stack fitted to a given line: what the endpoints and the command session are told.

One place answers "how should serialsocket and tcpstream be configured on
this line?" for every program that builds a stack over an impaired link --
:func:`linksim.link.serial_socket_pair`, the demo, the arm server, the
console and the soak:

* :func:`endpoint_config_for`: the serial endpoint's configuration (the
  line's delay and rate, plus overrides).
* :func:`endpoint_overrides`: the overrides an operator gave (window, packet
  length), as keyword arguments for :func:`endpoint_config_for`.
* :func:`rtt_hint_for`: the round trip a command session should expect.
* :func:`server_config_for`: the command server's timing derived from it.
"""

from __future__ import annotations

from typing import Any

from serialsocket import EndpointConfig
from serialsocket.packets import EIGHT_BIT_CLEAN
from tcpstream import ServerConfig
from tcpstream.commands import PACKET_SIZE

from ._config import LinkConfig

__all__ = [
    "endpoint_config_for",
    "endpoint_overrides",
    "handshake_timeout_for",
    "rtt_hint_for",
    "server_config_for",
]


def endpoint_config_for(link: LinkConfig, **overrides: Any) -> EndpointConfig:
    """An endpoint configuration matching the line: its delay and rate, plus overrides.

    Everything else is serialsocket's default, derived from those facts: on a
    rate-limited line the send buffer is what the line carries in one round
    trip (at least two full packets; see
    :meth:`~serialsocket.EndpointConfig.derived_send_buffer`), so a command
    (an emergency stop!) never waits behind minutes of queue and a writer such
    as the command session's telemetry sees the line is busy.
    """
    d = link.a_to_b
    # The simulated line carries every byte value (8N1): the 8-bit profile,
    # as a real 8N1 port would choose (PROTOCOL.md section 8).
    overrides.setdefault("encoding", EIGHT_BIT_CLEAN)
    return EndpointConfig(
        one_way_delay=d.delay + d.jitter,
        line_rate=d.rate,
        bits_per_char=d.bits_per_char,
        **overrides,
    )


def endpoint_overrides(*, window: int | None = None, max_len: int | None = None) -> dict[str, Any]:
    """The endpoint options an operator gave (None: the line's default), as keywords."""
    out: dict[str, Any] = {}
    if window is not None:
        out["window"] = window
    if max_len is not None:
        out["max_packet_length"] = max_len
    return out


def rtt_hint_for(link: LinkConfig) -> float:
    """The round trip a command session should expect on ``link``, in seconds.

    Propagation both ways plus the time to serialise one command packet each
    way at the line rate, prefix-encoded (about 1.6 characters a byte for
    binary float64 words in the printable profile) -- the heartbeat and
    deadman timers are derived from it, so it must not be optimistic.
    """
    total = 0.0
    for d in (link.a_to_b, link.b_to_a):
        total += d.delay + d.jitter
        if d.rate is not None:
            total += (PACKET_SIZE * 1.6 + 40) * d.bits_per_char / d.rate
    return max(0.05, total)


def handshake_timeout_for(link: LinkConfig) -> float:
    """How long a controller waits for the arm's GRANT on ``link``: 30 s, or six
    round trips where that is longer (HELLO, CHALLENGE, AUTH, GRANT are two,
    a retransmission or two of them on a noisy line the rest; Mars: 4 hours)."""
    return max(30.0, 6 * rtt_hint_for(link))


def server_config_for(
    link: LinkConfig, key: bytes | None, *, max_packet_rate: float | None = 200.0
) -> ServerConfig:
    """Server timing derived from the line (see :func:`rtt_hint_for`)."""
    return ServerConfig(key=key, rtt_hint=rtt_hint_for(link), max_packet_rate=max_packet_rate)
