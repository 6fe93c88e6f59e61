"""Architecture rules that keep the layers honest (ARCHITECTURE.md)."""

from __future__ import annotations

import ast
import pathlib

import pytest

import serialsocket
import tcpstream

ROOT = pathlib.Path(__file__).resolve().parents[1]

# Sans-I/O modules: bytes and `now` in, bytes and events out.  Nothing that
# touches a clock, a socket, a thread, a port or global randomness.
SANS_IO = [
    "_checks",
    "_config",
    "_dense",
    "_diagram",
    "_encoding",
    "_endpoint",
    "_errors",
    "_events",
    "_outcome",
    "_pacer",
    "_packet",
    "_params",
    "_parser",
    "_pcapng",
    "_receiver",
    "_rtt",
    "_sender",
    "_state",
    "_wire",
    "kermit/_attributes",
    "kermit/_core",
    "kermit/_params",
    "kermit/_receiver",
    "kermit/_sender",
    "kermit/_server",
    "kermit/_window",
]
FORBIDDEN_IN_CORE = {
    "trio",
    "serial",
    "socket",
    "time",
    "random",
    "threading",
    "asyncio",
    "os",
    "select",
}


def imports_of(path: pathlib.Path) -> set[str]:
    tree = ast.parse(path.read_text())
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


@pytest.mark.parametrize("module", SANS_IO)
def test_core_modules_are_sans_io(module: str) -> None:
    bad = imports_of(ROOT / "serialsocket" / f"{module}.py") & FORBIDDEN_IN_CORE
    assert not bad, f"serialsocket/{module}.py imports {bad}"


# The asyncio adapter and everything it shares with the trio glue: no trio
# (tests/serialsocket/test_asyncio_socket.py runs it with trio unimportable).
TRIO_FREE = ["asyncio", "_asyncio_driver", "_asyncio_port", "_asyncio_streams", "_pyserial"]


@pytest.mark.parametrize("module", TRIO_FREE)
def test_the_asyncio_path_never_imports_trio(module: str) -> None:
    assert "trio" not in imports_of(ROOT / "serialsocket" / f"{module}.py")


@pytest.mark.parametrize(
    ("package", "forbidden"),
    [("serialsocket", {"tcpstream", "linksim"}), ("tcpstream", {"serialsocket", "linksim"})],
)
def test_import_direction(package: str, forbidden: set[str]) -> None:
    for path in (ROOT / package).rglob("*.py"):
        assert not imports_of(path) & forbidden, f"{path} imports {imports_of(path) & forbidden}"


def test_public_names_are_pinned() -> None:
    from serialsocket import capture, kermit, packets  # the public submodules

    assert sorted(serialsocket.__all__) == sorted(
        [
            "MAX_WINDOW",
            "Connected",
            "ConnectionAborted",
            "ConnectionClosed",
            "ConnectionRequested",
            "EndOfStream",
            "Endpoint",
            "EndpointConfig",
            "EndpointStatistics",
            "Event",
            "LinkDead",
            "LocalProtocolError",
            "MalformedDataError",
            "ProtocolError",
            "RemoteProtocolError",
            "State",
            "LineFailed",
            "LinkBroken",
            "LinkDeadError",
            "PeerAborted",
            "SerialListener",
            "SerialSocket",
            "SocketStatistics",
            "accept",
            "connect",
            "listen",
            "open_serial_socket",
            "serve",
            # layer 1: ports and modems
            "PortStatistics",
            "SerialPort",
            "open_port",
            "open_pty_pair",
            "DialError",
            "LineBusy",
            "ModemConnection",
            "ModemError",
            "ModemTimeout",
            "NoAnswer",
            "NoCarrier",
            "NoDialtone",
            "answer",
            "dial",
            "hangup",
            "BlockingSerialSocket",
        ]
    )
    assert sorted(packets.__all__) == sorted(
        [
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
    )
    assert sorted(kermit.__all__) == sorted(
        [
            "MAX_KERMIT_WINDOW",
            "FileCompleted",
            "FileData",
            "FileStarted",
            "KermitConfig",
            "KermitEvent",
            "KermitReceiver",
            "REMOTE_COMMANDS",
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
    )
    assert sorted(capture.__all__) == sorted(
        [
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
    )
    for face in (serialsocket, packets, kermit, capture):
        for name in face.__all__:
            assert getattr(face, name) is not None


def test_protocol_error_is_abstract() -> None:
    with pytest.raises(TypeError):
        serialsocket.ProtocolError("x")
    err = serialsocket.RemoteProtocolError("peer sent nonsense")
    assert err.error_hint == "peer sent nonsense"


# tcpstream's sans-I/O core: the codec, the state table, the connections, the
# exactly-once memory.  Only _pump, _server, _client, _blocking and _api touch trio.
TCPSTREAM_SANS_IO = [
    "_auth",
    "_builders",
    "_client_connection",
    "_commands",
    "_config",
    "_connection",
    "_errors",
    "_events",
    "_memory",
    "_packet",
    "_server_connection",
    "_state",
    "_teleop_connection",
    "_teleop_packet",
    "_teleop_state",
]


@pytest.mark.parametrize("module", TCPSTREAM_SANS_IO)
def test_tcpstream_core_modules_are_sans_io(module: str) -> None:
    bad = imports_of(ROOT / "tcpstream" / f"{module}.py") & FORBIDDEN_IN_CORE
    assert not bad, f"tcpstream/{module}.py imports {bad}"


def test_tcpstream_public_names_are_pinned() -> None:
    from tcpstream import commands, connection  # the two public submodules

    assert sorted(tcpstream.__all__) == sorted(
        [
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
            "DEFAULT_PORT",
            "Executor",
            "FailureReason",
            "Feedback",
            "KEY_SIZE",
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
    )
    assert sorted(commands.__all__) == sorted(
        [
            "ARGUMENT_WORDS",
            "AUX_WORDS",
            "BODY_SIZE",
            "BadField",
            "BadMagic",
            "BadVersion",
            "Command",
            "CommandCode",
            "CommandFlags",
            "FailureReason",
            "Feedback",
            "FeedbackSlot",
            "JOINTS",
            "MAGIC",
            "MAX_PATH_POINTS",
            "NUMERIC_KINDS",
            "NonFiniteWord",
            "PACKET_SIZE",
            "PROTOCOL_VERSION",
            "Packet",
            "PacketError",
            "PacketKind",
            "SIGNED_SIZE",
            "TAG_SIZE",
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
    )
    assert sorted(connection.__all__) == sorted(
        [
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
            "IDENTITY_SIZE",
            "IllegalTransition",
            "LocalProtocolError",
            "MAX_BAD_IN_A_ROW",
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
            "TRANSITIONS",
            "TelemetryReceived",
            "Trigger",
            "transition",
        ]
    )
    from tcpstream import teleop  # the teleoperation channel (PROTOCOL.md section 14)

    assert sorted(teleop.__all__) == sorted(
        [
            "COMMANDS",
            "MAGIC",
            "MAX_FRAME",
            "TELEOP",
            "MuxChannel",
            "StreamMux",
            "open_mux",
            "TAG_SIZE",
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
            "open_teleop",
            "size_of",
        ]
    )
    for module in (tcpstream, commands, connection, teleop):
        for name in module.__all__:
            assert getattr(module, name) is not None
    # Names that mean something else in serialsocket live only in the submodules.
    assert not {"State", "SessionState", "PacketRejected", "TRANSITIONS"} & set(dir(tcpstream))


LINKSIM_SANS_IO = ["control/_vocabulary", "control/_command_line"]
"""The console's command language and command stack: lines and ``now`` in, text,
commands and waits out; linksim.control._interactive is their I/O (the model's
previews run on a private virtual clock in _preview, not here)."""


@pytest.mark.parametrize("module", LINKSIM_SANS_IO)
def test_the_console_command_line_is_sans_io(module: str) -> None:
    bad = imports_of(ROOT / "linksim" / f"{module}.py") & (FORBIDDEN_IN_CORE | {"readline"})
    assert not bad, f"linksim/{module}.py imports {bad}"
