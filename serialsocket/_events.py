"""Events an endpoint reports (frozen, slotted, keyword-only dataclasses).

Data does not travel in events: it is read with ``Endpoint.read`` so that the
endpoint knows when the application has consumed it and can reopen its window.
"""

from __future__ import annotations

from dataclasses import dataclass

from ._params import Negotiated

__all__ = [
    "Connected",
    "ConnectionAborted",
    "ConnectionClosed",
    "ConnectionRequested",
    "EndOfStream",
    "Event",
    "LinkDead",
]


@dataclass(frozen=True, slots=True, kw_only=True)
class Event:
    """Base class of endpoint events."""


@dataclass(frozen=True, slots=True, kw_only=True)
class ConnectionRequested(Event):
    """A peer asked to connect; call ``accept()`` or ``refuse(reason)``.

    Only emitted when the configuration says ``auto_accept=False``."""

    parameters: Negotiated


@dataclass(frozen=True, slots=True, kw_only=True)
class Connected(Event):
    """The init exchange finished; ``parameters`` is what both sides use."""

    parameters: Negotiated


@dataclass(frozen=True, slots=True, kw_only=True)
class EndOfStream(Event):
    """The peer sent EOF and every byte before it has been delivered."""


@dataclass(frozen=True, slots=True, kw_only=True)
class ConnectionClosed(Event):
    """Graceful close finished: both directions drained and acknowledged."""


@dataclass(frozen=True, slots=True, kw_only=True)
class ConnectionAborted(Event):
    """The connection ended abnormally.

    Attributes:
        reason: human-readable reason (the E-packet text when the peer sent one).
        by_peer: True when the peer aborted or refused, False when we did.
        refused: True when this ended a connection attempt (never established).
    """

    reason: str
    by_peer: bool
    refused: bool = False


@dataclass(frozen=True, slots=True, kw_only=True)
class LinkDead(Event):
    """The peer has been silent for ``silence`` seconds.

    Attributes:
        silence: seconds since the last valid packet from the peer.
        bytes_acknowledged: bytes the peer confirmed, since the connection began.
        bytes_in_flight: bytes sent but never confirmed (they may or may not
            have arrived).
        bytes_unsent: bytes the application queued that never left.
    """

    silence: float
    bytes_acknowledged: int
    bytes_in_flight: int
    bytes_unsent: int
