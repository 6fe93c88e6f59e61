"""serialsocket: a socket-like, reliable, sequenced, full-duplex byte stream over a serial line.

Layer 2 (this release): Kermit packets with CRC-16/KERMIT block checks, the
prefix encoding that keeps packets printable, and an incremental parser that
survives any line noise.  All of it is sans-I/O: bytes in, packets and events
out, no clocks or sockets inside.
"""

from ._checks import BlockCheck as BlockCheck
from ._checks import check_chars as check_chars
from ._checks import crc16_kermit as crc16_kermit
from ._encoding import EIGHT_BIT_CLEAN as EIGHT_BIT_CLEAN
from ._encoding import PRINTABLE as PRINTABLE
from ._encoding import Encoding as Encoding
from ._errors import LocalProtocolError as LocalProtocolError
from ._errors import MalformedDataError as MalformedDataError
from ._errors import ProtocolError as ProtocolError
from ._errors import RemoteProtocolError as RemoteProtocolError
from ._packet import Packet as Packet
from ._packet import build_packet as build_packet
from ._packet import data_capacity as data_capacity
from ._packet import packet_length as packet_length
from ._parser import PacketParser as PacketParser
from ._parser import PacketReceived as PacketReceived
from ._parser import PacketRejected as PacketRejected
from ._parser import ParserEvent as ParserEvent
from ._parser import ParserStatistics as ParserStatistics
from ._parser import RejectReason as RejectReason
from ._wire import DEFAULT_MAX_PACKET_LENGTH as DEFAULT_MAX_PACKET_LENGTH
from ._wire import MAX_PACKET_LENGTH as MAX_PACKET_LENGTH
from ._wire import MIN_PACKET_LENGTH as MIN_PACKET_LENGTH
from ._wire import PacketType as PacketType

__all__ = [
    "DEFAULT_MAX_PACKET_LENGTH",
    "EIGHT_BIT_CLEAN",
    "MAX_PACKET_LENGTH",
    "MIN_PACKET_LENGTH",
    "PRINTABLE",
    "BlockCheck",
    "Encoding",
    "LocalProtocolError",
    "MalformedDataError",
    "Packet",
    "PacketParser",
    "PacketReceived",
    "PacketRejected",
    "PacketType",
    "ParserEvent",
    "ParserStatistics",
    "ProtocolError",
    "RejectReason",
    "RemoteProtocolError",
    "build_packet",
    "check_chars",
    "crc16_kermit",
    "data_capacity",
    "packet_length",
]
