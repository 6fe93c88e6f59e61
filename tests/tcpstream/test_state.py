"""The state table, and hypothesis over state x event on the sans-I/O server."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tcpstream import CloseReason, LocalProtocolError, RefuseReason, commands
from tcpstream.commands import PACKET_SIZE, Packet, PacketKind, encode_packet, words_body
from tcpstream.connection import (
    TRANSITIONS,
    ClientConnection,
    CommandReceived,
    ControllerIdentity,
    ControlRequested,
    EmergencyStopRequested,
    Granted,
    IllegalTransition,
    Role,
    ServerConnection,
    SessionParameters,
    SessionState,
    Side,
    Trigger,
    transition,
)

PARAMS = SessionParameters(0.5, 3.0, 0.0, 1024)
INITIAL = {Side.CLIENT: SessionState.IDLE, Side.SERVER: SessionState.AWAITING_HELLO}


@pytest.mark.parametrize("side", list(Side))
def test_every_state_x_trigger_is_in_the_table_or_illegal(side: Side) -> None:
    for state in SessionState:
        for trigger in Trigger:
            if (side, state, trigger) in TRANSITIONS:
                assert transition(side, state, trigger) is TRANSITIONS[(side, state, trigger)]
            else:
                with pytest.raises(IllegalTransition) as info:
                    transition(side, state, trigger)
                assert isinstance(info.value, LocalProtocolError)


@pytest.mark.parametrize("side", list(Side))
def test_closed_is_final_and_every_live_state_reaches_it(side: Side) -> None:
    edges = {(s, t): n for (sd, s, t), n in TRANSITIONS.items() if sd is side}
    assert not any(s is SessionState.CLOSED for s, _ in edges)
    reachable = {INITIAL[side]}
    frontier = [INITIAL[side]]
    while frontier:
        state = frontier.pop()
        for (s, _), n in edges.items():
            if s is state and n not in reachable:
                reachable.add(n)
                frontier.append(n)
    assert SessionState.OPEN in reachable
    assert SessionState.CLOSED in reachable
    for state in reachable - {SessionState.CLOSED}:
        assert (state, Trigger.FAULT) in edges


# --- hypothesis: a server fed arbitrary packets and calls in any order -----------------

KINDS = list(PacketKind)


@st.composite
def server_inputs(draw: st.DrawFn) -> list[tuple[str, object]]:
    steps: list[tuple[str, object]] = []
    for _ in range(draw(st.integers(1, 25))):
        what = draw(st.sampled_from(["packet", "hello", "garbage", "timer", "grant", "refuse"]))
        if what == "packet":
            kind = draw(st.sampled_from(KINDS))
            code = draw(st.sampled_from([2, 6, 12, 13, 16, 99]))
            counter = draw(st.integers(0, 40))
            flags = draw(st.integers(0, 3))
            steps.append((what, (kind, code, counter, flags)))
        elif what == "garbage":
            steps.append((what, draw(st.binary(min_size=1, max_size=2 * PACKET_SIZE))))
        elif what == "timer":
            steps.append((what, draw(st.floats(0, 20))))
        elif what == "hello":
            steps.append((what, draw(st.sampled_from(list(Role)))))
        else:
            steps.append((what, None))
    return steps


def _hello_bytes(role: Role) -> bytes:
    client = ClientConnection(ControllerIdentity("h", 1), role=role)
    client.connect(0.0)
    return client.data_to_send()


@given(server_inputs(), st.booleans())
def test_server_survives_any_input_sequence(steps: list[tuple[str, object]], keyed: bool) -> None:
    key = b"k" * 16 if keyed else None
    server = ServerConnection(PARAMS, key=key, handshake_timeout=10.0)
    now = 0.0
    requested = False
    for what, arg in steps:
        before = server.state
        try:
            if what == "packet":
                kind, code, counter, flags = arg  # type: ignore[misc]
                body = words_body([0.0] * 18)
                raw = encode_packet(Packet(kind, flags, code, 0, 1, counter, body=body))
                server.receive_data(raw, now)
            elif what == "hello":
                server.receive_data(_hello_bytes(arg), now)  # type: ignore[arg-type]
            elif what == "garbage":
                server.receive_data(arg, now)  # type: ignore[arg-type]
            elif what == "timer":
                now = max(now, float(arg))  # type: ignore[arg-type]
                server.handle_timer(now)
            elif what == "grant":
                server.grant(Role.CONTROLLER, 0, now)
            else:
                server.refuse(RefuseReason.BUSY, "busy", now)
        except IllegalTransition:
            # Only a local call may be illegal, and it changes nothing.
            assert what in ("grant", "refuse")
            assert server.state is before
        while (ev := server.next_event()) is not None:
            if isinstance(ev, ControlRequested):
                requested = True
            if isinstance(ev, CommandReceived | EmergencyStopRequested):
                # Commands reach the application only in an OPEN controller session;
                # unauthenticated packets never do on a keyed arm.
                assert server.state is SessionState.OPEN
                assert server.role is Role.CONTROLLER
                assert not keyed
        out = server.data_to_send()
        assert len(out) % PACKET_SIZE == 0
        if before is SessionState.CLOSED:
            assert out == b""
            assert server.state is SessionState.CLOSED
        assert server.state in SessionState
    if server.state is SessionState.OPEN:
        assert requested


def test_client_api_misuse_is_a_local_error() -> None:
    client = ClientConnection(ControllerIdentity("x", 1))
    with pytest.raises(IllegalTransition):
        client.send_command(1, commands.status(), 0.0)
    client.connect(0.0)
    with pytest.raises(IllegalTransition):
        client.connect(0.0)
    with pytest.raises(LocalProtocolError, match="request id"):
        client.send_command(0, commands.status(), 0.0)


@st.composite
def client_inputs(draw: st.DrawFn) -> list[tuple[str, object]]:
    steps: list[tuple[str, object]] = []
    for _ in range(draw(st.integers(1, 25))):
        what = draw(st.sampled_from(["packet", "garbage", "timer", "command", "close"]))
        if what == "packet":
            kind = draw(st.sampled_from(KINDS))
            code = draw(st.sampled_from([0, 2, 6, 99]))
            counter = draw(st.integers(0, 40))
            flags = draw(st.integers(0, 2))
            status = draw(st.integers(0, 40))
            aux = draw(st.sampled_from([(0.0,) * 4, (0.5, 3.0, 0.0, 1024.0), (1.0, 0.5, 0.0, 0.0)]))
            steps.append((what, (kind, code, counter, flags, status, aux)))
        elif what == "garbage":
            steps.append((what, draw(st.binary(min_size=1, max_size=2 * PACKET_SIZE))))
        elif what == "timer":
            steps.append((what, draw(st.floats(0, 60))))
        else:
            steps.append((what, None))
    return steps


@given(client_inputs(), st.booleans())
def test_client_survives_any_input_sequence(steps: list[tuple[str, object]], keyed: bool) -> None:
    client = ClientConnection(ControllerIdentity("c", 1), key=b"k" * 16 if keyed else None)
    client.connect(0.0)
    client.data_to_send()
    now = 0.0
    for what, arg in steps:
        before = client.state
        try:
            if what == "packet":
                kind, code, counter, flags, status, aux = arg  # type: ignore[misc]
                raw = encode_packet(
                    Packet(kind, flags, code, status, 1, counter, aux, words_body([0.0] * 18))
                )
                client.receive_data(raw, now)
            elif what == "garbage":
                client.receive_data(arg, now)  # type: ignore[arg-type]
            elif what == "timer":
                now = max(now, float(arg))  # type: ignore[arg-type]
                client.handle_timer(now)
            elif what == "command":
                client.send_command(1, commands.status(), now)
            else:
                client.close(CloseReason.NORMAL, now)
        except IllegalTransition:
            assert what == "command"
            assert client.state is before
        while (ev := client.next_event()) is not None:
            if isinstance(ev, Granted):
                # A keyed client is never granted by an unauthenticated packet.
                assert not keyed
        out = client.data_to_send()
        assert len(out) % PACKET_SIZE == 0
        if before is SessionState.CLOSED:
            assert out == b""
