"""Typed errors, named for who is to blame (the h11 convention).

* :class:`LocalProtocolError` -- *this* program misused the API (a bad
  argument, an operation in the wrong state).  Fix the calling code.
* :class:`RemoteProtocolError` -- the *peer* sent something the protocol does
  not allow (a packet whose check is valid but whose contents are nonsense).
  It carries ``error_hint``: the text to put in the Kermit ``E`` packet that
  tells the peer why we are giving up.

Damaged packets (bad check, bad length, garbage between packets) are *not*
errors: line noise is expected, so the parser reports them as counted
rejection events and the ARQ layer recovers by NAK and retransmission.
"""

from __future__ import annotations

__all__ = ["LocalProtocolError", "MalformedDataError", "ProtocolError", "RemoteProtocolError"]


class ProtocolError(Exception):
    """Base of every protocol error raised by serialsocket; never raised itself."""

    def __init__(self, message: str, *, error_hint: str | None = None) -> None:
        if type(self) is ProtocolError:
            raise TypeError("ProtocolError is abstract; raise a subclass")
        super().__init__(message)
        self.error_hint = error_hint if error_hint is not None else message


class LocalProtocolError(ProtocolError):
    """The local program asked for something the protocol cannot do."""


class RemoteProtocolError(ProtocolError):
    """The peer broke the protocol; ``error_hint`` is the E-packet text to send back."""


class MalformedDataError(RemoteProtocolError):
    """A data field passed its block check but is not a valid prefix encoding.

    Typical causes: a dangling prefix at the end of the field, or a repeat
    count outside 1..94.  Because the check was good, this is a peer bug, not
    line noise.
    """
