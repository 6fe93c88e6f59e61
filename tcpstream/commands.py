"""tcpstream.commands: the command set and the packet codec, sans-I/O.

What another implementation of the wire protocol (tcpstream/PROTOCOL.md) or a
decoder needs, and the builders controller code uses.

Builders, one per command (seed 000, 003, 004): :func:`move_to`,
:func:`move_joints`, :func:`status`, :func:`emergency_stop`, ... each returns
a :class:`Command`, range-checked by :func:`validate_arguments`.

The command set (PROTOCOL.md sections 4-5): :class:`CommandCode`,
:class:`CommandFlags`, :class:`Command` (:data:`ARGUMENT_WORDS` argument
words, :data:`JOINTS`, :data:`MAX_PATH_POINTS`), the feedback array
:class:`Feedback` in :class:`FeedbackSlot` order, :class:`FailureReason`.

The packet codec (PROTOCOL.md sections 1-3): a :class:`Packet` of a
:class:`PacketKind` is :data:`PACKET_SIZE` bytes (:data:`SIGNED_SIZE` signed,
then :data:`TAG_SIZE` of tag; :data:`AUX_WORDS` aux words and a
:data:`BODY_SIZE` body), starting with :data:`MAGIC` and
:data:`PROTOCOL_VERSION`.  :func:`encode_packet` / :func:`decode_packet`;
bodies with :func:`words_body`, :func:`pack_text`, :func:`unpack_text`
(:data:`NUMERIC_KINDS` carry words).  A bad packet raises a
:class:`PacketError`: :class:`WrongSize`, :class:`BadMagic`,
:class:`BadVersion`, :class:`UnknownKind`, :class:`BadField`,
:class:`NonFiniteWord` or :class:`UnknownCommand`.
"""

from ._builders import add_obstacle as add_obstacle
from ._builders import center_fingers as center_fingers
from ._builders import change_speed as change_speed
from ._builders import close_fingers as close_fingers
from ._builders import emergency_stop as emergency_stop
from ._builders import move_delta as move_delta
from ._builders import move_joint as move_joint
from ._builders import move_joints as move_joints
from ._builders import move_path as move_path
from ._builders import move_to as move_to
from ._builders import open_fingers as open_fingers
from ._builders import reinitialize as reinitialize
from ._builders import squeeze as squeeze
from ._builders import status as status
from ._builders import terminate as terminate
from ._builders import transform_to_joints as transform_to_joints
from ._builders import transform_to_pose as transform_to_pose
from ._builders import weigh as weigh
from ._commands import ARGUMENT_WORDS as ARGUMENT_WORDS
from ._commands import AUX_WORDS as AUX_WORDS
from ._commands import JOINTS as JOINTS
from ._commands import MAX_PATH_POINTS as MAX_PATH_POINTS
from ._commands import Command as Command
from ._commands import CommandCode as CommandCode
from ._commands import CommandFlags as CommandFlags
from ._commands import FailureReason as FailureReason
from ._commands import Feedback as Feedback
from ._commands import FeedbackSlot as FeedbackSlot
from ._commands import validate_arguments as validate_arguments
from ._packet import BODY_SIZE as BODY_SIZE
from ._packet import MAGIC as MAGIC
from ._packet import NUMERIC_KINDS as NUMERIC_KINDS
from ._packet import PACKET_SIZE as PACKET_SIZE
from ._packet import PROTOCOL_VERSION as PROTOCOL_VERSION
from ._packet import SIGNED_SIZE as SIGNED_SIZE
from ._packet import TAG_SIZE as TAG_SIZE
from ._packet import BadField as BadField
from ._packet import BadMagic as BadMagic
from ._packet import BadVersion as BadVersion
from ._packet import NonFiniteWord as NonFiniteWord
from ._packet import Packet as Packet
from ._packet import PacketError as PacketError
from ._packet import PacketKind as PacketKind
from ._packet import UnknownCommand as UnknownCommand
from ._packet import UnknownKind as UnknownKind
from ._packet import WrongSize as WrongSize
from ._packet import decode_packet as decode_packet
from ._packet import encode_packet as encode_packet
from ._packet import pack_text as pack_text
from ._packet import unpack_text as unpack_text
from ._packet import words_body as words_body

__all__ = [
    "ARGUMENT_WORDS",
    "AUX_WORDS",
    "BODY_SIZE",
    "JOINTS",
    "MAGIC",
    "MAX_PATH_POINTS",
    "NUMERIC_KINDS",
    "PACKET_SIZE",
    "PROTOCOL_VERSION",
    "SIGNED_SIZE",
    "TAG_SIZE",
    "BadField",
    "BadMagic",
    "BadVersion",
    "Command",
    "CommandCode",
    "CommandFlags",
    "FailureReason",
    "Feedback",
    "FeedbackSlot",
    "NonFiniteWord",
    "Packet",
    "PacketError",
    "PacketKind",
    "UnknownCommand",
    "UnknownKind",
    "WrongSize",
    "add_obstacle",
    "center_fingers",
    "change_speed",
    "close_fingers",
    "decode_packet",
    "emergency_stop",
    "encode_packet",
    "move_delta",
    "move_joint",
    "move_joints",
    "move_path",
    "move_to",
    "open_fingers",
    "pack_text",
    "reinitialize",
    "squeeze",
    "status",
    "terminate",
    "transform_to_joints",
    "transform_to_pose",
    "unpack_text",
    "validate_arguments",
    "weigh",
    "words_body",
]
