"""serialsocket.capture: what crossed a line or a stream, to a pcapng file for Wireshark.

:class:`CaptureFile` writes a pcapng file; :class:`CapturingStream` wraps a
port or any trio stream and records what it sends (outbound) and receives
(inbound), each with its time.  ``serialsocket listen|connect --capture``,
``linksim relay --capture`` and ``linksim arm-server --capture`` use them.

The file format is built sans-I/O by :class:`PcapngWriter` and parsed back by
:func:`read_pcapng` (into a :class:`Capture` of :class:`Interface` s and
:class:`CapturedPacket` s with a :class:`Direction`).  Link types:
:data:`LINKTYPE_SERIAL` (LINKTYPE_USER0, 147: the bytes of a serial line) and
:data:`LINKTYPE_TCPSTREAM` (LINKTYPE_USER1, 148: a tcpstream session).  The
Wireshark dissector ``contrib/wireshark/telelink.lua`` decodes both::

    tshark -X lua_script:contrib/wireshark/telelink.lua -r run.pcapng -V
"""

from ._capture import CaptureFile as CaptureFile
from ._capture import CapturingStream as CapturingStream
from ._pcapng import LINKTYPE_SERIAL as LINKTYPE_SERIAL
from ._pcapng import LINKTYPE_TCPSTREAM as LINKTYPE_TCPSTREAM
from ._pcapng import Capture as Capture
from ._pcapng import CapturedPacket as CapturedPacket
from ._pcapng import Direction as Direction
from ._pcapng import Interface as Interface
from ._pcapng import PcapngError as PcapngError
from ._pcapng import PcapngWriter as PcapngWriter
from ._pcapng import read_pcapng as read_pcapng

__all__ = [
    "LINKTYPE_SERIAL",
    "LINKTYPE_TCPSTREAM",
    "Capture",
    "CaptureFile",
    "CapturedPacket",
    "CapturingStream",
    "Direction",
    "Interface",
    "PcapngError",
    "PcapngWriter",
    "read_pcapng",
]
