"""serialsocket.packets: layer 2, Kermit packets, sans-I/O.

Framing (reference/kermit.md; serialsocket/PROTOCOL.md sections 1-2): a
:class:`Packet` (``seq``, ``type`` as a :class:`PacketType`, ``data``) is
turned into wire bytes by :func:`build_packet` (normal packets up to LEN 94,
extended beyond); :func:`packet_length` and :func:`data_capacity` convert
between data and packet sizes.  Lengths count MARK through CHECK:
:data:`MIN_PACKET_LENGTH` .. :data:`MAX_PACKET_LENGTH`, default
:data:`DEFAULT_MAX_PACKET_LENGTH`.

Block checks: :class:`BlockCheck` (types 1, 2 and 3), :func:`check_chars`,
:func:`crc16_kermit` (CRC-16/KERMIT); :func:`crc32_ieee` and
:func:`crc32_chars` (CRC-32, ``BlockCheck.CRC32`` when two telelink ends agree).  Prefix encoding:
:class:`Encoding`, with the profiles :data:`PRINTABLE` (the default: printable
output) and :data:`EIGHT_BIT_CLEAN` (no 8th-bit prefixing).

Dense encodings for telelink-to-telelink links (negotiated in the init
exchange, serialsocket/PROTOCOL.md section 10; design notes in DENSE.md):
:class:`EscapeEncoding` (8-bit lines: escape only MARK, the escape byte and
declared unsafe bytes such as :data:`XON_XOFF`) and :class:`Radix91Encoding`
(printable lines: 16 characters per 13 bytes).

Corrected data packets (negotiated likewise, PROTOCOL.md section 15):
:func:`build_corrected` builds a ``d`` packet, a ``D`` whose data is
followed by sums that let a :class:`PacketParser` with ``correction`` on
repair one damaged character per block of 255; :func:`repair_field` the
data of a repair packet (``r``, 15.6), the sums of a ``D`` sent without
them, which a receiver uses on the damaged copy it kept.

Parsing: :class:`PacketParser` takes any bytes, line noise included, and
yields :data:`ParserEvent` s, :class:`PacketReceived` or
:class:`PacketRejected` (with a :class:`RejectReason`); it counts them in
:class:`ParserStatistics`.

Connection parameters of telelink's own protocol (the S / ACK(S) exchange):
:class:`InitParameters`, the agreed :class:`Negotiated` values (also carried
by :class:`serialsocket.Connected`), :data:`PROTOCOL_VERSION`.
"""

from ._checks import BlockCheck as BlockCheck
from ._checks import check_chars as check_chars
from ._checks import crc16_kermit as crc16_kermit
from ._checks import crc32_chars as crc32_chars
from ._checks import crc32_ieee as crc32_ieee
from ._dense import XON_XOFF as XON_XOFF
from ._dense import EscapeEncoding as EscapeEncoding
from ._dense import Radix91Encoding as Radix91Encoding
from ._encoding import EIGHT_BIT_CLEAN as EIGHT_BIT_CLEAN
from ._encoding import PRINTABLE as PRINTABLE
from ._encoding import Encoding as Encoding
from ._fec import build_corrected as build_corrected
from ._fec import repair_field as repair_field
from ._packet import Packet as Packet
from ._packet import build_packet as build_packet
from ._packet import data_capacity as data_capacity
from ._packet import packet_length as packet_length
from ._params import PROTOCOL_VERSION as PROTOCOL_VERSION
from ._params import InitParameters as InitParameters
from ._params import Negotiated as Negotiated
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
    "PROTOCOL_VERSION",
    "XON_XOFF",
    "BlockCheck",
    "Encoding",
    "EscapeEncoding",
    "InitParameters",
    "Negotiated",
    "Packet",
    "PacketParser",
    "PacketReceived",
    "PacketRejected",
    "PacketType",
    "ParserEvent",
    "ParserStatistics",
    "Radix91Encoding",
    "RejectReason",
    "build_corrected",
    "build_packet",
    "check_chars",
    "crc16_kermit",
    "crc32_chars",
    "crc32_ieee",
    "data_capacity",
    "packet_length",
    "repair_field",
]
