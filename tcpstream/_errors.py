"""Typed errors, named for who is to blame (h11's convention).

* :class:`LocalProtocolError`: this program misused the API (an operation in
  the wrong session state, an argument out of range).  Fix the calling code.
* :class:`RemoteProtocolError`: the peer broke the protocol badly enough that
  the session cannot go on (for example it sent only garbage).
* :class:`SessionError` and its subclasses: what a client sees when it cannot
  command the arm -- refused, not authenticated, or the session ended.

A single malformed packet is *not* an exception: it is counted, answered with
a ``FAILED`` reply and the session goes on.  A failed *command* raises
:class:`~tcpstream.CommandFailed` (defined with the command set).
"""

from __future__ import annotations

from ._events import CloseReason, RefuseReason

__all__ = [
    "AuthenticationFailed",
    "LocalProtocolError",
    "OutcomeUnknown",
    "Refused",
    "RemoteProtocolError",
    "SessionClosed",
    "SessionError",
]


class LocalProtocolError(Exception):
    """The local program asked for something the session cannot do in its state."""


class RemoteProtocolError(Exception):
    """The peer broke the protocol; the session is over."""


class SessionError(Exception):
    """Base of the errors a client sees when the session cannot carry a command."""


class Refused(SessionError):
    """The arm refused the connection request; ``reason`` says why, ``message`` what to do."""

    def __init__(self, reason: RefuseReason, message: str) -> None:
        super().__init__(f"refused ({reason.name}): {message}")
        self.reason = reason
        self.message = message


class AuthenticationFailed(SessionError):
    """The key did not match (either side), or one side had a key and the other none.

    The arm words every key failure identically, so this never says how close a
    wrong key was.  Check that both ends were given the same pre-shared key.
    """


class SessionClosed(SessionError):
    """The session ended before the command's outcome was known.

    ``reason`` is the close reason when the peer sent one.  A command that was
    sent but not confirmed may or may not have run: reconnect with the same
    client (``Client.resume``) and it is re-sent under the same request id, so
    the arm answers it from memory instead of running it twice.
    """

    def __init__(self, message: str, reason: CloseReason | None = None) -> None:
        super().__init__(message)
        self.reason = reason


class OutcomeUnknown(SessionClosed):
    """The command was sent, but whether it ran can no longer be known.

    Raised for every command sent without a seen outcome when the session
    resumes at an arm that restarted or no longer remembers this controller
    (memory pressure: PROTOCOL.md 9), and for a command whose reply could not
    be decoded.  The client does *not* re-send such a command: it may have run
    already, and running it twice is worse than asking.  Check the arm's state
    (``status()``, telemetry) before deciding what to command next.
    """
