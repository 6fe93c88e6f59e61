"""tcpstream: fixed-size manipulator command packets over any reliable byte stream.

The socket stream of seed 003 section 9.1: a controlling agent connects, the
manipulator grants or refuses, then fixed-size command packets flow both ways
until the session closes and the manipulator listens again.  The wire format
and the session are specified byte by byte in ``tcpstream/PROTOCOL.md``.

* Controller side: :func:`connect_tcp`, :func:`connect_stream` (trio,
  :class:`ArmClient`, :class:`CommandHandle`), :class:`BlockingClient` (for
  code that is not async), :mod:`tcpstream.asyncio` (for asyncio); settings
  in :class:`ClientConfig` / :class:`ClientOptions`.
* Arm side: :func:`serve_tcp`, :func:`serve_stream`, :class:`Server` (calls an
  :class:`Executor`: the simulated or real arm), :class:`ServerConfig`.
* The command contract: :class:`Command`, :class:`CommandCode`,
  :class:`CommandResult`, :class:`Feedback`, :class:`CommandFailed` with a
  :class:`FailureReason`; builders (``move_to``, ``status``, ...) in
  :mod:`tcpstream.commands`.
* Errors: :class:`SessionError` (:class:`Refused`, :class:`AuthenticationFailed`,
  :class:`SessionClosed`, :class:`OutcomeUnknown`), :class:`LocalProtocolError`.
* Keys: :func:`generate_key`, :func:`load_key_file`, :func:`write_key_file`.

Public submodules: :mod:`tcpstream.commands` (the command set and the packet
codec: everything another implementation of the wire protocol needs) and
:mod:`tcpstream.connection` (the sans-I/O connection cores, their events and
the session state table, for other event loops and tests).
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
