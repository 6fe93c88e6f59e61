"""The teleoperation channel: a hand controller streaming samples to the arm (PROTOCOL.md 14).

Seed 004's forward loop -- every sampling interval the hand controller's
increments go to the remote site and force/torque comes back -- over any
reliable stream, beside the command session (its own stream: a second TCP
connection, or its own serial socket), authenticated with the same pre-shared
key.  Latest value both ways: a sample overtaken by a newer one is never sent,
and increments are accumulated at the sender so a skipped sample loses no
motion.  A STOP overtakes every sample not yet on the line.

Operator: :func:`open_teleop` gives a :class:`TeleopOperator`; call
``submit(Sample(...))`` every sample and ``emergency_stop()`` when needed.
Arm: :class:`TeleopArm` with ``serve_stream(stream)``; its control loop reads
``latest()`` and answers ``reply(Reply(...))``.  The sans-I/O ends
(:class:`OperatorChannel`, :class:`ArmChannel`) and the codec are here too.
Both on one line (a serial socket): :func:`open_mux` splits a stream into a
command channel and a sample channel, commands always first.
"""

from __future__ import annotations

from ._teleop import TeleopArm, TeleopOperator, TeleopRefused, open_teleop
from ._teleop_connection import ArmChannel, OperatorChannel
from ._teleop_mux import COMMANDS, MAX_FRAME, TELEOP, MuxChannel, StreamMux, open_mux
from ._teleop_packet import (
    MAGIC,
    TAG_SIZE,
    TELEOP_VERSION,
    Buttons,
    ContactFlags,
    Reply,
    ReplyStatus,
    Sample,
    TeleopKind,
    TeleopMode,
    TeleopPacketError,
    decode_header,
    decode_reply,
    decode_sample,
    encode_reply,
    encode_sample,
    size_of,
)
from ._teleop_state import (
    TRANSITIONS,
    Backlog,
    ChannelClosed,
    ChannelState,
    ChannelStatistics,
    Granted,
    IllegalTransition,
    OperatorArrived,
    RefuseCode,
    Refused,
    ReplyReceived,
    SampleArrived,
    StopArrived,
    TeleopEvent,
)

__all__ = [
    "COMMANDS",
    "MAGIC",
    "MAX_FRAME",
    "TAG_SIZE",
    "TELEOP",
    "TELEOP_VERSION",
    "TRANSITIONS",
    "ArmChannel",
    "Backlog",
    "Buttons",
    "ChannelClosed",
    "ChannelState",
    "ChannelStatistics",
    "ContactFlags",
    "Granted",
    "IllegalTransition",
    "MuxChannel",
    "OperatorArrived",
    "OperatorChannel",
    "RefuseCode",
    "Refused",
    "Reply",
    "ReplyReceived",
    "ReplyStatus",
    "Sample",
    "SampleArrived",
    "StopArrived",
    "StreamMux",
    "TeleopArm",
    "TeleopEvent",
    "TeleopKind",
    "TeleopMode",
    "TeleopOperator",
    "TeleopPacketError",
    "TeleopRefused",
    "decode_header",
    "decode_reply",
    "decode_sample",
    "encode_reply",
    "encode_sample",
    "open_mux",
    "open_teleop",
    "size_of",
]
