"""The byte-level test vectors of tcpstream/PROTOCOL.md section 13, made by the real code.

A keyed session between a :class:`ClientConnection` and a
:class:`ServerConnection` with a published key, fixed nonces, identity,
incarnation and arm instance, scripted packet by packet; plus an unkeyed
REFUSE.  ``python -m tests.tcpstream.vectors`` prints the section;
``test_protocol_vectors.py`` checks that PROTOCOL.md holds exactly that, so the
document cannot drift from the code.
"""

from __future__ import annotations

import hashlib
import hmac
import struct
from collections.abc import Callable
from dataclasses import dataclass

from tcpstream import (
    CloseReason,
    CommandCode,
    CommandResult,
    FailureReason,
    Feedback,
    RefuseReason,
    commands,
)
from tcpstream.connection import (
    ClientConnection,
    ControllerIdentity,
    Role,
    ServerConnection,
    SessionParameters,
)

KEY = b"telelink-test-vector-key-000001!"
"""The published 32-byte pre-shared key of the vectors (never use it for anything else)."""
CLIENT_NONCE = bytes(range(0x10))
SERVER_NONCE = bytes(range(0x10, 0x20))
IDENTITY = ControllerIdentity("vector", 0x0102030405060708)
ARM_INSTANCE = 0x1122334455667788
PARAMETERS = SessionParameters(
    heartbeat_interval=0.25, dead_time=1.4, telemetry_period=0.08, memory_size=1024
)
FEEDBACK = Feedback(
    joints=(0.5, 0.0, 0.0, 0.0, 0.0, 0.0),
    finger_opening=0.08,
    p=(0.5, 0.0, 0.4),
    s=(0.0, 1.0, 0.0),
    a=(0.0, 0.0, 1.0),
)


@dataclass(frozen=True)
class Vector:
    name: str
    direction: str  # "C -> A" or "A -> C"
    what: str
    raw: bytes


def _nonces(values: list[bytes]) -> Callable[[int], bytes]:
    it = iter(values)
    return lambda n: next(it)


def session_vectors() -> tuple[list[Vector], dict[str, bytes]]:
    """Every packet kind, as the real connections produce them, and the derived secrets."""
    t = 0.0
    client = ClientConnection(IDENTITY, key=KEY, nonce_source=_nonces([CLIENT_NONCE]))
    server = ServerConnection(
        PARAMETERS, key=KEY, instance=ARM_INSTANCE, nonce_source=_nonces([SERVER_NONCE])
    )
    out: list[Vector] = []

    def c2a(name: str, what: str) -> None:
        raw = client.data_to_send()
        assert len(raw) == 216, (name, len(raw))
        out.append(Vector(name, "C -> A", what, raw))
        server.receive_data(raw, t)

    def a2c(name: str, what: str) -> None:
        raw = server.data_to_send()
        assert len(raw) == 216, (name, len(raw))
        out.append(Vector(name, "A -> C", what, raw))
        client.receive_data(raw, t)

    client.connect(t)
    c2a("HELLO", "controller 'vector', incarnation 0x0102030405060708, client nonce 00..0f")
    a2c("CHALLENGE", "server nonce 10..1f (never tagged)")
    c2a("AUTH", "client proof; the first tagged packet, counter 2")
    while server.next_event() is not None:
        pass
    server.grant(Role.CONTROLLER, 0, t, remembered=False)
    a2c(
        "GRANT",
        "controller; heartbeat 0.25 s, dead time 1.4 s, telemetry 0.08 s, memory 1024;"
        " server proof, arm instance 0x1122334455667788, memory flag 0",
    )
    client.send_command(1, commands.move_joint(1, 0.5), t)
    c2a("COMMAND", "request 1: MOVE_JOINT joint 1 by +0.5 rad, failures seen 0")
    server.accepted(1, CommandCode.MOVE_JOINT, 0, t)
    a2c("ACCEPTED", "request 1 queued at position 0")
    server.completed(1, CommandCode.MOVE_JOINT, CommandResult(FEEDBACK), t)
    a2c("COMPLETED", "request 1 done; feedback: joint 1 at 0.5 rad, P (0.5, 0, 0.4)")
    client.send_command(2, commands.move_to((3.0, 0.0, 0.0)), t)
    c2a("COMMAND-2", "request 2: MOVE_TO_POSITION (3, 0, 0) m")
    server.failed(
        2,
        CommandCode.MOVE_TO_POSITION,
        FailureReason.UNREACHABLE,
        "out of reach",
        (2.6, 0.15, 0.877, 3.0),
        t,
    )
    a2c("FAILED", "request 2 UNREACHABLE, detail (2.6, 0.15, 0.877, 3.0), text 'out of reach'")
    server.telemetry(10, FEEDBACK, t)
    a2c("TELEMETRY", "control sample 10, the feedback array")
    t = 0.25
    client.handle_timer(t)
    c2a("HEARTBEAT", "the controller sent nothing for 0.25 s")
    server.handle_timer(t)
    a2c("HEARTBEAT-A", "the arm's heartbeat")
    client.send_command(3, commands.emergency_stop(), t)
    c2a("EMERGENCY_STOP", "request 3, code 16")
    server.completed(3, CommandCode.EMERGENCY_STOP, CommandResult(FEEDBACK), t)
    a2c("COMPLETED-3", "request 3: the feedback after the halt")
    client.close(CloseReason.NORMAL, t, "controller done")
    c2a("BYE", "NORMAL, text 'controller done'")

    unkeyed = ServerConnection(PARAMETERS, instance=ARM_INSTANCE)
    hello = ClientConnection(ControllerIdentity("second", 9), nonce_source=_nonces([bytes(16)]))
    hello.connect(0.0)
    unkeyed.receive_data(hello.data_to_send(), 0.0)
    while unkeyed.next_event() is not None:
        pass
    unkeyed.refuse(RefuseReason.BUSY, "another controller holds the arm", 0.0)
    out.append(
        Vector(
            "REFUSE",
            "A -> C",
            "BUSY (unkeyed arm), text 'another controller holds the arm'",
            unkeyed.data_to_send(),
        )
    )

    ident = IDENTITY.name.encode().ljust(32, b"\0")
    transcript = CLIENT_NONCE + SERVER_NONCE + ident + struct.pack("!QB", IDENTITY.incarnation, 0)
    secrets = {
        "client proof": hmac.new(
            KEY, b"telelink-v1 client proof" + transcript, hashlib.sha256
        ).digest(),
        "server proof": hmac.new(
            KEY, b"telelink-v1 server proof" + transcript, hashlib.sha256
        ).digest(),
        "session key Ks": hmac.new(
            KEY, b"telelink-v1 session key" + transcript, hashlib.sha256
        ).digest(),
    }
    return out, secrets


def hexdump(raw: bytes) -> str:
    lines = []
    for offset in range(0, len(raw), 24):
        chunk = raw[offset : offset + 24]
        groups = " ".join(chunk[i : i + 8].hex() for i in range(0, len(chunk), 8))
        lines.append(f"{offset:03d}  {groups}")
    return "\n".join(lines)


def render() -> str:
    """Section 13 of PROTOCOL.md, between its markers."""
    vectors, secrets = session_vectors()
    parts = [
        "Key `K` = the 32 ASCII bytes `telelink-test-vector-key-000001!`; identity `vector`",
        "(NUL-padded to 32 bytes); incarnation `0x0102030405060708`; client nonce",
        "`000102...0f`; server nonce `101112...1f`; arm instance `0x1122334455667788`;",
        "role 0 (controller). Derived (section 8):",
        "",
        "```text",
    ]
    parts += [f"{name:<15} {value.hex()}" for name, value in secrets.items()]
    parts += [
        "```",
        "",
        "Every packet of one keyed session, in order, as sent (216 bytes each, decimal",
        "offsets, 24 bytes a line; the tag is bytes 200..215), then an unkeyed REFUSE:",
    ]
    for v in vectors:
        parts += [
            "",
            f"**{v.name}** ({v.direction}): {v.what}",
            "",
            "```text",
            hexdump(v.raw),
            "```",
        ]
    return "\n".join(parts)


if __name__ == "__main__":  # pragma: no cover
    print(render())
