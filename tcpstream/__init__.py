"""tcpstream: fixed-size manipulator command packets over any reliable byte stream.

Seed 003's socket stream (specified byte by byte in ``tcpstream/PROTOCOL.md``):
a controller connects, the arm grants or refuses, then 216-byte command
packets flow both ways until the session closes.

Controller: :func:`connect_tcp` / :func:`connect_stream` give an
:class:`ArmClient` (trio); :class:`BlockingClient` for code that is not async;
:mod:`tcpstream.asyncio` for asyncio.  Arm: :func:`serve_tcp`,
:func:`serve_stream`, :class:`Server`, which calls an :class:`Executor`.

Public submodules: :mod:`tcpstream.commands` (builders such as ``move_to``,
the command set and the packet codec: what another implementation of the
wire protocol needs), :mod:`tcpstream.connection` (the sans-I/O
connection cores, their events and the session state table) and
:mod:`tcpstream.teleop` (seed 004's teleoperation sample channel).
"""

from importlib.metadata import PackageNotFoundError as _NotInstalled
from importlib.metadata import version as _version

try:
    __version__ = _version("telelink")
    """The telelink distribution's version (pyproject.toml is the one source)."""
except _NotInstalled:  # imported from a source tree that was never installed
    __version__ = "0+unknown"


from . import commands as commands
from . import connection as connection
from . import teleop as teleop
from ._api import DEFAULT_PORT, connect_stream, connect_tcp, serve_stream, serve_tcp
from ._blocking import BlockingClient, WatchdogExpired
from ._client import ArmClient, ClientStatistics, CommandHandle
from ._commands import (
    Command,
    CommandCode,
    CommandFailed,
    CommandResult,
    Executor,
    FailureReason,
    Feedback,
)
from ._config import ServerConfig
from ._errors import (
    AuthenticationFailed,
    LocalProtocolError,
    OutcomeUnknown,
    Refused,
    SessionClosed,
    SessionError,
)
from ._events import CloseReason, RefuseReason
from ._keys import KEY_SIZE, generate_key, load_key_file, write_key_file
from ._options import ClientConfig, ClientOptions
from ._server import Server, ServerStatistics

__all__ = [
    "DEFAULT_PORT",
    "KEY_SIZE",
    "ArmClient",
    "AuthenticationFailed",
    "BlockingClient",
    "ClientConfig",
    "ClientOptions",
    "ClientStatistics",
    "CloseReason",
    "Command",
    "CommandCode",
    "CommandFailed",
    "CommandHandle",
    "CommandResult",
    "Executor",
    "FailureReason",
    "Feedback",
    "LocalProtocolError",
    "OutcomeUnknown",
    "RefuseReason",
    "Refused",
    "Server",
    "ServerConfig",
    "ServerStatistics",
    "SessionClosed",
    "SessionError",
    "WatchdogExpired",
    "connect_stream",
    "connect_tcp",
    "generate_key",
    "load_key_file",
    "serve_stream",
    "serve_tcp",
    "write_key_file",
]
