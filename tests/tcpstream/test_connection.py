"""The sans-I/O cores: handshake, authentication, replay/reorder/tamper, garbage, framing."""

from __future__ import annotations

import itertools
import logging

import pytest

from tcpstream import CloseReason, CommandResult, FailureReason, Feedback, RefuseReason, commands
from tcpstream.commands import (
    PACKET_SIZE,
    Packet,
    PacketKind,
    decode_packet,
    encode_packet,
    words_body,
)
from tcpstream.connection import (
    MAX_BAD_IN_A_ROW,
    ClientConnection,
    CommandReceived,
    ControllerIdentity,
    ControlRequested,
    Event,
    Failed,
    Granted,
    PacketRejected,
    RefusalReceived,
    Role,
    ServerConnection,
    SessionEnded,
    SessionParameters,
    SessionState,
)

from .harness import KEY

PARAMS = SessionParameters(
    heartbeat_interval=0.5, dead_time=3.0, telemetry_period=0.0, memory_size=1024
)
WHO = ControllerIdentity("op", 42)


def source(start: int):  # type: ignore[no-untyped-def]
    counter = itertools.count(start)
    return lambda n: next(counter).to_bytes(n, "big")


def drain(conn: ServerConnection | ClientConnection) -> list[Event]:
    events = []
    while (ev := conn.next_event()) is not None:
        events.append(ev)
    return events


class Pair:
    """A client and a server connection with a wire between them (no I/O)."""

    def __init__(
        self,
        *,
        server_key: bytes | None = KEY,
        client_key: bytes | None = KEY,
        role: Role = Role.CONTROLLER,
        seed: int = 1,
        identity: ControllerIdentity = WHO,
    ) -> None:
        self.server = ServerConnection(PARAMS, key=server_key, nonce_source=source(seed * 1000))
        self.client = ClientConnection(
            identity, key=client_key, role=role, nonce_source=source(seed * 1000 + 500)
        )
        self.server_events: list[Event] = []
        self.client_events: list[Event] = []
        self.to_server: list[bytes] = []  # every packet the client sent
        self.to_client: list[bytes] = []

    def flush(self, now: float = 0.0, *, grant: bool = True) -> None:
        """Move bytes both ways until quiet; grant any request."""
        while True:
            up, down = self.client.data_to_send(), self.server.data_to_send()
            if not up and not down:
                return
            if up:
                self.to_server += _split(up)
                self.server.receive_data(up, now)
            if down:
                self.to_client += _split(down)
                self.client.receive_data(down, now)
            for ev in drain(self.server):
                self.server_events.append(ev)
                if isinstance(ev, ControlRequested) and grant:
                    self.server.grant(ev.role, 0, now)
            self.client_events += drain(self.client)

    def open(self) -> Pair:
        self.client.connect(0.0)
        self.flush()
        return self


def _split(data: bytes) -> list[bytes]:
    return [data[i : i + PACKET_SIZE] for i in range(0, len(data), PACKET_SIZE)]


def received_commands(events: list[Event]) -> list[CommandReceived]:
    return [e for e in events if isinstance(e, CommandReceived)]


# --- handshake and authentication ---------------------------------------------------


def test_keyed_handshake_grants_and_tags_every_packet() -> None:
    pair = Pair().open()
    assert pair.server.state is SessionState.OPEN
    assert pair.client.state is SessionState.OPEN
    kinds = [decode_packet(p).kind for p in pair.to_server + pair.to_client]
    assert kinds == [PacketKind.HELLO, PacketKind.AUTH, PacketKind.CHALLENGE, PacketKind.GRANT]
    granted = [e for e in pair.client_events if isinstance(e, Granted)]
    assert granted == [Granted(Role.CONTROLLER, PARAMS, 0)]
    pair.client.send_command(1, commands.status(), 0.0)
    pair.flush()
    command = decode_packet(pair.to_server[-1])
    assert command.kind is PacketKind.COMMAND
    assert command.counter == 3  # HELLO, AUTH, COMMAND
    assert command.tag != bytes(16)
    assert received_commands(pair.server_events)[0].request_id == 1


def test_unkeyed_handshake_has_no_challenge_and_zero_tags() -> None:
    pair = Pair(server_key=None, client_key=None).open()
    kinds = [decode_packet(p).kind for p in pair.to_server + pair.to_client]
    assert kinds == [PacketKind.HELLO, PacketKind.GRANT]
    assert all(decode_packet(p).tag == bytes(16) for p in pair.to_server + pair.to_client)


@pytest.mark.parametrize(
    "client_key",
    [
        pytest.param(bytes([KEY[0] ^ 1]) + KEY[1:], id="one-bit-off"),
        pytest.param(b"x" * 32, id="unrelated"),
        pytest.param(KEY + b"!", id="longer"),
    ],
)
def test_wrong_key_is_refused_with_the_same_words(client_key: bytes) -> None:
    pair = Pair(client_key=client_key).open()
    refusals = [e for e in pair.client_events if isinstance(e, RefusalReceived)]
    assert refusals == [RefusalReceived(RefuseReason.NOT_AUTHORIZED, "authentication failed")]
    assert pair.server.state is SessionState.CLOSED
    assert not any(isinstance(e, ControlRequested) for e in pair.server_events)
    # The REFUSE packet is byte-for-byte the same whichever wrong key was used.
    assert pair.to_client[-1] == Pair(client_key=b"y" * 40).open().to_client[-1]


def test_client_without_key_cannot_answer_a_challenge() -> None:
    pair = Pair(client_key=None).open()
    ended = [e for e in pair.client_events if isinstance(e, SessionEnded)]
    assert ended[0].reason is CloseReason.AUTHENTICATION
    assert "requires a pre-shared key" in ended[0].message
    # Its BYE is untagged, and after the CHALLENGE nothing untagged is believed
    # (a forger could otherwise abort anyone's handshake): the arm ends it at
    # the handshake timeout.
    assert pair.server.state is SessionState.CHALLENGED
    pair.server.handle_timer(60.0)
    assert pair.server.state is SessionState.CLOSED


def test_keyed_client_refuses_an_unauthenticated_arm() -> None:
    """No downgrade: a controller with a key never commands an arm that cannot prove it."""
    pair = Pair(server_key=None).open()
    ended = [e for e in pair.client_events if isinstance(e, SessionEnded)]
    assert ended[0].reason is CloseReason.AUTHENTICATION
    assert pair.client.role is None


def test_short_keys_are_refused() -> None:
    with pytest.raises(ValueError, match="16 bytes"):
        ServerConnection(PARAMS, key=b"short")


# --- replay, reorder, tamper, reflection ---------------------------------------------


def test_replayed_command_is_rejected_and_counted() -> None:
    pair = Pair().open()
    pair.client.send_command(1, commands.move_joint(1, 0.1), 0.0)
    pair.flush()
    captured = pair.to_server[-1]
    pair.server.receive_data(captured, 1.0)
    events = drain(pair.server)
    assert received_commands(events) == []
    assert [type(e) for e in events] == [PacketRejected]
    assert pair.server.statistics().replays == 1
    # Keyed: a replay is dropped unanswered (a forger gets nothing back).
    assert pair.server.data_to_send() == b""
    unkeyed = Pair(server_key=None, client_key=None).open()
    unkeyed.client.send_command(1, commands.move_joint(1, 0.1), 0.0)
    unkeyed.flush()
    unkeyed.server.receive_data(unkeyed.to_server[-1], 1.0)
    reply = decode_packet(unkeyed.server.data_to_send())
    assert reply.kind is PacketKind.FAILED
    assert reply.status == FailureReason.NOT_AUTHORIZED


def test_reordered_commands_are_rejected() -> None:
    pair = Pair().open()
    pair.client.send_command(1, commands.move_joint(1, 0.1), 0.0)
    pair.client.send_command(2, commands.move_joint(2, 0.1), 0.0)
    first, second = _split(pair.client.data_to_send())
    pair.server.receive_data(second + first, 0.0)
    events = drain(pair.server)
    assert [e.request_id for e in received_commands(events)] == [2]
    assert pair.server.statistics().replays == 1


@pytest.mark.parametrize("offset", [4, 7, 13, 20, 30, 60, 199, 200, 215])
def test_tampered_packets_fail_the_tag(offset: int) -> None:
    pair = Pair().open()
    pair.client.send_command(1, commands.move_joint(1, 0.1), 0.0)
    raw = bytearray(pair.client.data_to_send())
    raw[offset] ^= 0x01
    pair.server.receive_data(bytes(raw), 0.0)
    events = drain(pair.server)
    assert received_commands(events) == []
    stats = pair.server.statistics()
    assert stats.bad_packets == 1
    # Flipping a bit in the header may break decoding first; either way nothing runs.
    assert stats.tag_failures + (1 if offset in (4, 7) else 0) >= 1


def test_packets_from_an_old_session_do_not_verify_in_a_new_one() -> None:
    old = Pair(seed=1).open()
    old.client.send_command(1, commands.move_joints([1.0] * 6), 0.0)
    old.flush()
    recorded = old.to_server[-1]
    new = Pair(seed=2).open()
    new.server.receive_data(recorded, 0.0)
    assert received_commands(drain(new.server)) == []
    assert new.server.statistics().tag_failures == 1


def test_a_reflected_packet_does_not_verify() -> None:
    pair = Pair().open()
    grant = pair.to_client[-1]
    pair.server.receive_data(grant, 0.0)
    drain(pair.server)
    assert pair.server.statistics().tag_failures == 1


def test_counters_checked_without_a_key_too() -> None:
    pair = Pair(server_key=None, client_key=None).open()
    pair.client.send_command(1, commands.status(), 0.0)
    pair.flush()
    pair.server.receive_data(pair.to_server[-1], 0.0)
    assert received_commands(drain(pair.server)) == []
    assert pair.server.statistics().replays == 1


# --- garbage, framing, handshake faults ---------------------------------------------------


def test_garbage_peer_is_dropped_after_the_limit_and_not_before() -> None:
    # Unkeyed: a keyed session drops unauthenticated junk without counting it
    # towards the limit (tests/tcpstream/test_forgery.py).
    pair = Pair(server_key=None, client_key=None).open()
    junk = encode_packet(Packet(PacketKind.COMMAND, code=99))  # decodes to UnknownCommand
    junk = junk[:6] + b"\x00\x63" + junk[8:]
    pair.server.receive_data(junk * (MAX_BAD_IN_A_ROW - 1), 0.0)
    assert pair.server.state is SessionState.OPEN
    replies = [decode_packet(p) for p in _split(pair.server.data_to_send())]
    assert [r.status for r in replies] == [FailureReason.UNKNOWN_COMMAND] * (MAX_BAD_IN_A_ROW - 1)
    pair.server.receive_data(junk, 0.0)
    assert pair.server.state is SessionState.CLOSED
    last = decode_packet(_split(pair.server.data_to_send())[-1])
    assert last.kind is PacketKind.BYE
    assert last.status == CloseReason.GARBAGE
    ended = [e for e in drain(pair.server) if isinstance(e, SessionEnded)]
    assert ended[-1].reason is CloseReason.GARBAGE


def test_a_good_packet_resets_the_garbage_count() -> None:
    pair = Pair().open()
    bad = b"\x00" * PACKET_SIZE
    for rid in range(1, 4):
        pair.server.receive_data(bad * (MAX_BAD_IN_A_ROW - 1), 0.0)
        pair.client.send_command(rid, commands.status(), 0.0)
        pair.server.receive_data(pair.client.data_to_send(), 0.0)
    assert pair.server.state is SessionState.OPEN
    assert len(received_commands(drain(pair.server))) == 3


def test_resynchronises_after_a_partial_packet() -> None:
    pair = Pair().open()
    pair.client.send_command(1, commands.status(), 0.0)
    good = pair.client.data_to_send()
    pair.server.receive_data(b"\x55" * 100 + good, 0.0)
    events = drain(pair.server)
    assert [e.request_id for e in received_commands(events)] == [1]
    stats = pair.server.statistics()
    assert (stats.resyncs, stats.bad_packets) == (1, 1)


def test_one_byte_at_a_time_gives_the_same_events() -> None:
    whole = Pair().open()
    for rid in (1, 2, 3):
        whole.client.send_command(rid, commands.move_joint(rid, 0.1), 0.0)
    data = whole.client.data_to_send()
    server = whole.server
    for b in data:
        server.receive_data(bytes([b]), 0.0)
    assert [e.request_id for e in received_commands(drain(server))] == [1, 2, 3]
    # and with trailing bytes of the next packet left over
    server.receive_data(data[:10], 0.0)
    assert received_commands(drain(server)) == []


def test_anything_but_hello_first_is_refused() -> None:
    server = ServerConnection(PARAMS)
    server.receive_data(encode_packet(Packet(PacketKind.COMMAND, code=2, counter=1)), 0.0)
    reply = decode_packet(server.data_to_send())
    assert (reply.kind, reply.status) == (PacketKind.REFUSE, RefuseReason.BAD_HELLO)
    assert server.state is SessionState.CLOSED


def test_handshake_timeout_refuses() -> None:
    server = ServerConnection(PARAMS, handshake_timeout=10.0, now=5.0)
    assert server.get_timer() == 15.0
    server.handle_timer(14.9)
    assert server.state is SessionState.AWAITING_HELLO
    server.handle_timer(15.0)
    reply = decode_packet(server.data_to_send())
    assert (reply.kind, reply.status) == (PacketKind.REFUSE, RefuseReason.HANDSHAKE_TIMEOUT)
    assert server.get_timer() is None


def test_heartbeats_and_silence_timers_are_exact() -> None:
    pair = Pair(server_key=None, client_key=None).open()
    assert pair.server.get_timer() == 0.5
    pair.server.handle_timer(0.5)
    beat = decode_packet(pair.server.data_to_send())
    assert beat.kind is PacketKind.HEARTBEAT
    assert pair.server.get_timer() == 1.0
    for t in (1.0, 1.5, 2.0, 2.5):
        pair.server.handle_timer(t)
    pair.server.handle_timer(3.0)  # nothing from the client since t=0: dead time 3 s
    assert pair.server.state is SessionState.CLOSED
    ended = [e for e in drain(pair.server) if isinstance(e, SessionEnded)]
    assert ended[-1].reason is CloseReason.SILENCE


def test_observer_commands_are_refused_by_the_arm() -> None:
    pair = Pair(role=Role.OBSERVER).open()
    assert pair.server.role is Role.OBSERVER
    # The sans-I/O client sends it; the arm is what must refuse it.
    pair.client.send_command(1, commands.status(), 0.0)
    pair.flush()
    reply = decode_packet(pair.to_client[-1])
    assert (reply.kind, reply.status) == (PacketKind.FAILED, FailureReason.NOT_AUTHORIZED)
    assert received_commands(pair.server_events) == []


def test_idle_controller_is_released_but_not_while_a_command_runs() -> None:
    server = ServerConnection(PARAMS, idle_timeout=10.0)
    client = ClientConnection(WHO)
    client.connect(0.0)
    server.receive_data(client.data_to_send(), 0.0)
    drain(server)
    server.grant(Role.CONTROLLER, 0, 0.0)
    client.receive_data(server.data_to_send(), 0.0)
    move = commands.move_joints([1.0] * 6)

    def run_until(end: float, start: float) -> None:
        """Both sides heartbeat each other every 0.5 s (the link stays alive)."""
        t = start
        while t < end and server.state is SessionState.OPEN:
            t += 0.25
            client.handle_timer(t)
            if up := client.data_to_send():  # b"" would mean end of stream
                server.receive_data(up, t)
            server.handle_timer(t)
            if down := server.data_to_send():
                client.receive_data(down, t)

    client.send_command(1, move, 2.0)
    server.receive_data(client.data_to_send(), 2.0)
    drain(server)
    server.accepted(1, move.code, 0, 2.0)
    run_until(30.0, 2.0)  # a command running is activity, however long it runs
    assert server.state is SessionState.OPEN
    server.completed(1, move.code, _result(), 30.0)
    run_until(39.75, 30.0)  # heartbeats alone do not count...
    assert server.state is SessionState.OPEN
    run_until(40.0, 39.75)  # ...10 s after the last reply, control is released
    assert server.state is SessionState.CLOSED
    ended = [e for e in drain(server) if isinstance(e, SessionEnded)]
    assert ended[-1].reason is CloseReason.IDLE


def _result() -> CommandResult:
    return CommandResult(Feedback((0.0,) * 6, 0.0, (0.0,) * 3, (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)))


def test_packet_trace_logs_every_packet_decoded(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.DEBUG, logger="tcpstream.packets"):
        pair = Pair(server_key=None, client_key=None).open()
        pair.client.send_command(7, commands.move_joint(2, 0.5), 0.0)
        pair.flush()
    lines = [r.getMessage() for r in caplog.records if r.name == "tcpstream.packets"]
    assert lines[0] == "client out: HELLO #1"
    assert "server out: GRANT #1 aux=0.5,3,0,1024" in lines
    assert (
        "client out: COMMAND #2 rid=7 code=MOVE_JOINT w=2,0.5,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0"
        in (lines)
    )
    assert (
        "server in: COMMAND #2 rid=7 code=MOVE_JOINT w=2,0.5,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0"
        in (lines)
    )


def test_request_id_zero_is_rejected() -> None:
    pair = Pair(server_key=None, client_key=None).open()
    raw = encode_packet(Packet(PacketKind.COMMAND, code=2, request_id=0, counter=2))
    pair.server.receive_data(raw, 0.0)
    assert received_commands(drain(pair.server)) == []
    reply = decode_packet(pair.server.data_to_send())
    assert (reply.kind, reply.status, reply.request_id) == (
        PacketKind.FAILED,
        FailureReason.BAD_PACKET,
        0,
    )


def test_an_undecodable_completed_settles_its_command() -> None:
    pair = Pair(server_key=None, client_key=None).open()
    pair.client.send_command(3, commands.status(), 0.0)
    pair.flush()
    words = [0.0] * 18
    words[17] = 99.0  # an error indicator this client does not know
    bad = Packet(PacketKind.COMPLETED, code=2, request_id=3, counter=2, body=words_body(words))
    pair.client.receive_data(encode_packet(bad), 0.0)
    events = drain(pair.client)
    failed = [e for e in events if isinstance(e, Failed)]
    assert [(f.request_id, f.reason) for f in failed] == [(3, FailureReason.BAD_PACKET)]
    assert "check the arm with STATUS" in failed[0].message
    assert pair.client.statistics().bad_packets == 1


def test_an_unknown_failure_reason_keeps_its_number() -> None:
    pair = Pair(server_key=None, client_key=None).open()
    pair.client.send_command(4, commands.status(), 0.0)
    pair.flush()
    reply = Packet(PacketKind.FAILED, code=2, status=200, request_id=4, counter=2)
    pair.client.receive_data(encode_packet(reply), 0.0)
    failed = [e for e in drain(pair.client) if isinstance(e, Failed)]
    assert failed[0].reason is FailureReason.ARM_FAULT
    assert failed[0].message.startswith("(reason code 200)")


@pytest.mark.parametrize("seen", [0.5, -1.0, 2.0**32])
def test_command_failures_seen_must_be_a_request_id(seen: float) -> None:
    pair = Pair(server_key=None, client_key=None).open()
    body = words_body([0.0] * 18)
    raw = encode_packet(
        Packet(PacketKind.COMMAND, code=2, request_id=1, counter=2, aux=(seen, 0, 0, 0), body=body)
    )
    pair.server.receive_data(raw, 0.0)
    assert received_commands(drain(pair.server)) == []
    reply = decode_packet(pair.server.data_to_send())
    assert (reply.kind, reply.status) == (PacketKind.FAILED, FailureReason.BAD_PACKET)
