"""PROTOCOL.md section 14.7 holds exactly the teleoperation bytes the code produces,
and those bytes follow the document's formulas when recomputed without the code.

Regenerate the section's block with ``python -m tests.tcpstream.test_teleop_vectors``.
"""

from __future__ import annotations

import hashlib
import hmac
import pathlib
import struct
import sys
from dataclasses import dataclass

from tcpstream.teleop import (
    ArmChannel,
    Buttons,
    ContactFlags,
    OperatorChannel,
    RefuseCode,
    Reply,
    ReplyStatus,
    Sample,
    TeleopKind,
    TeleopMode,
    decode_header,
    size_of,
)

PROTOCOL = pathlib.Path(__file__).parents[2] / "tcpstream" / "PROTOCOL.md"
BEGIN, END = "<!-- teleop-vectors:begin -->\n", "\n<!-- teleop-vectors:end -->"
KEY = b"telelink-test-vector-key-000001!"
CLIENT_NONCE = bytes(range(16))
SERVER_NONCE = bytes(range(16, 32))
SAMPLE = Sample(
    1,
    TeleopMode.CARTESIAN,
    Buttons.ENGAGED | Buttons.SHARED_COMPLIANCE,
    64,
    12.5,
    (0.015625, -0.25, 0.0, 0.0, 0.0, 0.125),
)
REPLY = Reply(
    1,
    ReplyStatus.FOLLOWING,
    ContactFlags.CONTACT | ContactFlags.COMPLIANT,
    2,
    64,
    12.5,
    0.25,
    (0.0, 0.0, 20.0, 0.5, -0.5, 0.0),
    (0.5, 0.0, 0.25, 0.0, 3.0, 0.0),
    (0.5, 0.0, 0.5, 0.0, 3.0, 0.0),
)


@dataclass(frozen=True)
class Vector:
    name: str
    note: str
    raw: bytes


def vectors() -> list[Vector]:
    op = OperatorChannel("vector", KEY, CLIENT_NONCE)
    arm = ArmChannel(KEY, SERVER_NONCE, rate_deadman=3.0, control_rate=125.0)
    out: list[Vector] = []

    def take(end: OperatorChannel | ArmChannel, name: str, note: str) -> bytes:
        raw = end.data_to_send()
        out.append(Vector(name, note, raw))
        return raw

    op.connect()
    arm.receive_data(take(op, "HELLO", "operator 'vector', nonce 00..0f; never tagged"), 0.0)
    op.receive_data(take(arm, "CHALLENGE", "nonce 10..1f; never tagged"), 0.0)
    arm.receive_data(take(op, "AUTH", "operator proof; the first tagged packet, counter 2"), 0.0)
    arm.grant()
    op.receive_data(take(arm, "GRANT", "arm proof; rate deadman 3.0 s, control rate 125 Hz"), 0.0)
    op.offer(SAMPLE)
    op.poll(12.5)
    arm.receive_data(
        take(
            op,
            "SAMPLE",
            "sample 1, CARTESIAN, ENGAGED|SHARED_COMPLIANCE, trigger 64, stamp 12.5 s, "
            "accumulated dX (0.015625, -0.25, 0, 0, 0, 0.125)",
        ),
        12.6,
    )
    arm.reply(REPLY)
    arm.poll(12.75)
    take(
        arm,
        "REPLY",
        "sample 1 applied, CONTACT|COMPLIANT, held 0.25 s, force (0, 0, 20) N, "
        "torque (0.5, -0.5, 0) N m, commanded and actual pose",
    )
    op.emergency_stop()
    take(op, "STOP", "emergency stop, counter 4")
    op.close(RefuseCode.NORMAL)
    take(op, "BYE", "operator done, reason NORMAL")
    lone = ArmChannel(None, SERVER_NONCE, rate_deadman=3.0, control_rate=125.0)
    lone.refuse(RefuseCode.BUSY)
    take(lone, "REFUSE", "unkeyed arm, reason BUSY; never tagged")
    return out


def _hex(raw: bytes) -> str:
    lines = []
    for at in range(0, len(raw), 24):
        chunk = raw[at : at + 24]
        words = " ".join(chunk[i : i + 8].hex() for i in range(0, len(chunk), 8))
        lines.append(f"{at:03d}  {words}")
    return "\n".join(lines)


def render() -> str:
    parts = [
        f"Key `K` = `{KEY.decode()}`; identity `vector` (NUL-padded to 32 bytes); operator "
        "nonce `000102...0f`; arm nonce `101112...1f`. Every packet of one keyed channel, in "
        "order (decimal offsets, 24 bytes a line), then an unkeyed REFUSE:",
    ]
    for v in vectors():
        parts.append(f"**{v.name}** ({len(v.raw)} bytes): {v.note}\n\n```text\n{_hex(v.raw)}\n```")
    return "\n\n".join(parts)


def test_the_document_holds_the_vectors_the_code_makes() -> None:
    text = PROTOCOL.read_text()
    section = text[text.index(BEGIN) + len(BEGIN) : text.index(END)]
    assert section == render(), "regenerate with: python -m tests.tcpstream.test_teleop_vectors"


def test_every_kind_is_covered_at_its_size() -> None:
    got = vectors()
    assert {decode_header(v.raw)[0] for v in got} == set(TeleopKind)
    assert all(len(v.raw) == size_of(TeleopKind(v.raw[3])) for v in got)


def test_the_vectors_follow_the_document_independently_of_the_code() -> None:
    by = {v.name: v.raw for v in vectors()}
    identity = by["HELLO"][8:40]
    assert identity == b"vector".ljust(32, b"\0")
    transcript = by["HELLO"][40:56] + by["CHALLENGE"][8:24] + identity

    def mac(label: bytes) -> bytes:
        return hmac.new(KEY, label + transcript, hashlib.sha256).digest()

    assert by["AUTH"][8:40] == mac(b"telelink-v1 teleop client proof")
    assert by["GRANT"][8:40] == mac(b"telelink-v1 teleop server proof")
    kc = mac(b"telelink-v1 teleop channel key")
    for name, direction in [
        ("AUTH", b"\x11"),
        ("GRANT", b"\x12"),
        ("SAMPLE", b"\x11"),
        ("REPLY", b"\x12"),
        ("STOP", b"\x11"),
        ("BYE", b"\x11"),
    ]:
        raw = by[name]
        assert raw[-8:] == hmac.new(kc, direction + raw[:-8], hashlib.sha256).digest()[:8], name
    # Counters: 1, 2, ... per direction.
    assert [struct.unpack_from("!I", by[n], 4)[0] for n in ("HELLO", "AUTH", "SAMPLE", "STOP")] == [
        1,
        2,
        3,
        4,
    ]
    # The sample's fields where section 14.3 puts them.
    s = by["SAMPLE"]
    assert struct.unpack_from("!IBBBBd6f", s, 8) == (
        1,
        2,
        0x11,
        64,
        0,
        12.5,
        0.015625,
        -0.25,
        0,
        0,
        0,
        0.125,
    )
    assert struct.unpack_from("!ff", by["GRANT"], 40) == (3.0, 125.0)


if __name__ == "__main__":
    sys.stdout.write(render() + "\n")
