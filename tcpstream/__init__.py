"""tcpstream: fixed-size manipulator command packets over any reliable byte stream.

The socket stream of seed 003 section 9.1: a controlling agent connects, the
manipulator grants or refuses, then fixed-size command packets flow both ways
until the session closes and the manipulator listens again.  The wire format
and the session are specified byte by byte in ``tcpstream/PROTOCOL.md``.

* Arm side: :func:`serve_tcp`, :func:`serve_stream`, :class:`Server` (calls an
  :class:`Executor`: the simulated or real arm).
* Controller side: :func:`connect_tcp`, :func:`connect_stream` (async,
  :class:`ArmClient`), :class:`BlockingClient` (for code that is not async).
* The command contract: :class:`Command`, :class:`CommandCode`,
  :class:`FailureReason`, :class:`Feedback`, :class:`CommandResult`,
  :class:`CommandFailed`; builders in :mod:`tcpstream.commands`.
* Sans-I/O cores for other event loops or tests: :class:`ServerConnection`,
  :class:`ClientConnection`, the codec (:func:`encode_packet`,
  :func:`decode_packet`) and the state table (:data:`TRANSITIONS`).
"""

from importlib.metadata import PackageNotFoundError as _NotInstalled
from importlib.metadata import version as _version

try:
    __version__ = _version("telelink")
    """The telelink distribution's version (pyproject.toml is the one source)."""
except _NotInstalled:  # imported from a source tree that was never installed
    __version__ = "0+unknown"


from . import _builders as commands
from ._api import DEFAULT_PORT, connect_stream, connect_tcp, serve_stream, serve_tcp
from ._blocking import BlockingClient, WatchdogExpired
from ._client import ArmClient, ClientStatistics, CommandHandle
from ._client_connection import ClientConnection
from ._commands import (
    ARGUMENT_WORDS,
    AUX_WORDS,
    JOINTS,
    MAX_PATH_POINTS,
    Command,
    CommandCode,
    CommandFailed,
    CommandFlags,
    CommandResult,
    Executor,
    FailureReason,
    Feedback,
    FeedbackSlot,
    validate_arguments,
)
from ._config import ServerConfig
from ._connection import MAX_BAD_IN_A_ROW, ConnectionStatistics
from ._errors import (
    AuthenticationFailed,
    LocalProtocolError,
    OutcomeUnknown,
    Refused,
    RemoteProtocolError,
    SessionClosed,
    SessionError,
)
from ._events import (
    Accepted,
    CloseReason,
    CommandReceived,
    Completed,
    ControllerIdentity,
    ControlRequested,
    EmergencyStopRequested,
    Event,
    Failed,
    Granted,
    PacketRejected,
    RefusalReceived,
    RefuseReason,
    Role,
    SessionEnded,
    SessionParameters,
    TelemetryReceived,
)
from ._keys import KEY_SIZE, generate_key, load_key_file, write_key_file
from ._options import ClientConfig, ClientOptions
from ._packet import (
    MAGIC,
    PACKET_SIZE,
    PROTOCOL_VERSION,
    BadField,
    BadMagic,
    BadVersion,
    NonFiniteWord,
    Packet,
    PacketError,
    PacketKind,
    UnknownCommand,
    UnknownKind,
    WrongSize,
    decode_packet,
    encode_packet,
)
from ._server import Server, ServerStatistics
from ._server_connection import ServerConnection
from ._state import TRANSITIONS, IllegalTransition, SessionState, Side, Trigger

__all__ = [
    "ARGUMENT_WORDS",
    "AUX_WORDS",
    "DEFAULT_PORT",
    "JOINTS",
    "KEY_SIZE",
    "MAGIC",
    "MAX_BAD_IN_A_ROW",
    "MAX_PATH_POINTS",
    "PACKET_SIZE",
    "PROTOCOL_VERSION",
    "TRANSITIONS",
    "Accepted",
    "ArmClient",
    "AuthenticationFailed",
    "BadField",
    "BadMagic",
    "BadVersion",
    "BlockingClient",
    "ClientConfig",
    "ClientConnection",
    "ClientOptions",
    "ClientStatistics",
    "CloseReason",
    "Command",
    "CommandCode",
    "CommandFailed",
    "CommandFlags",
    "CommandHandle",
    "CommandReceived",
    "CommandResult",
    "Completed",
    "ConnectionStatistics",
    "ControlRequested",
    "ControllerIdentity",
    "EmergencyStopRequested",
    "Event",
    "Executor",
    "Failed",
    "FailureReason",
    "Feedback",
    "FeedbackSlot",
    "Granted",
    "IllegalTransition",
    "LocalProtocolError",
    "NonFiniteWord",
    "OutcomeUnknown",
    "Packet",
    "PacketError",
    "PacketKind",
    "PacketRejected",
    "RefusalReceived",
    "RefuseReason",
    "Refused",
    "RemoteProtocolError",
    "Role",
    "Server",
    "ServerConfig",
    "ServerConnection",
    "ServerStatistics",
    "SessionClosed",
    "SessionEnded",
    "SessionError",
    "SessionParameters",
    "SessionState",
    "Side",
    "TelemetryReceived",
    "Trigger",
    "UnknownCommand",
    "UnknownKind",
    "WatchdogExpired",
    "WrongSize",
    "commands",
    "connect_stream",
    "connect_tcp",
    "decode_packet",
    "encode_packet",
    "generate_key",
    "load_key_file",
    "serve_stream",
    "serve_tcp",
    "validate_arguments",
    "write_key_file",
]
