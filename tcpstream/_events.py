"""Session vocabulary: roles, refusal and close reasons, identities and the events
the sans-I/O connections hand out (frozen, slotted dataclasses)."""

from __future__ import annotations

import enum
from dataclasses import dataclass

from ._commands import Command, CommandCode, CommandResult, FailureReason, Feedback

__all__ = [
    "IDENTITY_SIZE",
    "Accepted",
    "CloseReason",
    "CommandReceived",
    "Completed",
    "ControlRequested",
    "ControllerIdentity",
    "EmergencyStopRequested",
    "Event",
    "Failed",
    "Granted",
    "PacketRejected",
    "RefusalReceived",
    "RefuseReason",
    "Role",
    "SessionEnded",
    "SessionParameters",
    "TelemetryReceived",
]

IDENTITY_SIZE = 32
"""Bytes of controller name in a HELLO (UTF-8, NUL-padded)."""


class Role(enum.IntEnum):
    """What a connection may do (HELLO flags bit 0; GRANT flags)."""

    CONTROLLER = 0
    """Commands the arm and receives telemetry.  One at a time."""
    OBSERVER = 1
    """Receives telemetry only; any command it sends fails with NOT_AUTHORIZED."""


class RefuseReason(enum.IntEnum):
    """Why the arm refused a connection request (status of a REFUSE packet)."""

    BUSY = 1
    """Another controller holds the arm.  Retry later, or connect as an observer."""
    NOT_AUTHORIZED = 2
    """Authentication failed (worded the same whatever was wrong)."""
    SERVER_FULL = 3
    """The arm serves its maximum number of connections."""
    BAD_HELLO = 4
    """The first packet was not a well-formed HELLO."""
    HANDSHAKE_TIMEOUT = 5
    """The handshake did not finish within the arm's handshake timeout."""
    SHUTTING_DOWN = 6
    """The arm is stopping its server."""


class CloseReason(enum.IntEnum):
    """Why a session ended (status of a BYE packet, and of :class:`SessionEnded`)."""

    NORMAL = 0
    """The controller said goodbye after its commands were done."""
    TERMINATED = 1
    """A TERMINATE command ran: the session ends, the arm resets and listens again."""
    SILENCE = 2
    """Nothing heard for longer than the dead time (the deadman for a controller)."""
    GARBAGE = 3
    """Too many bad packets in a row: the peer is not speaking this protocol."""
    HANDSHAKE_TIMEOUT = 4
    """The handshake did not finish in time."""
    AUTHENTICATION = 5
    """A key mismatch (or a key on one side only) ended the handshake."""
    REFUSED = 6
    """The arm refused the request (see the REFUSE packet's reason)."""
    PEER_EOF = 7
    """The byte stream ended without a BYE."""
    SHUTDOWN = 8
    """The local program closed the session (server stopping, client cancelled)."""
    TAKEN_OVER = 9
    """The same controller connected again; this older connection is retired."""
    IDLE = 10
    """The controller sent no command for the arm's idle timeout; control is released."""
    STALLED = 11
    """The peer stopped reading: output backed up past the bound (local only, no BYE)."""


@dataclass(frozen=True, slots=True)
class ControllerIdentity:
    """Who commands the arm, and the key of the exactly-once memory.

    ``name`` is chosen by the operator (up to 32 bytes of UTF-8);
    ``incarnation`` is a random 64-bit number a client picks once, when it is
    created, and keeps across reconnects.  A restarted controller program gets
    a new incarnation, so its request ids (which start again at 1) can never be
    mistaken for its predecessor's.
    """

    name: str
    incarnation: int


@dataclass(frozen=True, slots=True)
class SessionParameters:
    """The timing the arm grants (GRANT aux words)."""

    heartbeat_interval: float
    """Each side sends a HEARTBEAT when it has sent nothing for this long (s)."""
    dead_time: float
    """Silence longer than this ends the session; for the controller, it is the deadman (s)."""
    telemetry_period: float
    """Seconds between TELEMETRY packets (0: none)."""
    memory_size: int
    """Request ids the arm remembers per controller identity (exactly-once window)."""


class Event:
    """Base of everything a connection reports."""

    __slots__ = ()


# --- arm side ---------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ControlRequested(Event):
    """A (verified, if keyed) controller asks for a role; call ``grant`` or ``refuse``."""

    identity: ControllerIdentity
    role: Role


@dataclass(frozen=True, slots=True)
class CommandReceived(Event):
    """A well-formed, authorised command from the controller (arguments validated)."""

    request_id: int
    command: Command
    failures_seen: int = 0
    """The highest request id of a FAILED reply the controller had received when
    it sent this command (COMMAND aux[0]): the arm skips it if a later failure
    happened that the controller could not have known about."""


@dataclass(frozen=True, slots=True)
class EmergencyStopRequested(Event):
    """Halt now, ahead of the queue."""

    request_id: int


# --- controller side --------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Granted(Event):
    """The arm granted ``role``; ``last_request_id`` is the highest id it remembers for us.

    ``arm_instance`` is a random number the arm's server picks when it starts:
    a different one on a reconnect means the arm restarted and its exactly-once
    memory is gone.  ``remembered`` is False when the arm has no memory of this
    controller (never seen by this arm instance, or forgotten under memory
    pressure): nothing sent before this grant can be resumed.
    """

    role: Role
    parameters: SessionParameters
    last_request_id: int
    arm_instance: int = 0
    remembered: bool = False


@dataclass(frozen=True, slots=True)
class RefusalReceived(Event):
    """The arm refused the request."""

    reason: RefuseReason
    message: str


@dataclass(frozen=True, slots=True)
class Accepted(Event):
    """The command with ``request_id`` is queued at ``position`` (0: running next)."""

    request_id: int
    code: CommandCode
    position: int


@dataclass(frozen=True, slots=True)
class Completed(Event):
    """The command ran; ``result`` is the arm's state after it."""

    request_id: int
    code: CommandCode
    result: CommandResult


@dataclass(frozen=True, slots=True)
class Failed(Event):
    """The command did not run, or stopped part way (request_id 0: an unattributable packet)."""

    request_id: int
    code: int
    reason: FailureReason
    message: str
    aux: tuple[float, float, float, float]


@dataclass(frozen=True, slots=True)
class TelemetryReceived(Event):
    """The arm's state at control sample ``sample``."""

    sample: int
    feedback: Feedback


# --- both -------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class PacketRejected(Event):
    """A packet was dropped (counted): undecodable, bad tag, old counter, wrong state."""

    reason: FailureReason
    message: str


@dataclass(frozen=True, slots=True)
class SessionEnded(Event):
    """The session is over (the connection is CLOSED); ``by_peer`` if the peer ended it."""

    reason: CloseReason
    message: str
    by_peer: bool
