"""tcpstream.connection: the sans-I/O session cores, h11-style.

A connection is a plain object: feed it bytes (``receive_data``) and the time
(``handle_timer``), take bytes (``data_to_send``) and events
(``next_event``), and ask ``get_timer`` when to call back.  No clock, socket
or task inside.  :class:`ServerConnection` is the arm's end,
:class:`ClientConnection` the controller's (it is what
:class:`tcpstream.ArmClient` and :mod:`tcpstream.asyncio` drive); both count
in :class:`ConnectionStatistics` and give up after :data:`MAX_BAD_IN_A_ROW`
bad packets in a row.

Events (subclasses of :class:`Event`): at the arm :class:`ControlRequested`
(a :class:`ControllerIdentity` asking for a :class:`Role`),
:class:`CommandReceived`, :class:`EmergencyStopRequested`; at the controller
:class:`Granted` (with :class:`SessionParameters`), :class:`RefusalReceived`
(a :class:`RefuseReason`), :class:`Accepted`, :class:`Completed`,
:class:`Failed`, :class:`TelemetryReceived`; at both
:class:`PacketRejected` (a bad packet, counted and answered) and
:class:`SessionEnded` (a :class:`CloseReason`).

The session's state machine (PROTOCOL.md section 7): :class:`SessionState`,
one table :data:`TRANSITIONS` keyed by :class:`Side`, state and
:class:`Trigger`, applied by :func:`transition`; anything not in it raises
:class:`IllegalTransition`, a :class:`LocalProtocolError` (this program
misused the API; :class:`RemoteProtocolError` is the peer's fault).  The
packets themselves are :mod:`tcpstream.commands`.
"""

from ._client_connection import ClientConnection as ClientConnection
from ._connection import MAX_BAD_IN_A_ROW as MAX_BAD_IN_A_ROW
from ._connection import ConnectionStatistics as ConnectionStatistics
from ._errors import LocalProtocolError as LocalProtocolError
from ._errors import RemoteProtocolError as RemoteProtocolError
from ._events import IDENTITY_SIZE as IDENTITY_SIZE
from ._events import Accepted as Accepted
from ._events import CloseReason as CloseReason
from ._events import CommandReceived as CommandReceived
from ._events import Completed as Completed
from ._events import ControllerIdentity as ControllerIdentity
from ._events import ControlRequested as ControlRequested
from ._events import EmergencyStopRequested as EmergencyStopRequested
from ._events import Event as Event
from ._events import Failed as Failed
from ._events import Granted as Granted
from ._events import PacketRejected as PacketRejected
from ._events import RefusalReceived as RefusalReceived
from ._events import RefuseReason as RefuseReason
from ._events import Role as Role
from ._events import SessionEnded as SessionEnded
from ._events import SessionParameters as SessionParameters
from ._events import TelemetryReceived as TelemetryReceived
from ._server_connection import ServerConnection as ServerConnection
from ._state import TRANSITIONS as TRANSITIONS
from ._state import IllegalTransition as IllegalTransition
from ._state import SessionState as SessionState
from ._state import Side as Side
from ._state import Trigger as Trigger
from ._state import transition as transition

__all__ = [
    "IDENTITY_SIZE",
    "MAX_BAD_IN_A_ROW",
    "TRANSITIONS",
    "Accepted",
    "ClientConnection",
    "CloseReason",
    "CommandReceived",
    "Completed",
    "ConnectionStatistics",
    "ControlRequested",
    "ControllerIdentity",
    "EmergencyStopRequested",
    "Event",
    "Failed",
    "Granted",
    "IllegalTransition",
    "LocalProtocolError",
    "PacketRejected",
    "RefusalReceived",
    "RefuseReason",
    "RemoteProtocolError",
    "Role",
    "ServerConnection",
    "SessionEnded",
    "SessionParameters",
    "SessionState",
    "Side",
    "TelemetryReceived",
    "Trigger",
    "transition",
]
