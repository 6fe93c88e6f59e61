"""The teleoperation channel's states, transitions, reasons, events and statistics.

PROTOCOL.md section 14.  One table, :data:`TRANSITIONS`, holds every legal
state change of either end (:mod:`tcpstream._teleop_connection` applies it);
anything else raises :class:`IllegalTransition`.  The events are what the ends'
``receive_data`` return; :class:`Backlog` is the transport's figures the
operator end paces by.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from ._teleop_packet import Reply, Sample

__all__ = [
    "TRANSITIONS",
    "Backlog",
    "ChannelClosed",
    "ChannelState",
    "ChannelStatistics",
    "Granted",
    "IllegalTransition",
    "OperatorArrived",
    "RefuseCode",
    "Refused",
    "ReplyReceived",
    "SampleArrived",
    "StopArrived",
    "TeleopEvent",
]


class ChannelState(enum.Enum):
    IDLE = "idle"
    HELLO_SENT = "hello-sent"
    AUTH_SENT = "auth-sent"
    AWAITING_HELLO = "awaiting-hello"
    CHALLENGED = "challenged"
    AWAITING_DECISION = "awaiting-decision"
    OPEN = "open"
    CLOSED = "closed"


S = ChannelState
TRANSITIONS: frozenset[tuple[ChannelState, ChannelState]] = frozenset(
    {
        # operator
        (S.IDLE, S.HELLO_SENT),
        (S.HELLO_SENT, S.AUTH_SENT),  # CHALLENGE answered with AUTH
        (S.HELLO_SENT, S.OPEN),  # GRANT (unkeyed arm)
        (S.AUTH_SENT, S.OPEN),  # GRANT with a valid server proof
        # arm
        (S.AWAITING_HELLO, S.CHALLENGED),  # keyed: CHALLENGE sent
        (S.AWAITING_HELLO, S.AWAITING_DECISION),  # unkeyed HELLO
        (S.CHALLENGED, S.AWAITING_DECISION),  # AUTH verified
        (S.AWAITING_DECISION, S.OPEN),  # grant()
        # both: BYE, refusal, garbage, authentication failure
        *((s, S.CLOSED) for s in ChannelState if s is not S.CLOSED),
    }
)
"""Every legal state change of either end; anything else raises :class:`IllegalTransition`."""


class IllegalTransition(Exception):
    """A local call the channel's state does not allow (the caller's bug)."""


class RefuseCode(enum.IntEnum):
    """REFUSE and BYE reason byte (PROTOCOL.md 14.2)."""

    NORMAL = 0
    BUSY = 1
    NOT_AUTHORIZED = 2
    BAD_HELLO = 3
    GARBAGE = 4
    SHUTDOWN = 5


@dataclass(frozen=True, slots=True)
class Backlog:
    """The transport's own figures: our bytes it holds that are not yet on the wire."""

    queued_bytes: int
    """Accepted, not yet sent even once (serial socket: ``bytes_queued``)."""
    line_seconds: float = 0.0
    """Already handed to the line, still waiting for it (serial socket: ``line_backlog``)."""


@dataclass(frozen=True, slots=True)
class Granted:
    rate_deadman: float
    control_rate: float


@dataclass(frozen=True, slots=True)
class Refused:
    reason: RefuseCode


@dataclass(frozen=True, slots=True)
class ReplyReceived:
    reply: Reply
    now: float


@dataclass(frozen=True, slots=True)
class OperatorArrived:
    identity: str


@dataclass(frozen=True, slots=True)
class SampleArrived:
    sample: Sample
    now: float


@dataclass(frozen=True, slots=True)
class StopArrived:
    now: float


@dataclass(frozen=True, slots=True)
class ChannelClosed:
    reason: RefuseCode
    by_peer: bool


TeleopEvent = (
    Granted
    | Refused
    | ReplyReceived
    | OperatorArrived
    | SampleArrived
    | StopArrived
    | ChannelClosed
)


@dataclass(frozen=True, slots=True, kw_only=True)
class ChannelStatistics:
    """One end's record (``statistics()``)."""

    state: str
    packets_in: int
    packets_out: int
    bytes_in: int
    bytes_out: int
    bad_packets: int
    tag_failures: int
    replays: int
    resyncs: int
    samples_offered: int
    samples_sent: int
    samples_coalesced: int
    samples_received: int
    samples_superseded: int
    replies_sent: int
    replies_coalesced: int
    replies_received: int
    stops_sent: int
    stops_received: int
    stops_repeated: int
    """Operator: copies of its STOP sent after the first, until a REPLY said STOPPED."""
    held_by_backlog: int
    held_by_window: int
    samples_after_stop: int
    """Operator: samples offered after its STOP (never sent); arm: samples that
    arrived after a STOP (ignored)."""
    lane_packets_in: int
    """SAMPLEs (arm) or REPLYs (operator) taken from the transport's latest-value lane."""
    lane_packets_out: int
    """SAMPLEs or REPLYs handed to the lane (counted in ``packets_out`` too)."""
    lane_stale: int
    """Lane messages dropped: of another channel, before the grant, or overtaken
    by a packet with a higher counter."""
    lane_replaced: int
    """Lane messages that replaced one the transport had not yet put on the line
    (that one is then counted coalesced, not sent)."""
    in_flight_bytes: int
    window_bytes: float
    delivery_rate: float | None
    min_rtt: float | None
