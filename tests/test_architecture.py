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
    "_encoding",
    "_endpoint",
    "_errors",
    "_events",
    "_packet",
    "_params",
    "_parser",
    "_receiver",
    "_rtt",
    "_sender",
    "_state",
    "_wire",
    "kermit/_core",
    "kermit/_params",
    "kermit/_receiver",
    "kermit/_sender",
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


@pytest.mark.parametrize(
    ("package", "forbidden"),
    [("serialsocket", {"tcpstream", "linksim"}), ("tcpstream", {"serialsocket", "linksim"})],
)
def test_import_direction(package: str, forbidden: set[str]) -> None:
    for path in (ROOT / package).rglob("*.py"):
        assert not imports_of(path) & forbidden, f"{path} imports {imports_of(path) & forbidden}"


def test_public_names_are_pinned() -> None:
    from serialsocket import kermit, packets  # the two public submodules

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
            "BlockCheck",
            "Encoding",
            "InitParameters",
            "Negotiated",
            "Packet",
            "PacketParser",
            "PacketReceived",
            "PacketRejected",
            "PacketType",
            "ParserEvent",
            "ParserStatistics",
            "RejectReason",
            "build_packet",
            "check_chars",
            "crc16_kermit",
            "data_capacity",
            "packet_length",
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
            "KermitSender",
            "KermitState",
            "KermitStatistics",
            "KermitTransferError",
            "OutgoingFile",
            "TransferComplete",
            "TransferFailed",
            "kermit_receive",
            "kermit_send",
        ]
    )
    for face in (serialsocket, packets, kermit):
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
]


@pytest.mark.parametrize("module", TCPSTREAM_SANS_IO)
def test_tcpstream_core_modules_are_sans_io(module: str) -> None:
    bad = imports_of(ROOT / "tcpstream" / f"{module}.py") & FORBIDDEN_IN_CORE
    assert not bad, f"tcpstream/{module}.py imports {bad}"


def test_tcpstream_public_names_are_pinned() -> None:
    assert sorted(tcpstream.__all__) == sorted(
        [
            "ARGUMENT_WORDS",
            "AUX_WORDS",
            "Accepted",
            "ArmClient",
            "AuthenticationFailed",
            "BadField",
            "BadMagic",
            "BadVersion",
            "BlockingClient",
            "ClientConfig",
            "ClientConnection",
            "ClientOptions",
            "CloseReason",
            "Command",
            "CommandCode",
            "CommandFailed",
            "CommandFlags",
            "CommandHandle",
            "CommandReceived",
            "CommandResult",
            "Completed",
            "ClientStatistics",
            "ConnectionStatistics",
            "ControlRequested",
            "ControllerIdentity",
            "DEFAULT_PORT",
            "EmergencyStopRequested",
            "Event",
            "Executor",
            "Failed",
            "FailureReason",
            "Feedback",
            "FeedbackSlot",
            "Granted",
            "IllegalTransition",
            "JOINTS",
            "KEY_SIZE",
            "LocalProtocolError",
            "MAGIC",
            "MAX_BAD_IN_A_ROW",
            "MAX_PATH_POINTS",
            "NonFiniteWord",
            "PACKET_SIZE",
            "PROTOCOL_VERSION",
            "OutcomeUnknown",
            "Packet",
            "PacketError",
            "PacketKind",
            "PacketRejected",
            "RefusalReceived",
            "RefuseReason",
            "Refused",
            "RemoteProtocolError",
            "Role",
            "Server",
            "ServerConfig",
            "ServerConnection",
            "ServerStatistics",
            "SessionClosed",
            "SessionEnded",
            "SessionError",
            "SessionParameters",
            "SessionState",
            "Side",
            "TRANSITIONS",
            "TelemetryReceived",
            "Trigger",
            "UnknownCommand",
            "UnknownKind",
            "WatchdogExpired",
            "WrongSize",
            "commands",
            "connect_stream",
            "connect_tcp",
            "decode_packet",
            "encode_packet",
            "generate_key",
            "load_key_file",
            "serve_stream",
            "serve_tcp",
            "validate_arguments",
            "write_key_file",
        ]
    )
    for name in tcpstream.__all__:
        assert getattr(tcpstream, name) is not None
