"""The endpoint's state table (serialsocket/_state.py) against itself, its
diagram in PROTOCOL.md, and a real Endpoint driven into every state.

* Every state x trigger pair: the table's next state, or LocalProtocolError.
* Every entry of the table is taken by a real Endpoint, through its public
  API or the wire, with exactly that trigger.
* In every state, the public calls and the packets the named state sets speak
  of (LIVE, WRITABLE, CONNECTED, PEER_MAY_ABORT, TERMINAL, DEAF) do what the
  sets say.
"""

from __future__ import annotations

import pathlib
from collections.abc import Callable

import pytest

from serialsocket import (
    ConnectionAborted,
    ConnectionRequested,
    Endpoint,
    EndpointConfig,
    LocalProtocolError,
    State,
)
from serialsocket._checks import BlockCheck
from serialsocket._diagram import render
from serialsocket._packet import Packet, build_packet
from serialsocket._state import (
    CONNECTED,
    DEAF,
    LIVE,
    PEER_MAY_ABORT,
    STATE_SETS,
    TERMINAL,
    TRANSITIONS,
    WRITABLE,
    Trigger,
    allowed,
    transition,
)
from serialsocket._wire import PacketType

from .simlink import SimLink

ROOT = pathlib.Path(__file__).resolve().parents[2]
DELAY = 0.05
Step = tuple[State, Trigger, State]


# --- the table alone -----------------------------------------------------------------


@pytest.mark.parametrize("state", list(State))
@pytest.mark.parametrize("trigger", list(Trigger))
def test_every_state_x_trigger_goes_where_the_table_says_or_raises(
    state: State, trigger: Trigger
) -> None:
    if (state, trigger) in TRANSITIONS:
        assert allowed(state, trigger)
        assert transition(state, trigger) is TRANSITIONS[(state, trigger)]
    else:
        assert not allowed(state, trigger)
        with pytest.raises(LocalProtocolError, match=f"in state '{state.value}'"):
            transition(state, trigger)


def test_the_table_has_the_expected_shape() -> None:
    assert len(TRANSITIONS) == 19
    # Only reset() leaves an end state, and it leads back to IDLE.
    for (state, trigger), after in TRANSITIONS.items():
        if state in TERMINAL:
            assert (trigger, after) == (Trigger.RESET, State.IDLE)
    # A dead link is judged only while ESTABLISHED (the endpoint declares it
    # only from its ESTABLISHED timer); CONNECTING fails at its deadline.
    assert [s for s, t in TRANSITIONS if t is Trigger.LINK_DEAD] == [State.ESTABLISHED]
    # Every live state can be ended by an E: REFUSED while connecting, ABORT otherwise.
    ends_by_e = {s for s, t in TRANSITIONS if t in (Trigger.ABORT, Trigger.REFUSED)}
    assert ends_by_e == LIVE
    assert not any(s is State.CONNECTING and t is Trigger.ABORT for s, t in TRANSITIONS)


def test_the_state_sets_agree_with_the_table() -> None:
    assert {s for s, t in TRANSITIONS if t is Trigger.RESET} == TERMINAL | {State.IDLE}
    # The states from which the table leads to ESTABLISHED are not CONNECTED yet.
    connecting = {s for (s, _), n in TRANSITIONS.items() if n is State.ESTABLISHED}
    assert connecting == {State.LISTEN, State.CONNECTING}
    assert {State.ESTABLISHED, State.LINGER} == CONNECTED
    assert set(State) - TERMINAL - {State.LINGER} == WRITABLE
    assert LIVE - {State.LISTEN} == PEER_MAY_ABORT
    assert {State.CLOSED, State.DEAD} == DEAF
    assert {name: sets for name, (sets, _) in STATE_SETS.items()} == {
        "live": LIVE,
        "writable": WRITABLE,
        "connected": CONNECTED,
        "peer may abort": PEER_MAY_ABORT,
        "terminal": TERMINAL,
        "deaf": DEAF,
    }


# --- the diagram ---------------------------------------------------------------------


def test_protocol_md_holds_exactly_the_rendered_table() -> None:
    doc = (ROOT / "serialsocket" / "PROTOCOL.md").read_text()
    section = doc[doc.index("## 7. States\n") : doc.index("## 8. ")]
    assert "```\n" + render() + "```\n" in section
    assert section.count("```") == 2  # no other, hand-drawn, diagram beside it


def test_the_rendering_lists_every_transition_once() -> None:
    lines = render().splitlines()
    rows = [line.split()[:3] for line in lines[2 : 2 + len(TRANSITIONS)]]
    assert {(State[s], Trigger[t], State[n]) for s, t, n in rows} == {
        (s, t, n) for (s, t), n in TRANSITIONS.items()
    }
    assert len(rows) == len(TRANSITIONS)
    assert lines[2] == "IDLE         LISTEN           LISTEN       listen() called"
    assert "ESTABLISHED  LINK_DEAD        DEAD         silence longer than dead_after" in lines
    assert "DEAD         -     -         -          -               x         x" in lines


# --- a real Endpoint in every state --------------------------------------------------


class Rig:
    """Endpoint ``a`` (the one under test) and its peer ``b`` on a simulated line."""

    def __init__(self, b_config: EndpointConfig | None = None) -> None:
        self.a = Endpoint(EndpointConfig(one_way_delay=DELAY))
        self.b = Endpoint(b_config or EndpointConfig(one_way_delay=DELAY))
        self.link = SimLink(self.a, self.b, delay=DELAY)
        self.steps: list[Step] = []
        """Every state change of ``a``: (from, trigger, to)."""
        go = self.a._go

        def recording_go(trigger: Trigger) -> None:
            old = self.a.state
            go(trigger)
            self.steps.append((old, trigger, self.a.state))

        self.a._go = recording_go  # type: ignore[method-assign]

    def run_until(self, cond: Callable[[], bool]) -> None:
        self.link.run_until(cond, limit=1_000.0)

    def established(self) -> Rig:
        self.a.connect(self.link.now)
        self.b.listen()
        self.run_until(lambda: self.a.state is self.b.state is State.ESTABLISHED)
        return self

    def lingering(self) -> Rig:
        self.established()
        self.a.close(self.link.now)
        self.b.close(self.link.now)
        self.run_until(lambda: self.a.state is State.LINGER)
        return self

    def in_state(self, state: State) -> Rig:
        now = self.link.now
        if state is State.LISTEN:
            self.a.listen()
        elif state is State.CONNECTING:
            self.a.connect(now)
        elif state is State.ESTABLISHED:
            self.established()
        elif state is State.LINGER:
            self.lingering()
        elif state is State.CLOSED:
            self.a.close(now)
        elif state is State.FAILED:
            self.established().a.abort("test", self.link.now)
        elif state is State.DEAD:
            self.established().a.handle_timer(self.link.now + 1e6)
        assert self.a.state is state
        return self


def _refused(r: Rig) -> None:
    r.b.listen()
    r.run_until(lambda: any(isinstance(e, ConnectionRequested) for e in r.b.events()))
    r.b.refuse("not now", r.link.now)
    r.run_until(lambda: r.a.state is not State.CONNECTING)
    (event,) = [e for e in r.a.events() if isinstance(e, ConnectionAborted)]
    assert (event.reason, event.by_peer, event.refused) == ("not now", True, True)


def _simultaneous_open(r: Rig) -> None:
    r.b.connect(r.link.now)
    r.run_until(lambda: r.a.state is not State.CONNECTING)
    r.run_until(lambda: r.b.state is State.ESTABLISHED)


def _connect_timeout(r: Rig) -> None:
    while r.a.state is State.CONNECTING:
        timer = r.a.get_timer()
        assert timer is not None
        r.a.handle_timer(timer)


def _both_close(r: Rig) -> None:
    r.a.close(r.link.now)
    r.b.close(r.link.now)
    r.run_until(lambda: r.a.state is not State.ESTABLISHED)


def _linger_timer(r: Rig) -> None:
    timer = r.a.get_timer()
    assert timer is not None
    assert timer < 1e6
    r.a.handle_timer(timer)


DRIVE: dict[tuple[State, Trigger], Callable[[Rig], None]] = {
    (State.IDLE, Trigger.LISTEN): lambda r: r.a.listen(),
    (State.IDLE, Trigger.CONNECT): lambda r: r.a.connect(r.link.now),
    (State.IDLE, Trigger.CLOSE): lambda r: r.a.close(r.link.now),
    (State.IDLE, Trigger.RESET): lambda r: r.a.reset(),
    (State.LISTEN, Trigger.INIT_RECEIVED): lambda r: (
        r.b.connect(r.link.now),
        r.run_until(lambda: r.a.state is not State.LISTEN),
    ),
    (State.LISTEN, Trigger.ABORT): lambda r: r.a.abort("test", r.link.now),
    (State.LISTEN, Trigger.CLOSE): lambda r: r.a.close(r.link.now),
    (State.CONNECTING, Trigger.INIT_RECEIVED): _simultaneous_open,
    (State.CONNECTING, Trigger.INIT_ACKED): lambda r: (
        r.b.listen(),
        r.run_until(lambda: r.a.state is not State.CONNECTING),
    ),
    (State.CONNECTING, Trigger.CONNECT_TIMEOUT): _connect_timeout,
    (State.CONNECTING, Trigger.REFUSED): _refused,
    (State.ESTABLISHED, Trigger.BOTH_CLOSED): _both_close,
    (State.ESTABLISHED, Trigger.ABORT): lambda r: r.a.abort("test", r.link.now),
    (State.ESTABLISHED, Trigger.LINK_DEAD): lambda r: r.a.handle_timer(r.link.now + 1e6),
    (State.LINGER, Trigger.LINGER_EXPIRED): _linger_timer,
    (State.LINGER, Trigger.ABORT): lambda r: r.a.abort("test", r.link.now),
    (State.CLOSED, Trigger.RESET): lambda r: r.a.reset(),
    (State.FAILED, Trigger.RESET): lambda r: r.a.reset(),
    (State.DEAD, Trigger.RESET): lambda r: r.a.reset(),
}


def test_every_table_entry_is_driven_below() -> None:
    assert set(DRIVE) == set(TRANSITIONS)


@pytest.mark.parametrize(("state", "trigger"), list(DRIVE), ids=lambda x: x.name)
def test_a_real_endpoint_takes_each_transition_of_the_table(state: State, trigger: Trigger) -> None:
    refusing = EndpointConfig(one_way_delay=DELAY, auto_accept=False)
    rig = Rig(refusing if trigger is Trigger.REFUSED else None).in_state(state)
    taken = len(rig.steps)
    DRIVE[(state, trigger)](rig)
    after = TRANSITIONS[(state, trigger)]
    assert rig.steps[taken:] == [(state, trigger, after)]
    assert rig.a.state is after


def test_a_new_connection_request_ends_the_linger_early() -> None:
    rig = Rig(EndpointConfig(one_way_delay=DELAY, linger=0.01)).lingering()
    rig.run_until(lambda: rig.b.state is State.CLOSED)  # b's short linger is over
    assert rig.a.state is State.LINGER
    rig.b.reset()
    rig.b.connect(rig.link.now)
    rig.run_until(lambda: rig.a.state is not State.LINGER)
    assert rig.steps[-1] == (State.LINGER, Trigger.LINGER_EXPIRED, State.CLOSED)


def test_an_abort_while_connecting_is_a_refusal() -> None:
    rig = Rig().in_state(State.CONNECTING)
    rig.a.abort("changed my mind", 0.0)
    assert rig.steps[-1] == (State.CONNECTING, Trigger.REFUSED, State.FAILED)


def test_silence_while_connecting_fails_the_connect_not_the_link() -> None:
    """The dead-link decision: CONNECTING never becomes DEAD, whatever the silence."""
    rig = Rig().in_state(State.CONNECTING)
    rig.a.handle_timer(1e6)
    assert rig.a.state is State.FAILED
    rig = Rig().in_state(State.LINGER)
    rig.a.handle_timer(1e6)
    assert rig.a.state is State.CLOSED
    rig = Rig().in_state(State.LISTEN)
    assert rig.a.get_timer() is None
    rig.a.handle_timer(1e6)
    assert rig.a.state is State.LISTEN


API: dict[Trigger, Callable[[Endpoint], None]] = {
    Trigger.LISTEN: lambda ep: ep.listen(),
    Trigger.CONNECT: lambda ep: ep.connect(0.0),
    Trigger.RESET: lambda ep: ep.reset(),
}


@pytest.mark.parametrize("state", list(State), ids=lambda s: s.name)
@pytest.mark.parametrize("trigger", list(API), ids=lambda t: t.name)
def test_public_calls_move_as_the_table_says_or_raise_and_stay(
    state: State, trigger: Trigger
) -> None:
    ep = Rig().in_state(state).a
    if allowed(state, trigger):
        API[trigger](ep)
        assert ep.state is TRANSITIONS[(state, trigger)]
    else:
        with pytest.raises(LocalProtocolError):
            API[trigger](ep)
        assert ep.state is state


def _packet(ptype: str, data: bytes = b"", seq: int = 0) -> bytes:
    return build_packet(Packet(seq=seq, type=ptype, data=data), BlockCheck.CRC16)


@pytest.mark.parametrize("state", list(State), ids=lambda s: s.name)
def test_each_state_behaves_as_its_state_sets_say(state: State) -> None:
    def fresh() -> Endpoint:
        return Rig().in_state(state).a

    # WRITABLE: send() queues; otherwise it raises and queues nothing.
    ep = fresh()
    if state in WRITABLE:
        assert ep.send(b"abc", 0.0) == 3
    else:
        with pytest.raises(LocalProtocolError, match="cannot send"):
            ep.send(b"abc", 0.0)
    # TERMINAL: send_eof() raises.
    ep = fresh()
    if state in TERMINAL:
        with pytest.raises(LocalProtocolError, match="cannot send EOF"):
            ep.send_eof(0.0)
    else:
        ep.send_eof(0.0)
    # LIVE: abort() queues an E and fails the connection; elsewhere a no-op.
    ep = fresh()
    pending = ep.control_pending
    ep.abort("bye", 1e3)
    if state in LIVE:
        assert (ep.state, ep.control_pending) == (State.FAILED, pending + 1)
    else:
        assert (ep.state, ep.control_pending) == (state, pending)
    # close(): CLOSED where the table allows CLOSE; a no-op where nothing is
    # writable; else the close begins and the state stays.
    ep = fresh()
    ep.close(1e3)
    closes = allowed(state, Trigger.CLOSE)
    assert ep.state is (TRANSITIONS[(state, Trigger.CLOSE)] if closes else state)
    # PEER_MAY_ABORT: the peer's E ends the connection; elsewhere it is ignored.
    ep = fresh()
    ep.receive_data(_packet(PacketType.ERROR, b"peer says no"), 1e3)
    assert ep.state is (State.FAILED if state in PEER_MAY_ABORT else state)
    # CONNECTED: the peer's data packets are handled (delivered or counted).
    ep = fresh()
    before = ep.statistics()
    # With long sequence numbers two characters before the data carry the
    # high bits of the number (PROTOCOL.md section 9): sequence number 0.
    head = b"  " if before.long_sequence else b""
    ep.receive_data(_packet(PacketType.DATA, head + b"hi"), 1e3)
    after = ep.statistics()
    handled = (after.bytes_readable, after.duplicates_received) != (
        before.bytes_readable,
        before.duplicates_received,
    )
    assert handled == (state in CONNECTED)
    # DEAF: receive_data stops after the packet that found it so.
    ep = fresh()
    received = ep.statistics().packets_received
    ep.receive_data(_packet("Q") + _packet("Q"), 1e3)
    assert ep.statistics().packets_received - received == (1 if state in DEAF else 2)
    assert ep.state is state
    # Timers run in CONNECTING, ESTABLISHED and LINGER only.
    timed = {State.CONNECTING, State.ESTABLISHED, State.LINGER}
    assert (fresh().get_timer() is not None) == (state in timed)
