"""The endpoint's connection state machine: every legal transition, in one table.

Rule 1: the state changes only through :func:`transition`, with a trigger from
:class:`Trigger`.  Rule 2: a (state, trigger) pair missing from ``TRANSITIONS``
is a bug in the caller -- :func:`transition` raises LocalProtocolError and the
state does not change.

::

    IDLE --listen--> LISTEN --init received--> ESTABLISHED
    IDLE --connect--> CONNECTING --init acked--> ESTABLISHED
    CONNECTING --connect timeout--> FAILED
    CONNECTING --init received--> ESTABLISHED     (simultaneous open)
    CONNECTING --refused (E)--> FAILED
    IDLE/LISTEN --close--> CLOSED
    ESTABLISHED --both EOFs done--> LINGER --linger expired--> CLOSED
    any live state --abort sent / E received--> FAILED
    any live state --dead link--> DEAD
    CLOSED/FAILED/DEAD --reset--> IDLE

Half-close is not a state: ESTABLISHED carries two flags (our EOF sent, the
peer's EOF received).  Data may still flow in the open direction.
"""

from __future__ import annotations

import enum

from ._errors import LocalProtocolError

__all__ = ["TERMINAL", "TRANSITIONS", "State", "Trigger", "transition"]


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
    """The peer fell silent for longer than ``dead_after``."""


class Trigger(enum.Enum):
    """What can move the state machine."""

    LISTEN = "listen() called"
    CONNECT = "connect() called"
    INIT_RECEIVED = "peer's init accepted"
    INIT_ACKED = "peer accepted our init"
    CONNECT_TIMEOUT = "connect deadline passed"
    REFUSED = "peer refused or we refused"
    BOTH_CLOSED = "both EOFs sent, delivered and acknowledged"
    LINGER_EXPIRED = "linger time over"
    ABORT = "abort sent or received"
    LINK_DEAD = "silence longer than dead_after"
    CLOSE = "close() before any connection"
    RESET = "reset() called"


TERMINAL = frozenset({State.CLOSED, State.FAILED, State.DEAD})
"""States a connection ends in; only reset() leaves them."""

_LIVE = (State.LISTEN, State.CONNECTING, State.ESTABLISHED, State.LINGER)

TRANSITIONS: dict[tuple[State, Trigger], State] = {
    (State.IDLE, Trigger.LISTEN): State.LISTEN,
    (State.IDLE, Trigger.CONNECT): State.CONNECTING,
    (State.LISTEN, Trigger.INIT_RECEIVED): State.ESTABLISHED,
    (State.IDLE, Trigger.CLOSE): State.CLOSED,
    (State.LISTEN, Trigger.CLOSE): State.CLOSED,
    (State.CONNECTING, Trigger.INIT_RECEIVED): State.ESTABLISHED,
    (State.CONNECTING, Trigger.INIT_ACKED): State.ESTABLISHED,
    (State.CONNECTING, Trigger.CONNECT_TIMEOUT): State.FAILED,
    (State.CONNECTING, Trigger.REFUSED): State.FAILED,
    (State.ESTABLISHED, Trigger.BOTH_CLOSED): State.LINGER,
    (State.LINGER, Trigger.LINGER_EXPIRED): State.CLOSED,
    **{(s, Trigger.ABORT): State.FAILED for s in _LIVE},
    **{(s, Trigger.LINK_DEAD): State.DEAD for s in (State.CONNECTING, State.ESTABLISHED)},
    **{(s, Trigger.RESET): State.IDLE for s in (State.IDLE, *TERMINAL)},
}


def transition(state: State, trigger: Trigger) -> State:
    """The next state, or LocalProtocolError for an illegal pair."""
    try:
        return TRANSITIONS[(state, trigger)]
    except KeyError:
        raise LocalProtocolError(f"cannot {trigger.value!r} in state {state.value!r}") from None
