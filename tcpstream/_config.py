"""Server configuration and the timing rules derived from the link (PROTOCOL.md section 10)."""

from __future__ import annotations

import math
import secrets
from collections.abc import Callable
from dataclasses import dataclass, field

from ._auth import MIN_KEY_SIZE
from ._memory import DEFAULT_IDENTITIES, DEFAULT_MEMORY_SIZE

__all__ = ["DEADMAN_FLOOR", "HEARTBEAT_FLOOR", "MIN_PACKET_RATE", "ServerConfig"]

HEARTBEAT_FLOOR = 0.25
"""Seconds: heartbeats more often than 4/s buy nothing on any link we serve."""
MIN_PACKET_RATE = 10.0
"""Packets/s: the lowest per-connection rate limit accepted (see
:meth:`ServerConfig.packet_rate_floor`)."""
DEADMAN_FLOOR = 1.0
"""Seconds: the shortest deadman the arm accepts by default.  Shorter trips on
ordinary scheduling hiccups of a busy controller host."""


@dataclass(frozen=True, slots=True, kw_only=True)
class ServerConfig:
    """Everything the arm's server is told.  Timing defaults follow from ``rtt_hint``.

    ``rtt_hint`` is the link's expected round trip in seconds (TCP across a
    continent: ~0.1-0.2; Earth-Moon: 2.6 plus the serial line's serialisation
    and retransmission time).  From it:

    * ``heartbeat_interval`` defaults to ``max(HEARTBEAT_FLOOR, rtt_hint / 2)``;
    * ``dead_time`` (the deadman) defaults to
      ``max(DEADMAN_FLOOR, 2 * rtt_hint + 4 * heartbeat_interval)``: a healthy
      controller's heartbeat is never that late even if one is delayed by a
      full round trip of retransmission;
    * ``handshake_timeout`` defaults to ``max(10, 4 * rtt_hint + dead_time)``.

    A ``dead_time`` not above ``rtt_hint + heartbeat_interval`` is refused: it
    would halt the arm on a healthy link.
    """

    key: bytes | None = None
    """Pre-shared key (>= 16 bytes); None: no authentication (trusted links only)."""
    rtt_hint: float = 0.2
    heartbeat_interval: float | None = None
    dead_time: float | None = None
    handshake_timeout: float | None = None
    idle_timeout: float | None = 3600.0
    """Seconds a controller may hold the arm without commanding it (heartbeats do
    not count; a command still running does) before control is released for
    others; None: no limit.  Observers are bounded by ``max_connections`` instead."""
    telemetry_every: int = 10
    """Telemetry every N-th control sample (seed 004 forwards every tenth); 0: none."""
    queue_size: int = 32
    """Commands waiting per arm, besides the one running.  A command at 2400 baud
    takes ~1 s to arrive, so 32 is half a minute of pipelined work -- more than
    any operator plans ahead, and small enough that an emergency stop has little
    to flush."""
    memory_size: int = DEFAULT_MEMORY_SIZE
    memory_identities: int = DEFAULT_IDENTITIES
    max_connections: int = 8
    """Simultaneous connections (one controller, the rest observers or waiting);
    each costs three tasks and a few kB.  One slot is always the controller's
    (observers take at most ``max_connections - 1``); a connection never
    granted is closed to admit a newer one when all are taken, and when every
    slot holds a granted session one handshake is admitted beyond the limit
    (PROTOCOL.md section 10)."""
    max_packet_rate: float | None = 200.0
    """Packets per second each connection may send, sustained; None: no limit.
    Past it the server reads that connection more slowly -- nothing is dropped;
    the transport's flow control pushes back on the sender -- so a flooding peer
    costs the arm at most this many packets' work a second (``linksim bench
    flood``: about 6 % of a core at 200) and ``max_connections`` times that in
    all.  An honest controller needs far less: 4 heartbeats a second, a few
    STATUS polls, and commands the 125 Hz arm takes one by one.  Benchmarks
    that ping-pong as fast as the host allows set None."""
    packet_burst: int | None = None
    """Packets a connection may send at once above the rate, e.g. a full queue
    re-sent after a reconnect.  None: ``max(64, 2 * (queue_size + 1))``."""
    allow_observers: bool = True
    nonce_source: Callable[[int], bytes] = field(default=secrets.token_bytes, compare=False)

    def __post_init__(self) -> None:
        if self.key is not None and len(self.key) < MIN_KEY_SIZE:
            raise ValueError(f"the pre-shared key needs at least {MIN_KEY_SIZE} bytes")
        if not self.rtt_hint >= 0:
            raise ValueError("rtt_hint must be >= 0 seconds")
        if self.idle_timeout is not None and not self.idle_timeout > 0:
            raise ValueError("idle_timeout must be > 0 seconds (or None)")
        if self.telemetry_every < 0 or self.queue_size < 1 or self.max_connections < 1:
            raise ValueError("telemetry_every >= 0, queue_size >= 1, max_connections >= 1")
        if self.max_packet_rate is not None and not (
            self.max_packet_rate > 0 and math.isfinite(self.max_packet_rate)
        ):
            raise ValueError("max_packet_rate must be a finite number of packets/s > 0 (or None)")
        if self.packet_burst is not None and self.packet_burst < 2:
            raise ValueError(
                "packet_burst must be >= 2 packets (HELLO and AUTH arrive together), or None"
            )
        hb, dead = self.timing()
        if hb <= 0:
            raise ValueError("heartbeat_interval must be > 0")
        if dead <= self.rtt_hint + hb:
            raise ValueError(
                f"dead_time {dead:g} s must exceed the round trip plus a heartbeat interval "
                f"({self.rtt_hint + hb:g} s), or a healthy link would trip the deadman"
            )
        floor = self.packet_rate_floor()
        if self.max_packet_rate is not None and self.max_packet_rate < floor:
            raise ValueError(
                f"max_packet_rate {self.max_packet_rate:g}/s is below {floor:g}/s: an honest "
                "controller's heartbeats and polls would fall behind for good (and a deadman "
                "trip on a healthy link would follow); raise it, or turn the limit off"
            )

    def timing(self) -> tuple[float, float]:
        """``(heartbeat_interval, dead_time)`` with the defaults applied."""
        hb = self.heartbeat_interval
        if hb is None:
            hb = max(HEARTBEAT_FLOOR, self.rtt_hint / 2)
        dead = self.dead_time
        if dead is None:
            dead = max(DEADMAN_FLOOR, 2 * self.rtt_hint + 4 * hb)
        return hb, dead

    def packet_rate_floor(self) -> float:
        """The lowest ``max_packet_rate`` accepted: ``max(MIN_PACKET_RATE, 4 /
        heartbeat_interval)``, four times what an idle controller sends, so a
        throttled honest connection never builds a lasting backlog."""
        return max(MIN_PACKET_RATE, 4.0 / self.timing()[0])

    def burst(self) -> int:
        """``packet_burst`` with the default applied."""
        if self.packet_burst is not None:
            return self.packet_burst
        return max(64, 2 * (self.queue_size + 1))

    def handshake_time(self) -> float:
        if self.handshake_timeout is not None:
            return self.handshake_timeout
        return max(10.0, 4 * self.rtt_hint + self.timing()[1])
