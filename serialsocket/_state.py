"""The endpoint's connection state machine: what each trigger does in each state.

Rule 1: the state changes only through :func:`transition`, with a trigger from
:class:`Trigger`.  Rule 2: a (state, trigger) pair missing from ``TRANSITIONS``
is a bug in the caller -- :func:`transition` raises LocalProtocolError and the
state does not change.  Rule 3: where a behaviour spans several states, the
endpoint asks this module -- the named state sets below (:data:`LIVE`,
:data:`WRITABLE`, ...), or :func:`allowed` right before the transition it
guards -- rather than listing states itself; a check for one state (mostly
ESTABLISHED, the only state in which data packets go out) names that state.

``TRANSITIONS`` is the diagram: PROTOCOL.md section 7 prints it, as
:func:`serialsocket._diagram.render` renders it (a test keeps the two equal).

Half-close is not a state: ESTABLISHED carries two flags (our EOF sent, the
peer's EOF received).  Data may still flow in the open direction.  Closing
is not a state either: close() in ESTABLISHED sets a deadline, and the
connection stays ESTABLISHED until both EOFs are done (LINGER).
"""

from __future__ import annotations

import enum

from ._errors import LocalProtocolError

__all__ = [
    "CONNECTED",
    "DEAF",
    "LIVE",
    "PEER_MAY_ABORT",
    "STATE_SETS",
    "TERMINAL",
    "TRANSITIONS",
    "WRITABLE",
    "State",
    "Trigger",
    "allowed",
    "transition",
]


class State(enum.Enum):
    """Where an endpoint is in the life of a connection."""

    IDLE = "idle"
    """New or reset: neither listening nor connecting."""
    LISTEN = "listen"
    """Waiting for a peer's init packet (the manipulator side)."""
    CONNECTING = "connecting"
    """Init sent, waiting for the peer's answer; the init is retransmitted."""
    ESTABLISHED = "established"
    """Connected; data may flow in each direction until that direction's EOF."""
    LINGER = "linger"
    """Both directions closed and acknowledged; still re-acknowledging the
    peer's EOF in case our last ACK was lost (TCP's TIME-WAIT)."""
    CLOSED = "closed"
    """Closed gracefully; reset() to listen or connect again."""
    FAILED = "failed"
    """Refused, aborted (by either side) or timed out while connecting."""
    DEAD = "dead"
    """The peer fell silent for longer than ``dead_after`` while ESTABLISHED."""


class Trigger(enum.Enum):
    """What can move the state machine (the value is what the debug log says)."""

    LISTEN = "listen() called"
    CONNECT = "connect() called"
    INIT_RECEIVED = "peer's init accepted"
    """In LISTEN, or in CONNECTING when both sides connect at once."""
    INIT_ACKED = "peer accepted our init"
    CONNECT_TIMEOUT = "connect deadline passed"
    REFUSED = "peer refused or we refused"
    """An E packet, sent or received, while CONNECTING."""
    BOTH_CLOSED = "both EOFs sent, delivered and acknowledged"
    LINGER_EXPIRED = "linger time over"
    """Or the peer's init arrived: it has moved on to a new connection."""
    ABORT = "abort sent or received"
    """An E packet, sent or received, once listening or connected."""
    LINK_DEAD = "silence longer than dead_after"
    CLOSE = "close() before any connection"
    RESET = "reset() called"


TERMINAL = frozenset({State.CLOSED, State.FAILED, State.DEAD})
"""States a connection ends in; only reset() leaves them.  send_eof() raises."""

LIVE = frozenset({State.LISTEN, State.CONNECTING, State.ESTABLISHED, State.LINGER})
"""A connection is under way or awaited: abort() ends it with an E packet."""

WRITABLE = frozenset({State.IDLE, State.LISTEN, State.CONNECTING, State.ESTABLISHED})
"""The application's direction is not over: send() queues data (sent once
ESTABLISHED) and close() has something to close."""

CONNECTED = frozenset({State.ESTABLISHED, State.LINGER})
"""Parameters are agreed: the peer's data, EOF and ACK packets are handled,
and an abort is not a refusal."""

PEER_MAY_ABORT = frozenset({State.CONNECTING, State.ESTABLISHED, State.LINGER})
"""The peer's E packet ends the connection.  In LISTEN there is none yet to
end: a stray E (say, a refusal meant for an earlier caller) is ignored."""

DEAF = frozenset({State.CLOSED, State.DEAD})
"""receive_data() stops reading packets: nothing more will be answered.
FAILED still reads, to repeat its E to a peer that keeps talking."""

STATE_SETS: dict[str, tuple[frozenset[State], str]] = {
    "live": (LIVE, "abort() sends an E and ends the connection"),
    "writable": (WRITABLE, "send() queues data; close() has something to close"),
    "connected": (CONNECTED, "the peer's D, Z and ACK packets are handled"),
    "peer may abort": (PEER_MAY_ABORT, "the peer's E ends the connection"),
    "terminal": (TERMINAL, "only reset() leaves; send_eof() raises"),
    "deaf": (DEAF, "receive_data() stops reading packets"),
}
"""The named state sets with what each means, for the diagram (PROTOCOL.md section 7)."""


TRANSITIONS: dict[tuple[State, Trigger], State] = {
    (State.IDLE, Trigger.LISTEN): State.LISTEN,
    (State.IDLE, Trigger.CONNECT): State.CONNECTING,
    (State.IDLE, Trigger.CLOSE): State.CLOSED,
    (State.IDLE, Trigger.RESET): State.IDLE,
    (State.LISTEN, Trigger.INIT_RECEIVED): State.ESTABLISHED,
    (State.LISTEN, Trigger.ABORT): State.FAILED,
    (State.LISTEN, Trigger.CLOSE): State.CLOSED,
    (State.CONNECTING, Trigger.INIT_RECEIVED): State.ESTABLISHED,  # simultaneous open
    (State.CONNECTING, Trigger.INIT_ACKED): State.ESTABLISHED,
    (State.CONNECTING, Trigger.CONNECT_TIMEOUT): State.FAILED,
    # While connecting, every abort (sent or received) is a refusal, not ABORT.
    (State.CONNECTING, Trigger.REFUSED): State.FAILED,
    (State.ESTABLISHED, Trigger.BOTH_CLOSED): State.LINGER,
    (State.ESTABLISHED, Trigger.ABORT): State.FAILED,
    # Silence is judged only while established: CONNECTING has its connect
    # deadline, LISTEN waits for ever, LINGER ends on its own timer.
    (State.ESTABLISHED, Trigger.LINK_DEAD): State.DEAD,
    (State.LINGER, Trigger.LINGER_EXPIRED): State.CLOSED,
    (State.LINGER, Trigger.ABORT): State.FAILED,
    (State.CLOSED, Trigger.RESET): State.IDLE,
    (State.FAILED, Trigger.RESET): State.IDLE,
    (State.DEAD, Trigger.RESET): State.IDLE,
}


def allowed(state: State, trigger: Trigger) -> bool:
    """``trigger`` is legal in ``state`` (the endpoint's guards ask this)."""
    return (state, trigger) in TRANSITIONS


def transition(state: State, trigger: Trigger) -> State:
    """The next state, or LocalProtocolError for an illegal pair."""
    try:
        return TRANSITIONS[(state, trigger)]
    except KeyError:
        raise LocalProtocolError(f"cannot {trigger.value!r} in state {state.value!r}") from None
