"""serialsocket.kermit: Kermit file transfer, interoperable with C-Kermit and G-Kermit.

Kermit's own half-duplex file-transfer protocol (S, F, A, D..., Z, B) on the
same packet layer as the serial socket (:mod:`serialsocket.packets`): sliding
windows up to :data:`MAX_KERMIT_WINDOW`, long packets, CRC-16 block checks,
8th-bit and repeat prefixes, attribute packets (size, type, date,
disposition), RESEND/REGET/PSEND recovery, text mode, FORCE-3, streaming on
reliable transports, name conversion, and server mode.

Over a port (any ``trio.abc.Stream``, e.g. :func:`serialsocket.open_port`)::

    from serialsocket import open_port
    from serialsocket.kermit import KermitConfig, kermit_receive, kermit_send

    port = await open_port("/dev/ttyS0", 9600)
    stats = await kermit_send(port, ["a.bin", "b.txt"], KermitConfig(window=8))
    stats = await kermit_receive(port, "incoming/", KermitConfig())

Both return :class:`KermitStatistics` only when every file is confirmed whole,
and raise :class:`KermitTransferError` (``by_peer``, ``statistics``) otherwise;
``on_event=`` sees each :data:`KermitEvent`.

Sans-I/O, like :class:`serialsocket.Endpoint`: :class:`KermitSender`
(``files``: :class:`OutgoingFile` s) and :class:`KermitReceiver` take
``receive_data(bytes, now)`` and ``handle_timer(now)``; give
``data_to_send()``, ``next_event()`` and ``get_timer()``; report
``state`` (:class:`KermitState`) and ``statistics()``.  Events:
:class:`FileStarted`, :class:`FileData` (receiver), :class:`FileCompleted`,
then :class:`TransferComplete` or :class:`TransferFailed`.

:class:`KermitConfig` holds the local settings (``max_packet_length``,
``window``, ``check`` as a :class:`serialsocket.packets.BlockCheck`,
``timeout``, ``retry_limit``, ``seven_bit``, ``repeat``, ``attributes``,
the line hints ``delay`` and ``rate``, ``dynamic_length``, ``force3``,
``streaming``, ``recovery``, ``resend``, ``text``, ``literal_names``).
Server mode: :func:`kermit_server` serves a directory until FINISH or BYE
(:class:`KermitServer` is its sans-I/O core); :func:`kermit_get` and
:func:`kermit_remote` (one of :data:`REMOTE_COMMANDS`) are the client.
Command line: ``python -m serialsocket kermit send|receive|server|get|remote``;
details and interop notes: serialsocket/KERMIT.md.
"""

from ._core import FileCompleted as FileCompleted
from ._core import FileData as FileData
from ._core import FileStarted as FileStarted
from ._core import KermitEvent as KermitEvent
from ._core import KermitState as KermitState
from ._core import KermitStatistics as KermitStatistics
from ._core import OutgoingFile as OutgoingFile
from ._core import RemoteReply as RemoteReply
from ._core import TransferComplete as TransferComplete
from ._core import TransferFailed as TransferFailed
from ._io import KermitTransferError as KermitTransferError
from ._io import kermit_receive as kermit_receive
from ._io import kermit_send as kermit_send
from ._params import MAX_KERMIT_WINDOW as MAX_KERMIT_WINDOW
from ._params import KermitConfig as KermitConfig
from ._receiver import KermitReceiver as KermitReceiver
from ._sender import KermitSender as KermitSender
from ._serve import REMOTE_COMMANDS as REMOTE_COMMANDS
from ._serve import kermit_get as kermit_get
from ._serve import kermit_remote as kermit_remote
from ._serve import kermit_server as kermit_server
from ._server import KermitServer as KermitServer
from ._server import ServerRequest as ServerRequest
from ._server import TransactionEnded as TransactionEnded
from ._server import TransactionStarted as TransactionStarted

__all__ = [
    "MAX_KERMIT_WINDOW",
    "REMOTE_COMMANDS",
    "FileCompleted",
    "FileData",
    "FileStarted",
    "KermitConfig",
    "KermitEvent",
    "KermitReceiver",
    "KermitSender",
    "KermitServer",
    "KermitState",
    "KermitStatistics",
    "KermitTransferError",
    "OutgoingFile",
    "RemoteReply",
    "ServerRequest",
    "TransactionEnded",
    "TransactionStarted",
    "TransferComplete",
    "TransferFailed",
    "kermit_get",
    "kermit_receive",
    "kermit_remote",
    "kermit_send",
    "kermit_server",
]
