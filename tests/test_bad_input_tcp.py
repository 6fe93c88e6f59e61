"""The bad-input matrix (issue 11), TCP session: a running Server fed hostile streams.

Each case opens an in-memory stream to a real :class:`tcpstream.Server` (the
same code path as a TCP connection) on trio's virtual clock, writes hostile
bytes or behaves like a hostile peer, and asserts the outcome exactly: the
server closes the stream (disconnect), refuses with a reason, or answers a
FAILED and counts the packet.  After every case the server still serves a
well-behaved controller, which gets its command executed exactly once.
"""

from __future__ import annotations

import math
import random
import struct
import tracemalloc
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import pytest
import trio
import trio.testing

from tcpstream import (
    CloseReason,
    Command,
    CommandCode,
    FailureReason,
    Server,
    ServerConfig,
    commands,
)
from tcpstream._pump import CLOSE_TIMEOUT
from tcpstream.commands import PACKET_SIZE, Packet, PacketKind, decode_packet, encode_packet
from tcpstream.connection import (
    MAX_BAD_IN_A_ROW,
    ClientConnection,
    ControllerIdentity,
    Event,
    Failed,
    Granted,
    RefusalReceived,
    SessionEnded,
)

from .tcpstream.fakearm import FakeArm
from .tcpstream.harness import KEY, run

CONFIG = ServerConfig(key=KEY, rtt_hint=0.2, max_connections=3, handshake_timeout=10.0)
"""Handshake 10 s, heartbeat 0.25 s, deadman max(1, 0.4 + 1) = 1.4 s."""
READ_LIMIT = 60.0
"""Virtual seconds any read waits: far beyond every timeout in CONFIG."""


class Peer:
    """One hand-driven connection to the server: raw bytes out, everything in."""

    def __init__(self, stream: trio.abc.Stream) -> None:
        self.stream = stream
        self.received = bytearray()
        self.closed_at: float | None = None

    async def send(self, data: bytes) -> bool:
        """Write; False if the server has already closed the stream."""
        try:
            await self.stream.send_all(data)
        except (trio.BrokenResourceError, trio.ClosedResourceError):
            return False
        return True

    async def read_until_closed(self, limit: float = READ_LIMIT) -> bytes:
        with trio.move_on_after(limit):
            while chunk := await self.stream.receive_some():
                self.received += chunk
            self.closed_at = trio.current_time()
        return bytes(self.received)

    def packets(self) -> list[Packet]:
        raw = bytes(self.received)
        return [decode_packet(raw[i : i + PACKET_SIZE]) for i in range(0, len(raw), PACKET_SIZE)]


@asynccontextmanager
async def serving(config: ServerConfig = CONFIG) -> AsyncIterator[tuple[Server, FakeArm, Opener]]:
    arm = FakeArm(move_time=0.5)
    async with Server(arm, config) as server, trio.open_nursery() as nursery:
        yield server, arm, Opener(server, nursery)
        nursery.cancel_scope.cancel()


class Opener:
    def __init__(self, server: Server, nursery: trio.Nursery) -> None:
        self._server = server
        self._nursery = nursery

    def open(self) -> Peer:
        client_end, server_end = trio.testing.memory_stream_pair()
        self._nursery.start_soon(self._server.serve_stream, server_end)
        return Peer(client_end)


async def _session(
    opener: Opener, *, key: bytes | None = KEY, name: str = "op"
) -> tuple[Peer, ClientConnection, list[Event]]:
    """A controller that completes the handshake by hand (sans-I/O client)."""
    peer = opener.open()
    client = ClientConnection(ControllerIdentity(name, 7), key=key, now=trio.current_time())
    client.connect(trio.current_time())
    events: list[Event] = []
    with trio.fail_after(READ_LIMIT):
        while not any(isinstance(e, (Granted, RefusalReceived, SessionEnded)) for e in events):
            await peer.send(client.data_to_send())
            chunk = await peer.stream.receive_some()
            client.receive_data(chunk, trio.current_time())
            while (ev := client.next_event()) is not None:
                events.append(ev)
        await peer.send(client.data_to_send())
    return peer, client, events


async def _command_reply(peer: Peer, client: ClientConnection) -> list[Event]:
    """Flush the client's output and collect events until a reply settles a command."""
    events: list[Event] = []
    await peer.send(client.data_to_send())
    with trio.fail_after(READ_LIMIT):
        while not any(isinstance(e, (Failed, SessionEnded)) for e in events) and not any(
            type(e).__name__ == "Completed" for e in events
        ):
            chunk = await peer.stream.receive_some()
            if not chunk:
                client.receive_data(b"", trio.current_time())
            else:
                client.receive_data(chunk, trio.current_time())
            while (ev := client.next_event()) is not None:
                events.append(ev)
            await peer.send(client.data_to_send())
    return events


async def _still_serves(server: Server, arm: FakeArm, opener: Opener) -> None:
    """A well-behaved controller connects and gets one command executed exactly once."""
    before = len(arm.executed)
    peer, client, events = await _session(opener, name=f"good{before}")
    assert any(isinstance(e, Granted) for e in events), events
    client.send_command(1, commands.move_joint(1, 0.1), trio.current_time())
    replies = await _command_reply(peer, client)
    assert [type(e).__name__ for e in replies][-1] == "Completed", replies
    assert len(arm.executed) == before + 1
    client.close(CloseReason.NORMAL, trio.current_time())
    await peer.send(client.data_to_send())
    await peer.stream.aclose()


async def _slot_freed(server: Server) -> None:
    """The server lets go of a closed connection within CLOSE_TIMEOUT even when
    the peer never closes its end (a half-closed peer cannot hold a slot)."""
    await trio.sleep(CLOSE_TIMEOUT + 0.1)
    assert server.statistics().connections == 0


def _hello_bytes(version: int = 1) -> bytes:
    client = ClientConnection(ControllerIdentity("v", 1), key=KEY)
    client.connect(0.0)
    raw = bytearray(client.data_to_send())
    raw[2] = version
    return bytes(raw)


# --- before the handshake ------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "payload"),
    [
        ("garbage", random.Random(3).randbytes(PACKET_SIZE * (MAX_BAD_IN_A_ROW + 2))),
        ("oversized single write", random.Random(4).randbytes(1 << 20)),
        ("wrong version", _hello_bytes(version=2) * (MAX_BAD_IN_A_ROW + 2)),
        ("wrong magic", b"XX" + _hello_bytes()[2:]),
        ("a COMMAND before HELLO", encode_packet(Packet(PacketKind.COMMAND, code=1, counter=1))),
        ("a GRANT from the controller", encode_packet(Packet(PacketKind.GRANT, counter=1))),
    ],
)
def test_hostile_bytes_before_hello_end_in_a_disconnect(name: str, payload: bytes) -> None:
    async def main() -> None:
        async with serving() as (server, arm, opener):
            peer = opener.open()
            start = trio.current_time()
            async with trio.open_nursery() as n:
                n.start_soon(peer.send, payload)
                await peer.read_until_closed()
            assert peer.closed_at is not None, f"{name}: the server kept the stream open"
            assert peer.closed_at - start <= CONFIG.handshake_time() + 5.0
            kinds = {p.kind for p in peer.packets()}
            assert PacketKind.GRANT not in kinds
            assert kinds <= {PacketKind.FAILED, PacketKind.REFUSE, PacketKind.BYE}, kinds
            assert arm.executed == []
            await _slot_freed(server)
            await _still_serves(server, arm, opener)

    run(main)


def test_truncated_hello_then_eof_closes_and_frees_the_slot() -> None:
    async def main() -> None:
        async with serving() as (server, arm, opener):
            peer = opener.open()
            await peer.send(_hello_bytes()[:100])
            await peer.stream.send_eof() if hasattr(peer.stream, "send_eof") else None
            await peer.stream.aclose()
            await _slot_freed(server)
            await _still_serves(server, arm, opener)

    run(main)


def test_half_open_connections_fill_the_server_then_time_out() -> None:
    """Peers that connect and say nothing hold a slot for at most the handshake
    time, and never keep a controller out: with every slot held, a new
    connection takes the oldest silent one's (issue 17, finding 6: twelve idle
    sockets kept a keyed controller out with SERVER_FULL)."""

    async def main() -> None:
        async with serving() as (server, _arm, opener):
            silent = [opener.open() for _ in range(CONFIG.max_connections)]
            await trio.sleep(0.1)
            assert server.statistics().connections == CONFIG.max_connections
            _peer, _client, events = await _session(opener)
            assert any(isinstance(e, Granted) for e in events), events
            await silent[0].read_until_closed()  # the oldest silent one made room
            assert silent[0].closed_at is not None
            stats = server.statistics()
            assert (stats.handshakes_evicted, stats.refused) == (1, 0)
            start = trio.current_time()
            async with trio.open_nursery() as n:
                for other in silent[1:]:
                    n.start_soon(other.read_until_closed)
            for other in silent[1:]:
                assert other.closed_at is not None
                assert other.closed_at - start <= CONFIG.handshake_time() + 5.0

    run(main)


def test_slow_loris_hello_does_not_extend_the_handshake() -> None:
    """One byte of HELLO per second: the handshake deadline is absolute, so the
    peer is dropped at the deadline however busy it keeps the line."""

    async def main() -> None:
        async with serving() as (server, arm, opener):
            peer = opener.open()
            hello = _hello_bytes()
            start = trio.current_time()

            async def trickle() -> None:
                for i in range(len(hello)):
                    if not await peer.send(hello[i : i + 1]):
                        return
                    await trio.sleep(1.0)

            async with trio.open_nursery() as n:
                n.start_soon(trickle)
                await peer.read_until_closed()
                n.cancel_scope.cancel()
            assert peer.closed_at is not None
            assert peer.closed_at - start <= CONFIG.handshake_time() + 5.0 + 1.0
            assert PacketKind.GRANT not in {p.kind for p in peer.packets()}
            await _still_serves(server, arm, opener)

    run(main)


# --- after the handshake --------------------------------------------------------------


NAN = float("nan")
BAD_PACKET = FailureReason.BAD_PACKET  # a non-finite word fails decoding
BAD_ARGUMENT = FailureReason.BAD_ARGUMENT  # decodes, but validate_arguments refuses it


@pytest.mark.parametrize(
    ("name", "command", "reason"),
    [
        ("NaN argument", Command(CommandCode.MOVE_JOINTS, (0.1, NAN)), BAD_PACKET),
        (
            "infinite argument",
            Command(CommandCode.MOVE_TO_POSITION, (math.inf,)),
            BAD_PACKET,
        ),
        ("joint 9 of 6", Command(CommandCode.MOVE_JOINT, (9.0, 0.1)), BAD_ARGUMENT),
        (
            "fractional joint",
            Command(CommandCode.MOVE_JOINT, (1.5, 0.1)),
            BAD_ARGUMENT,
        ),
        ("speed 7", Command(CommandCode.CHANGE_SPEED, (7.0,)), BAD_ARGUMENT),
        ("negative grip", Command(CommandCode.SQUEEZE, (-1.0,)), BAD_ARGUMENT),
        (
            "path of 10**6 points",
            Command(CommandCode.MOVE_PATH, (1e6,)),
            BAD_ARGUMENT,
        ),
    ],
)
def test_out_of_range_and_non_finite_arguments_fail_and_never_reach_the_arm(
    name: str, command: Command, reason: FailureReason
) -> None:
    finite = all(math.isfinite(w) for w in command.args)

    async def main() -> None:
        # Our own encoder refuses a non-finite word, so such a COMMAND is a
        # hostile peer's: forged on an unkeyed session by patching the bytes.
        config = CONFIG if finite else ServerConfig(rtt_hint=0.2, max_connections=3)
        async with serving(config) as (_server, arm, opener):
            peer, client, events = await _session(opener, key=KEY if finite else None)
            assert any(isinstance(e, Granted) for e in events)
            if finite:
                client.send_command(5, command, trio.current_time())
                replies = await _command_reply(peer, client)
            else:
                placeholder = Command(command.code, [0.0] * len(command.args), command.flags)
                client.send_command(5, placeholder, trio.current_time())
                raw = bytearray(client.data_to_send())
                raw[56 : 56 + 8 * len(command.args)] = struct.pack(
                    f"!{len(command.args)}d", *command.args
                )
                await peer.send(bytes(raw))
                replies = await _command_reply(peer, client)
            [failed] = [e for e in replies if isinstance(e, Failed)]
            assert failed.request_id == 5
            assert failed.reason is reason, failed
            assert arm.executed == []
            # The session survives one bad command: the next good one runs.
            client.send_command(6, commands.move_joint(2, 0.1), trio.current_time())
            replies = await _command_reply(peer, client)
            assert type(replies[-1]).__name__ == "Completed"
            assert len(arm.executed) == 1

    run(main)


def test_a_silent_controller_trips_the_deadman_and_the_arm_halts() -> None:
    """Half-open after the grant (the controller stops sending, the stream stays
    up): the deadman ends the session after dead_time and the arm is halted."""

    async def main() -> None:
        async with serving() as (server, arm, opener):
            peer, client, _ = await _session(opener)
            client.send_command(1, commands.move_joint(1, 0.5), trio.current_time())
            await peer.send(client.data_to_send())
            start = trio.current_time()
            await peer.read_until_closed()  # the client never answers heartbeats
            assert peer.closed_at is not None
            hb, dead = CONFIG.timing()
            assert peer.closed_at - start <= dead + hb + 0.5
            assert server.statistics().deadman_trips == 1
            assert arm.halts, "the arm was not halted"
            bye = peer.packets()[-1]
            assert bye.kind is PacketKind.BYE
            assert bye.status == CloseReason.SILENCE
            await _still_serves(server, arm, opener)

    run(main)


@pytest.mark.parametrize("keyed", [False, True])
def test_garbage_after_the_grant_is_counted_then_disconnects(keyed: bool) -> None:
    """Unkeyed: the garbage limit ends the session (BYE GARBAGE).  Keyed: packets
    whose tag does not verify change nothing (issue 17, finding 7) -- counted and
    dropped, never answered, never towards the limit -- so a peer that sends
    only garbage is ended by silence (the dead time) instead."""
    config = CONFIG if keyed else ServerConfig(rtt_hint=0.2, max_connections=3)

    async def main() -> None:
        async with serving(config) as (server, arm, opener):
            peer, _client, _ = await _session(opener, key=KEY if keyed else None)
            # Noise with no magic in it is skipped in one resync (one count); then
            # framed packets of a version nobody speaks, each counted.
            noise = struct.pack("!d", math.nan) * (PACKET_SIZE // 8) * 3
            bad_version = (b"TL\x09" + bytes(PACKET_SIZE - 3)) * MAX_BAD_IN_A_ROW
            await peer.send(noise + bad_version)
            await peer.read_until_closed()
            assert peer.closed_at is not None
            bye = peer.packets()[-1]
            expected = CloseReason.SILENCE if keyed else CloseReason.GARBAGE
            assert (bye.kind, bye.status) == (PacketKind.BYE, expected), bye
            # The resync counts as the first of the run, then each packet.
            assert server.statistics().bad_packets == MAX_BAD_IN_A_ROW + (1 if keyed else 0)
            if keyed:  # only the unframed noise was answered, not one forgery
                assert [p.kind for p in peer.packets()].count(PacketKind.FAILED) == 1
            assert arm.executed == []
            # The lease outlives the close by the dead time (the same controller
            # may resume); then the deadman trips and the arm is free again.
            await _slot_freed(server)
            assert server.statistics().deadman_trips == 1
            if keyed:  # _still_serves speaks with the key
                await _still_serves(server, arm, opener)

    run(main)


def test_a_megabyte_flood_leaves_memory_flat() -> None:
    """Eight peers each write 1 MiB of noise; traced memory after they are all
    dropped is within 256 KiB of before (nothing retained per byte)."""

    async def main() -> None:
        async with serving() as (server, arm, opener):
            await _still_serves(server, arm, opener)
            tracemalloc.start()
            try:
                base = tracemalloc.get_traced_memory()[0]
                rng = random.Random(9)
                for _ in range(8):
                    peer = opener.open()
                    async with trio.open_nursery() as n:
                        n.start_soon(peer.send, rng.randbytes(1 << 20))
                        await peer.read_until_closed()
                    await peer.stream.aclose()
                await _slot_freed(server)
                grown = tracemalloc.get_traced_memory()[0] - base
            finally:
                tracemalloc.stop()
            assert grown < 256 * 1024, grown
            assert server.statistics().connections == 0
            await _still_serves(server, arm, opener)

    run(main)


def test_a_command_in_the_same_read_as_the_bye_is_not_run_and_crashes_nothing() -> None:
    """A COMMAND and the BYE right behind it, in one write: the session is closed
    by the time the command is looked at.  It used to be accepted anyway, and
    the ACCEPTED on a closed session crashed the server (IllegalTransition,
    seen when Ctrl-C interrupted a demo); now it is not run and is counted."""

    async def main() -> None:
        async with serving() as (server, arm, opener):
            peer, client, events = await _session(opener, name="quitter")
            assert any(isinstance(e, Granted) for e in events), events
            client.send_command(1, commands.move_joint(1, 0.1), trio.current_time())
            client.close(CloseReason.NORMAL, trio.current_time())
            await peer.send(client.data_to_send())  # both packets, one write
            await trio.sleep(0.5)
            assert arm.executed == []
            assert server.statistics().commands_after_close == 1
            await peer.stream.aclose()
            await _still_serves(server, arm, opener)

    run(main)
