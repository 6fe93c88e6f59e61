"""``--capture FILE`` on ``linksim relay``, ``serialsocket listen|connect`` and
``linksim arm-server`` (issue 24, part 4): the programs run as a user runs
them, and every capture is parsed back with :func:`read_pcapng`.

Waits have generous guards that only stop a hang; nothing is timed.
"""

from __future__ import annotations

import json
import pathlib
import signal
import subprocess
import sys

import trio

import tcpstream
from serialsocket.capture import (
    LINKTYPE_SERIAL,
    LINKTYPE_TCPSTREAM,
    Capture,
    Direction,
    Interface,
    read_pcapng,
)
from tcpstream.commands import CommandCode, PacketKind, decode_packet

from .serialsocket.test_kermit_cli import wait_until_reading
from .test_capture import _payload

GUARD = 60.0


def _bytes(capture: Capture, interface: int, direction: Direction) -> bytes:
    return b"".join(
        p.data for p in capture.packets if p.interface == interface and p.direction == direction
    )


def _serial(*args: str) -> list[str]:
    return [sys.executable, "-m", "serialsocket", *args]


def _assert_received_up_to_final_acks(sent: bytes, received: bytes) -> None:
    """``received`` is ``sent``, or ``sent`` without trailing ACK packets (the
    close's last ACK copies, which may arrive after the receiver has exited)."""
    assert sent.startswith(received)
    tail = sent[len(received) :]
    packets = [p for p in tail.split(b"\r") if p]
    assert len(packets) <= 3, tail
    assert all(p[:1] == b"\x01" and p[3:4] == b"Y" for p in packets), tail


def test_relay_and_both_netcats_capture_the_same_bytes(tmp_path: pathlib.Path) -> None:
    relay_file, listen_file, connect_file = (
        tmp_path / "relay.pcapng",
        tmp_path / "listen.pcapng",
        tmp_path / "connect.pcapng",
    )
    relay = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "linksim",
            "relay",
            "--json",
            "--delay",
            "0.002",
            "--capture",
            str(relay_file),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    upload = bytes(range(256)) * 8 + b"~~~~~ run ~~~~~"
    download = b"telemetry\r\n" * 50
    try:
        assert relay.stdout is not None
        paths = json.loads(relay.stdout.readline())
        a, b = paths["a"], paths["b"]
        common = ["--delay", "0.002", "--dead-after", "60", "--quiet"]
        server = subprocess.Popen(
            _serial("listen", b, *common, "--capture", str(listen_file)),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        try:
            assert server.stdin is not None
            server.stdin.write(download)
            server.stdin.close()
            wait_until_reading(server, b)
            client = subprocess.run(
                _serial(
                    "connect",
                    a,
                    *common,
                    "--connect-timeout",
                    "30",
                    "--capture",
                    str(connect_file),
                ),
                input=upload,
                capture_output=True,
                timeout=GUARD,
            )
            assert server.stdout is not None
            assert server.stderr is not None
            got_up = server.stdout.read()
            assert server.wait(timeout=GUARD) == 0, server.stderr.read()
        finally:
            if server.poll() is None:
                server.kill()
                server.wait()
        assert client.returncode == 0, client.stderr[-2000:]
        assert got_up == upload
        assert client.stdout == download
    finally:
        relay.send_signal(signal.SIGTERM)
        assert relay.wait(timeout=GUARD) == 0

    relayed = read_pcapng(relay_file.read_bytes())
    listened = read_pcapng(listen_file.read_bytes())
    connected = read_pcapng(connect_file.read_bytes())
    assert relayed.interfaces == (
        Interface(a, LINKTYPE_SERIAL, "linksim relay side a"),
        Interface(b, LINKTYPE_SERIAL, "linksim relay side b"),
    )
    assert connected.interfaces == (Interface(a, LINKTYPE_SERIAL, "serialsocket connect"),)
    assert listened.interfaces == (Interface(b, LINKTYPE_SERIAL, "serialsocket listen"),)
    # A clean line: what one program sent is what the relay read from its tty,
    # what it delivered to the other tty, and what the other program received.
    # The one exception: the copies of the ACK that completes a close
    # (PROTOCOL.md 6) may reach the other tty after that program has exited.
    up = _bytes(connected, 0, Direction.OUTBOUND)
    assert up == _bytes(relayed, 0, Direction.OUTBOUND)
    assert up == _bytes(relayed, 1, Direction.INBOUND)
    _assert_received_up_to_final_acks(up, _bytes(listened, 0, Direction.INBOUND))
    down = _bytes(listened, 0, Direction.OUTBOUND)
    assert down == _bytes(relayed, 1, Direction.OUTBOUND)
    assert down == _bytes(relayed, 0, Direction.INBOUND)
    _assert_received_up_to_final_acks(down, _bytes(connected, 0, Direction.INBOUND))
    # And they are the serial socket's packets, carrying the data.
    assert (up[:1], up[3:4]) == (b"\x01", b"I")  # MARK ... TYPE I: the connect request
    assert _payload(connected.packets, Direction.OUTBOUND) == upload
    assert _payload(connected.packets, Direction.INBOUND) == download
    # The relay stamps a delivery at its modelled arrival: one delay (2 ms)
    # after the read it came from, at least (timestamps are whole microseconds).
    for side in (0, 1):
        sent = [p for p in relayed.packets if p.interface == side and p.direction == 2]
        got = [p for p in relayed.packets if p.interface == 1 - side and p.direction == 1]
        assert got[0].timestamp - sent[0].timestamp >= 0.002 - 2e-6


def test_capture_file_that_cannot_be_written_is_exit_1(tmp_path: pathlib.Path) -> None:
    bad = str(tmp_path / "no-such-dir" / "x.pcapng")
    netcat = subprocess.run(
        _serial("connect", "loop://", "--capture", bad), capture_output=True, timeout=GUARD
    )
    assert netcat.returncode == 1
    assert b"No such file or directory" in netcat.stderr
    assert b"Traceback" not in netcat.stderr
    relay = subprocess.run(
        [sys.executable, "-m", "linksim", "relay", "--capture", bad],
        capture_output=True,
        timeout=GUARD,
    )
    assert relay.returncode == 1
    assert f"linksim relay: cannot write {bad}: No such file or directory" in relay.stderr.decode()
    server = subprocess.run(
        [sys.executable, "-m", "linksim", "arm-server", "--transport", "tcp", "--capture", bad],
        capture_output=True,
        timeout=GUARD,
    )
    assert server.returncode == 1
    assert b"No such file or directory" in server.stderr
    assert b"Traceback" not in server.stderr


def arm_server_capture(path: pathlib.Path) -> int:
    """One TCP session with ``linksim arm-server --capture``: a STATUS command.

    Returns the request id of the command.
    """
    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "linksim",
            "arm-server",
            "--transport",
            "tcp",
            "--tcp-port",
            "0",
            "--sessions",
            "1",
            "--capture",
            str(path),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    rid: list[int] = []
    try:
        assert server.stdout is not None
        port = json.loads(server.stdout.readline())["tcp_port"]

        async def control() -> None:
            with trio.fail_after(GUARD):
                async with tcpstream.connect_tcp("127.0.0.1", port) as arm:
                    handle = await arm.submit(tcpstream.commands.status())
                    result = await handle.completed()
                    rid.append(handle.request_id)
                    assert result.feedback is not None

        trio.run(control)
        assert server.wait(timeout=GUARD) == 0
    finally:
        if server.poll() is None:
            server.kill()
            server.wait()
    return rid[0]


def test_arm_server_tcp_capture_holds_the_command_packets(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "arm.pcapng"
    rid = arm_server_capture(path)
    capture = read_pcapng(path.read_bytes())
    assert len(capture.interfaces) == 1
    (interface,) = capture.interfaces
    assert interface.linktype == LINKTYPE_TCPSTREAM
    assert interface.name.startswith("tcp 127.0.0.1:")
    received = _bytes(capture, 0, Direction.INBOUND)
    sent = _bytes(capture, 0, Direction.OUTBOUND)
    assert len(received) % 216 == 0
    assert len(sent) % 216 == 0
    inbound = [decode_packet(received[i : i + 216]) for i in range(0, len(received), 216)]
    outbound = [decode_packet(sent[i : i + 216]) for i in range(0, len(sent), 216)]
    assert inbound[0].kind == PacketKind.HELLO
    assert outbound[0].kind == PacketKind.GRANT
    commands = [p for p in inbound if p.kind == PacketKind.COMMAND]
    assert [(p.code, p.request_id) for p in commands] == [(CommandCode.STATUS, rid)]
    replies = [(p.kind, p.request_id) for p in outbound if p.request_id == rid]
    assert replies == [(PacketKind.ACCEPTED, rid), (PacketKind.COMPLETED, rid)]
