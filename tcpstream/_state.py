"""The session state machine: every legal transition, in one table (PROTOCOL.md section 7).

Read :data:`TRANSITIONS` to draw the machine.  A transition not in the table
raises :class:`IllegalTransition`: for a local call that is the caller's bug
(it is a :class:`LocalProtocolError`); for a packet from the peer the
connection catches it, counts the packet as rejected and answers it.
"""

from __future__ import annotations

import enum

from ._errors import LocalProtocolError

__all__ = ["TRANSITIONS", "IllegalTransition", "SessionState", "Side", "Trigger", "transition"]


class Side(enum.Enum):
    """Which end of the session a machine belongs to."""

    CLIENT = "client"
    """The controlling agent (it connects)."""
    SERVER = "server"
    """The manipulator (it listens, grants or refuses)."""


class SessionState(enum.Enum):
    """Where a session is."""

    IDLE = "idle"
    """Client: created, HELLO not yet sent."""
    AWAITING_HELLO = "awaiting-hello"
    """Server: stream open, waiting for the HELLO."""
    HELLO_SENT = "hello-sent"
    """Client: waiting for CHALLENGE (keyed arm) or GRANT/REFUSE."""
    CHALLENGED = "challenged"
    """Server: CHALLENGE sent, waiting for AUTH."""
    AUTH_SENT = "auth-sent"
    """Client: AUTH sent, waiting for GRANT/REFUSE."""
    AWAITING_DECISION = "awaiting-decision"
    """Server: the request is verified; the application grants or refuses."""
    OPEN = "open"
    """Granted: commands, replies, telemetry and heartbeats flow."""
    CLOSED = "closed"
    """Over: BYE or REFUSE sent or received, or the connection given up."""


class Trigger(enum.Enum):
    """What moves a machine: a packet in (``*_IN``), a local call, or a fault."""

    CONNECT = "connect"
    HELLO_IN = "hello-in"
    CHALLENGE = "challenge"
    CHALLENGE_IN = "challenge-in"
    AUTH_IN = "auth-in"
    GRANT = "grant"
    GRANT_IN = "grant-in"
    REFUSE = "refuse"
    REFUSE_IN = "refuse-in"
    COMMAND = "command"
    COMMAND_IN = "command-in"
    REPLY = "reply"
    REPLY_IN = "reply-in"
    HEARTBEAT = "heartbeat"
    HEARTBEAT_IN = "heartbeat-in"
    BYE = "bye"
    BYE_IN = "bye-in"
    FAULT = "fault"
    """Garbage limit, silence, handshake timeout, authentication failure, EOF."""


_C, _S = Side.CLIENT, Side.SERVER
_St, _T = SessionState, Trigger

_LIVE = {
    _C: (_St.IDLE, _St.HELLO_SENT, _St.AUTH_SENT, _St.OPEN),
    _S: (_St.AWAITING_HELLO, _St.CHALLENGED, _St.AWAITING_DECISION, _St.OPEN),
}

TRANSITIONS: dict[tuple[Side, SessionState, Trigger], SessionState] = {
    # Client handshake: HELLO, then (keyed) CHALLENGE -> AUTH, then GRANT or REFUSE.
    (_C, _St.IDLE, _T.CONNECT): _St.HELLO_SENT,
    (_C, _St.HELLO_SENT, _T.CHALLENGE_IN): _St.AUTH_SENT,
    (_C, _St.HELLO_SENT, _T.GRANT_IN): _St.OPEN,
    (_C, _St.HELLO_SENT, _T.REFUSE_IN): _St.CLOSED,
    (_C, _St.AUTH_SENT, _T.GRANT_IN): _St.OPEN,
    (_C, _St.AUTH_SENT, _T.REFUSE_IN): _St.CLOSED,
    # Server handshake: HELLO, then (keyed) CHALLENGE and AUTH, then the decision.
    (_S, _St.AWAITING_HELLO, _T.HELLO_IN): _St.AWAITING_DECISION,
    (_S, _St.AWAITING_DECISION, _T.CHALLENGE): _St.CHALLENGED,
    (_S, _St.CHALLENGED, _T.AUTH_IN): _St.AWAITING_DECISION,
    (_S, _St.AWAITING_DECISION, _T.GRANT): _St.OPEN,
    (_S, _St.AWAITING_HELLO, _T.REFUSE): _St.CLOSED,
    (_S, _St.CHALLENGED, _T.REFUSE): _St.CLOSED,
    (_S, _St.AWAITING_DECISION, _T.REFUSE): _St.CLOSED,
    # The open session.
    (_C, _St.OPEN, _T.COMMAND): _St.OPEN,
    (_C, _St.OPEN, _T.REPLY_IN): _St.OPEN,
    (_S, _St.OPEN, _T.COMMAND_IN): _St.OPEN,
    (_S, _St.OPEN, _T.REPLY): _St.OPEN,
    (_C, _St.OPEN, _T.HEARTBEAT): _St.OPEN,
    (_C, _St.OPEN, _T.HEARTBEAT_IN): _St.OPEN,
    (_S, _St.OPEN, _T.HEARTBEAT): _St.OPEN,
    (_S, _St.OPEN, _T.HEARTBEAT_IN): _St.OPEN,
}
# Either side may say goodbye, hear goodbye or give up from any live state.
for _side, _states in _LIVE.items():
    for _state in _states:
        TRANSITIONS[(_side, _state, _T.BYE)] = _St.CLOSED
        TRANSITIONS[(_side, _state, _T.FAULT)] = _St.CLOSED
        if _state is not _St.IDLE:  # nothing can arrive before the HELLO is sent
            TRANSITIONS[(_side, _state, _T.BYE_IN)] = _St.CLOSED
del _side, _states, _state


class IllegalTransition(LocalProtocolError):
    """``trigger`` is not allowed in ``state`` for this side."""

    def __init__(self, side: Side, state: SessionState, trigger: Trigger) -> None:
        super().__init__(f"{side.value}: {trigger.value} is not allowed in state {state.value}")
        self.side = side
        self.state = state
        self.trigger = trigger


def transition(side: Side, state: SessionState, trigger: Trigger) -> SessionState:
    """The next state, or :class:`IllegalTransition`."""
    try:
        return TRANSITIONS[(side, state, trigger)]
    except KeyError:
        raise IllegalTransition(side, state, trigger) from None
