"""The Wireshark dissector ``contrib/wireshark/telelink.lua``, run by tshark (issue 24, part 4).

Each capture is decoded with ``tshark -X lua_script:... -r FILE`` and the
dissector's fields are compared with what the capture is known to hold: a real
serial-socket session, hand-built Kermit packets (long, split over chunks,
damaged, type-1 checked, between noise), an arm-server TCP session
(LINKTYPE_TCPSTREAM) and a plain TCP capture of port 7010.

Skipped, with the reason, where tshark (with Lua) is not installed; ``.ci/run``
installs Debian's tshark when it can.
"""

from __future__ import annotations

import functools
import os
import pathlib
import random
import shutil
import struct
import subprocess

import pytest
import trio
import trio.testing

import tcpstream
from linksim import DirectionConfig, LinkConfig, endpoint_config_for
from linksim.arm import SimulatedArm
from linksim.link import ImpairedLink, server_config_for
from serialsocket import accept, connect
from serialsocket.capture import (
    LINKTYPE_SERIAL,
    CaptureFile,
    CapturingStream,
    Direction,
    Interface,
    PcapngWriter,
    read_pcapng,
)
from serialsocket.packets import PRINTABLE, Packet, build_packet
from tcpstream.commands import CommandCode, PacketKind, encode_packet, move_joint, words_body
from tcpstream.commands import Packet as CommandPacket

from .test_capture import EPOCH, arq_capture
from .test_capture_cli import arm_server_capture

ROOT = pathlib.Path(__file__).resolve().parents[1]
DISSECTOR = ROOT / "contrib" / "wireshark" / "telelink.lua"
GUARD = 120.0


@functools.cache
def _tshark_missing() -> str | None:
    """Why the dissector cannot be run here, or None."""
    exe = shutil.which("tshark")
    if exe is None:
        return "tshark is not installed (Debian: apt-get install tshark; .ci/run tries)"
    version = subprocess.run([exe, "-v"], capture_output=True, text=True, timeout=GUARD).stdout
    if "without Lua" in version or "with Lua" not in version:
        return "this tshark was built without Lua: it cannot load the dissector"
    return None


@pytest.fixture(autouse=True)
def _need_tshark() -> None:
    reason = _tshark_missing()
    if reason is not None:
        pytest.skip(reason)


def tshark(path: pathlib.Path, *args: str, home: pathlib.Path) -> str:
    """tshark's output for ``path`` with the dissector loaded (and no user preferences)."""
    done = subprocess.run(
        ["tshark", "-X", f"lua_script:{DISSECTOR}", "-r", str(path), *args],
        capture_output=True,
        text=True,
        timeout=GUARD,
        env={**os.environ, "HOME": str(home), "XDG_CONFIG_HOME": str(home)},
    )
    assert done.returncode == 0, done.stderr
    assert "Lua: Error" not in done.stderr, done.stderr
    assert "Lua: Error" not in done.stdout
    return done.stdout


def fields(path: pathlib.Path, names: list[str], home: pathlib.Path) -> list[dict[str, str]]:
    """One dict per frame: each field's values, several joined with ``|``."""
    args = ["-T", "fields", "-E", "occurrence=a", "-E", "aggregator=|", "-E", "separator=\t"]
    for name in names:
        args += ["-e", name]
    out = tshark(path, *args, home=home)
    return [dict(zip(names, line.split("\t"), strict=True)) for line in out.splitlines()]


def _hex(value: str) -> bytes:
    """A bytes field as tshark prints it (plain or colon-separated hex)."""
    return bytes.fromhex(value.replace(":", ""))


def _direction(row: dict[str, str]) -> Direction:
    """The frame's direction flag (tshark prints the flags word in hex)."""
    return Direction(int(row["frame.packet_flags_direction"], 0))


def test_a_serial_socket_session(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "arq.pcapng"
    payload = arq_capture(path)
    names = [
        "frame.number",
        "frame.packet_flags_direction",
        "telelink.type",
        "telelink.seq",
        "telelink.length",
        "telelink.extended",
        "telelink.check.type",
        "telelink.check.good",
        "telelink.init.window",
        "telelink.init.version",
        "telelink.init.maxlx",
        "telelink.ack.next",
        "telelink.ack.window",
        "telelink.data.decoded",
    ]
    rows = [r for r in fields(path, names, tmp_path) if r["telelink.type"]]
    first = rows[0]
    init = read_pcapng(path.read_bytes()).packets[0].data
    assert (first["telelink.type"], first["telelink.seq"], first["telelink.length"]) == (
        "I",
        "0",
        str(init.index(b"\r")),  # MARK through CHECK
    )
    assert _direction(first) == Direction.OUTBOUND
    assert (first["telelink.check.type"], first["telelink.check.good"]) == ("3", "1")
    assert (first["telelink.init.window"], first["telelink.init.version"]) == ("31", "1")
    assert first["telelink.init.maxlx"] == "1017"  # 1024 - 7: the length is measured
    # The answer arrives one byte per chunk: shown once, where its last byte is.
    answers = [r for r in rows if r["telelink.type"] == "Y" and r["telelink.seq"] == "0"]
    assert len(answers) == 1
    assert _direction(answers[0]) == Direction.INBOUND
    # Every check is good; the data decodes to what was sent, each way.
    assert {g for r in rows for g in r["telelink.check.good"].split("|")} == {"1"}
    for direction, expected in (
        (Direction.OUTBOUND, payload),
        (Direction.INBOUND, payload.upper()),
    ):
        decoded = b"".join(
            _hex(v)
            for r in rows
            if _direction(r) == direction
            for v in r["telelink.data.decoded"].split("|")
            if v
        )
        assert decoded == expected
    # Long packets: the first data packet is extended, 128 characters.
    data = next(r for r in rows if r["telelink.type"].startswith("D"))
    assert data["telelink.extended"].split("|")[0] == "1"
    assert data["telelink.length"].split("|")[0] == "128"
    # ACKs carry the cumulative next-expected and the window.
    ack = next(r for r in rows if r["telelink.type"] == "Y" and r["telelink.seq"] == "1")
    assert ack["telelink.ack.next"] == "2"
    assert int(ack["telelink.ack.window"]) > 0
    # The summary line: the interface, the direction and each packet.
    summary = tshark(path, home=tmp_path).splitlines()
    assert summary[0].endswith(f"telelink {len(init)} client tx I 0")
    window = ack["telelink.ack.window"]
    assert any(line.endswith(f"client rx Y 1 next=2 win={window}") for line in summary)


def arm_over_serial_capture(path: pathlib.Path) -> None:
    """A command session over a serial socket on a noisy 9600 bit/s, 0.25 s line.

    Virtual clock and a seeded line: the same capture every run, with damaged
    packets, NAKs and resends among them.  The controller's side is captured.
    """
    link = LinkConfig.symmetric(
        DirectionConfig(delay=0.25, rate=9600, byte_error_rate=5e-4), seed=1
    )
    cfg = endpoint_config_for(link)

    async def main() -> None:
        line = ImpairedLink(link)
        with CaptureFile(path, clock=lambda: EPOCH + trio.current_time()) as cap:
            controller_line = CapturingStream(line.a, cap, cap.add_interface("controller"))
            async with (
                trio.open_nursery() as nursery,
                tcpstream.Server(SimulatedArm(), server_config_for(link, None)) as server,
            ):

                async def serve() -> None:
                    await server.serve_stream(await accept(line.b, cfg, nursery=nursery))

                nursery.start_soon(serve)
                sock = await connect(controller_line, cfg, nursery=nursery)
                async with tcpstream.connect_stream(sock, identity="capture") as arm:
                    await arm.send(tcpstream.commands.status())
                    await arm.send(move_joint(3, 0.25))
                nursery.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))


def test_command_packets_inside_the_serial_socket(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "arm-serial.pcapng"
    arm_over_serial_capture(path)
    names = [
        "frame.packet_flags_direction",
        "telelink.type",
        "telelink.check.good",
        "tlcmd.kind",
        "tlcmd.code",
        "tlcmd.request_id",
    ]
    rows = fields(path, names, tmp_path)
    # The line damaged packets, and the receiver asked for them again ...
    assert "0" in {g for r in rows for g in r["telelink.check.good"].split("|")}
    assert any("N" in r["telelink.type"].split("|") for r in rows)
    # ... yet the command stream comes out whole and in order, each way.

    def stream(direction: Direction) -> list[tuple[int, int, int]]:
        return [
            (int(k), int(c), int(q))
            for r in rows
            if r["tlcmd.kind"] and _direction(r) == direction
            for k, c, q in zip(
                r["tlcmd.kind"].split("|"),
                r["tlcmd.code"].split("|"),
                r["tlcmd.request_id"].split("|"),
                strict=True,
            )
            if int(k) != PacketKind.HEARTBEAT and int(k) != PacketKind.TELEMETRY
        ]

    status, joint = int(CommandCode.STATUS), int(CommandCode.MOVE_JOINT)
    assert stream(Direction.OUTBOUND) == [
        (PacketKind.HELLO, 0, 0),
        (PacketKind.COMMAND, status, 1),
        (PacketKind.COMMAND, joint, 2),
        (PacketKind.BYE, 0, 0),
    ]
    assert stream(Direction.INBOUND) == [
        (PacketKind.GRANT, 0, 0),
        (PacketKind.ACCEPTED, status, 1),
        (PacketKind.COMPLETED, status, 1),
        (PacketKind.ACCEPTED, joint, 2),
        (PacketKind.COMPLETED, joint, 2),
    ]


def serial_line_capture(path: pathlib.Path) -> dict[str, bytes]:
    """Hand-built line traffic: returns the packets by name."""
    rng = random.Random(24)
    blob = rng.randbytes(300)
    packets = {
        "long": build_packet(Packet(seq=5, type="D", data=PRINTABLE.encode(blob))),
        "ack": build_packet(Packet(seq=5, type="Y", data=b"&?")),  # next 6, window 31
        "damaged": bytearray(build_packet(Packet(seq=6, type="D", data=b"abc"))),
        # G-Kermit's Send-Init, type-1 checked (reference/kermit.md section 2).
        "send_init": b"\x019 S~' @-#Y3~*!J*0+++B\"U1AH\r",
        "error": build_packet(Packet(seq=0, type="E", data=PRINTABLE.encode(b"disk full\r\n"))),
        "nak": build_packet(Packet(seq=7, type="N")),
        "poll": build_packet(Packet(seq=4, type="Y", data=b"%?P")),
    }
    packets["damaged"][5] ^= 0x01  # one bit of the data: the CRC no longer matches
    packets["blob"] = blob
    long = packets["long"]
    writer = PcapngWriter()
    out = writer.header() + writer.add_interface(Interface("/dev/ttyS0", LINKTYPE_SERIAL))[1]
    chunks: list[tuple[bytes, Direction]] = [
        (b"ATDT5551234\r" + long[:50], Direction.OUTBOUND),  # modem text, then a start
        (long[50:250], Direction.OUTBOUND),  # the middle: no packet ends here
        (packets["nak"], Direction.INBOUND),  # the other direction meanwhile
        (long[250:] + packets["ack"], Direction.OUTBOUND),
        (bytes(packets["damaged"]) + packets["send_init"], Direction.OUTBOUND),
        (packets["error"] + packets["poll"], Direction.INBOUND),
    ]
    for n, (data, direction) in enumerate(chunks):
        out += writer.packet(0, data, EPOCH + n, direction)
    path.write_bytes(out)
    return packets


def test_kermit_framing_long_split_damaged_and_type_1(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "line.pcapng"
    packets = serial_line_capture(path)
    names = [
        "frame.number",
        "telelink.carried",
        "telelink.noise.text",
        "telelink.type",
        "telelink.seq",
        "telelink.extended",
        "telelink.lenx",
        "telelink.hcheck.good",
        "telelink.length",
        "telelink.check.type",
        "telelink.check.good",
        "telelink.data.decoded",
        "telelink.ack.next",
        "telelink.ack.window",
        "telelink.ack.poll",
        "telelink.reason",
        "telelink.init.maxl",
        "telelink.init.chkt",
    ]
    f1, f2, f3, f4, f5, f6 = fields(path, names, tmp_path)
    assert f1["telelink.noise.text"] == "ATDT5551234\\x0d"
    assert f1["telelink.type"] == f2["telelink.type"] == ""  # the long packet is not done
    assert f2["telelink.carried"] == "50"
    assert (f3["telelink.type"], f3["telelink.seq"]) == ("N", "7")  # its own direction
    assert f3["telelink.carried"] == ""
    assert f4["telelink.carried"] == "250"
    assert f4["telelink.type"] == "D|Y"
    assert f4["telelink.seq"] == "5|5"
    assert f4["telelink.extended"] == "1"
    long = packets["long"]
    assert f4["telelink.length"] == f"{len(long) - 1}|{len(packets['ack']) - 1}"
    assert f4["telelink.lenx"] == str(len(long) - 1 - 7)
    assert f4["telelink.hcheck.good"] == "1"
    assert f4["telelink.check.type"] == "3|3"
    assert f4["telelink.check.good"] == "1|1"
    assert _hex(f4["telelink.data.decoded"]) == packets["blob"]
    assert (f4["telelink.ack.next"], f4["telelink.ack.window"]) == ("6", "31")
    assert f4["telelink.ack.poll"] == "0"
    # The damaged packet is shown and flagged; the S packet's check is type 1.
    assert f5["telelink.type"] == "D|S"
    assert f5["telelink.check.good"] == "0|1"
    assert f5["telelink.check.type"] == "3|1"
    assert (f5["telelink.init.maxl"], f5["telelink.init.chkt"]) == ("94", "3")
    assert f6["telelink.type"] == "E|Y"
    assert f6["telelink.reason"] == "disk full\\r\\n"  # tshark escapes controls
    assert (f6["telelink.ack.next"], f6["telelink.ack.poll"]) == ("5", "1")
    text = tshark(path, "-V", "-Y", "frame.number == 5", home=tmp_path)
    assert "Kermit D seq=6 len=10: Data" in text
    assert "Check good: False" in text
    assert "Block check failed" in text
    assert "Kermit S seq=0 len=27: Send-Init" in text
    assert "Block check type: 1 (6-bit checksum)" in text


def test_arm_server_tcp_session(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "arm.pcapng"
    rid = arm_server_capture(path)
    names = [
        "frame.packet_flags_direction",
        "tlcmd.kind",
        "tlcmd.code",
        "tlcmd.request_id",
        "tlcmd.version",
    ]
    rows = [r for r in fields(path, names, tmp_path) if r["tlcmd.kind"]]

    def kinds(direction: Direction) -> list[int]:
        return [
            int(k) for r in rows if _direction(r) == direction for k in r["tlcmd.kind"].split("|")
        ]

    received, sent = kinds(Direction.INBOUND), kinds(Direction.OUTBOUND)
    assert received[0] == PacketKind.HELLO
    assert PacketKind.COMMAND in received
    assert sent[0] == PacketKind.GRANT
    assert PacketKind.ACCEPTED in sent
    assert PacketKind.COMPLETED in sent
    command = next(r for r in rows if r["tlcmd.kind"] == str(int(PacketKind.COMMAND)))
    assert command["tlcmd.code"] == str(int(CommandCode.STATUS))
    assert command["tlcmd.request_id"] == str(rid)
    assert {v for r in rows for v in r["tlcmd.version"].split("|")} == {"1"}


def _checksum(header: bytes) -> int:
    total = sum(struct.unpack(f"!{len(header) // 2}H", header))
    while total > 0xFFFF:
        total = (total & 0xFFFF) + (total >> 16)
    return ~total & 0xFFFF


def _segment(src: int, dst: int, seq: int, ack: int, flags: int, payload: bytes) -> bytes:
    """An IPv4/TCP segment between 127.0.0.1 ports (LINKTYPE_RAW)."""
    tcp = struct.pack("!HHIIBBHHH", src, dst, seq, ack, 5 << 4, flags, 65535, 0, 0) + payload
    ip = struct.pack(
        "!BBHHHBBH4s4s", 0x45, 0, 20 + len(tcp), 1, 0, 64, 6, 0, b"\x7f\0\0\1", b"\x7f\0\0\1"
    )
    ip = ip[:10] + struct.pack("!H", _checksum(ip)) + ip[12:]
    return ip + tcp


def test_plain_tcp_capture_on_port_7010(tmp_path: pathlib.Path) -> None:
    command = move_joint(3, 0.25)
    stream = b"".join(
        encode_packet(
            CommandPacket(
                kind=PacketKind.COMMAND,
                code=command.code,
                request_id=rid,
                counter=rid,
                body=words_body(command.args),
            )
        )
        for rid in (41, 42)
    )
    assert len(stream) == 432
    syn, ack, psh = 0x02, 0x10, 0x18
    client, server = 50000, 7010
    segments = [
        _segment(client, server, 1000, 0, syn, b""),
        _segment(server, client, 5000, 1001, syn | ack, b""),
        _segment(client, server, 1001, 5001, ack, b""),
        # Two packets in segments of 300 and 132 bytes: TCP must reassemble.
        _segment(client, server, 1001, 5001, psh, stream[:300]),
        _segment(client, server, 1301, 5001, psh, stream[300:]),
    ]
    writer = PcapngWriter()
    out = writer.header() + writer.add_interface(Interface("lo", 101))[1]  # LINKTYPE_RAW
    for n, segment in enumerate(segments):
        out += writer.packet(0, segment, EPOCH + n / 10)
    path = tmp_path / "tcp.pcapng"
    path.write_bytes(out)
    names = ["frame.number", "tlcmd.kind", "tlcmd.code", "tlcmd.request_id", "tlcmd.word"]
    rows = fields(path, names, tmp_path)
    assert [r["tlcmd.kind"] for r in rows] == ["", "", "", "6", "6"]
    assert [r["tlcmd.request_id"] for r in rows[3:]] == ["41", "42"]
    assert rows[3]["tlcmd.code"] == str(int(CommandCode.MOVE_JOINT))
    words = [float(w) for w in rows[4]["tlcmd.word"].split("|")]
    assert words == [3.0, 0.25] + [0.0] * 16
    text = tshark(path, "-V", "-Y", "frame.number == 5", home=tmp_path)
    assert "tcpstream COMMAND #42 rid=42 MOVE_JOINT" in text


def test_corrected_and_repair_packets_are_named(tmp_path: pathlib.Path) -> None:
    """``d`` and ``r`` packets (PROTOCOL.md 15) are named, not "Unknown type"."""
    from serialsocket.packets import BlockCheck, build_corrected, repair_field

    plain = build_packet(Packet(seq=9, type="D", data=b"hello" * 30))
    corrected = build_corrected(10, b"world" * 30, BlockCheck.CRC16)
    repair = build_packet(Packet(seq=9, type="r", data=repair_field(plain[:-1], 3)))
    path = tmp_path / "sums.pcapng"
    writer = PcapngWriter()
    out = writer.header() + writer.add_interface(Interface("/dev/ttyS0", LINKTYPE_SERIAL))[1]
    out += writer.packet(0, corrected + repair, EPOCH, Direction.OUTBOUND)
    path.write_bytes(out)
    [row] = fields(path, ["telelink.type", "telelink.check.good"], tmp_path)
    assert row["telelink.type"] == "d|r"
    assert row["telelink.check.good"] == "1|1"
    text = tshark(path, "-V", home=tmp_path)
    assert "Data with sums (corrected data packet, PROTOCOL.md 15)" in text
    assert "Repair (the sums of a damaged D packet, PROTOCOL.md 15.6)" in text
    assert "Unknown type" not in text
