"""serialsocket: a socket-like, reliable, sequenced, full-duplex byte stream over a serial line.

Layer 1, port I/O: :func:`open_port` opens a serial device, a pty or a
pyserial URL as a trio stream (8N1, raw); :func:`open_pty_pair` makes a
connected raw pty pair; :func:`dial`, :func:`answer` and :func:`hangup` drive
a Hayes modem.  Layer 2, packets (:mod:`serialsocket.packets`): Kermit
packets with CRC-16/KERMIT block checks, the prefix encoding that keeps
packets printable, and an incremental parser that survives any line noise.
Layer 3, ARQ: :class:`Endpoint`, a connected, reliable, sequenced,
full-duplex byte stream with selective-repeat windows and timers sized for
slow, long-delay lines.  Layers 2 and 3 are sans-I/O: bytes and ``now`` in,
bytes, events and timer deadlines out.

:class:`SerialSocket` (``connect``, ``accept``, ``listen``, ``serve``) runs
the endpoint over a port as a trio ``HalfCloseableStream``;
:class:`BlockingSerialSocket` offers the same to code that is not async, and
:mod:`serialsocket.asyncio` to asyncio code (it never imports trio).
:class:`EndpointConfig`'s ``check`` and ``encoding`` come from
:mod:`serialsocket.packets`.

Kermit file transfer on the same packet layer is :mod:`serialsocket.kermit`
(sans-I/O sender and receiver, ``kermit_send`` / ``kermit_receive`` over a
port); it interoperates with C-Kermit and G-Kermit
(``python -m serialsocket kermit send|receive``; serialsocket/KERMIT.md).
"""

from importlib import import_module
from importlib.metadata import PackageNotFoundError as _NotInstalled
from importlib.metadata import version as _version
from typing import TYPE_CHECKING

try:
    __version__ = _version("telelink")
    """The telelink distribution's version (pyproject.toml is the one source)."""
except _NotInstalled:  # imported from a source tree that was never installed
    __version__ = "0+unknown"


from ._config import MAX_WINDOW as MAX_WINDOW
from ._config import EndpointConfig as EndpointConfig
from ._endpoint import Endpoint as Endpoint
from ._endpoint import EndpointStatistics as EndpointStatistics
from ._errors import LocalProtocolError as LocalProtocolError
from ._errors import MalformedDataError as MalformedDataError
from ._errors import ProtocolError as ProtocolError
from ._errors import RemoteProtocolError as RemoteProtocolError
from ._events import Connected as Connected
from ._events import ConnectionAborted as ConnectionAborted
from ._events import ConnectionClosed as ConnectionClosed
from ._events import ConnectionRequested as ConnectionRequested
from ._events import EndOfStream as EndOfStream
from ._events import Event as Event
from ._events import LinkDead as LinkDead
from ._outcome import LineFailed as LineFailed
from ._outcome import LinkBroken as LinkBroken
from ._outcome import LinkDeadError as LinkDeadError
from ._outcome import PeerAborted as PeerAborted
from ._outcome import SocketStatistics as SocketStatistics
from ._pyserial import PortStatistics as PortStatistics
from ._state import State as State

if TYPE_CHECKING:
    from ._blocking import BlockingSerialSocket as BlockingSerialSocket
    from ._hayes import DialError as DialError
    from ._hayes import LineBusy as LineBusy
    from ._hayes import ModemConnection as ModemConnection
    from ._hayes import ModemError as ModemError
    from ._hayes import ModemTimeout as ModemTimeout
    from ._hayes import NoAnswer as NoAnswer
    from ._hayes import NoCarrier as NoCarrier
    from ._hayes import NoDialtone as NoDialtone
    from ._hayes import answer as answer
    from ._hayes import dial as dial
    from ._hayes import hangup as hangup
    from ._port import SerialPort as SerialPort
    from ._port import open_port as open_port
    from ._port import open_pty_pair as open_pty_pair
    from ._socket import SerialListener as SerialListener
    from ._socket import SerialSocket as SerialSocket
    from ._socket import accept as accept
    from ._socket import connect as connect
    from ._socket import listen as listen
    from ._socket import open_serial_socket as open_serial_socket
    from ._socket import serve as serve

_TRIO_NAMES = {
    "BlockingSerialSocket": "_blocking",
    "DialError": "_hayes",
    "LineBusy": "_hayes",
    "ModemConnection": "_hayes",
    "ModemError": "_hayes",
    "ModemTimeout": "_hayes",
    "NoAnswer": "_hayes",
    "NoCarrier": "_hayes",
    "NoDialtone": "_hayes",
    "answer": "_hayes",
    "dial": "_hayes",
    "hangup": "_hayes",
    "SerialPort": "_port",
    "open_port": "_port",
    "open_pty_pair": "_port",
    "SerialListener": "_socket",
    "SerialSocket": "_socket",
    "accept": "_socket",
    "connect": "_socket",
    "listen": "_socket",
    "open_serial_socket": "_socket",
    "serve": "_socket",
}
"""Names from the modules that import trio (the trio sockets, the ports, the
modem dialer, the blocking facade): loaded on first use, so that
``import serialsocket.asyncio`` never imports trio.  The imports above, under
TYPE_CHECKING, are what type checkers and the import-graph test see."""


def __getattr__(name: str) -> object:
    module = _TRIO_NAMES.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f"{__name__}.{module}"), name)
    globals()[name] = value  # once loaded, an ordinary attribute
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_TRIO_NAMES))


__all__ = [
    "MAX_WINDOW",
    "BlockingSerialSocket",
    "Connected",
    "ConnectionAborted",
    "ConnectionClosed",
    "ConnectionRequested",
    "DialError",
    "EndOfStream",
    "Endpoint",
    "EndpointConfig",
    "EndpointStatistics",
    "Event",
    "LineBusy",
    "LineFailed",
    "LinkBroken",
    "LinkDead",
    "LinkDeadError",
    "LocalProtocolError",
    "MalformedDataError",
    "ModemConnection",
    "ModemError",
    "ModemTimeout",
    "NoAnswer",
    "NoCarrier",
    "NoDialtone",
    "PeerAborted",
    "PortStatistics",
    "ProtocolError",
    "RemoteProtocolError",
    "SerialListener",
    "SerialPort",
    "SerialSocket",
    "SocketStatistics",
    "State",
    "accept",
    "answer",
    "connect",
    "dial",
    "hangup",
    "listen",
    "open_port",
    "open_pty_pair",
    "open_serial_socket",
    "serve",
]
