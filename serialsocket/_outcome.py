"""How a serial-socket connection ends, in terms both I/O adapters share (sans-I/O).

The trio glue (:mod:`serialsocket._driver`, :mod:`serialsocket._socket`) and
the asyncio glue (:mod:`serialsocket.asyncio`) run the same
:class:`~serialsocket.Endpoint` and tell the application the same things:

* the causes of a broken link (:class:`LinkBroken` and its kinds), chained to
  ``trio.BrokenResourceError`` in trio and to ``ConnectionError`` in asyncio;
* :class:`LinkOutcome`, which reads the endpoint's events that end a
  connection and remembers who ended it;
* :func:`ending`, the one-line report of a connection that did not close
  cleanly, with the byte counts (:func:`counts`);
* :class:`SocketStatistics`, the record ``statistics()`` returns.

Nothing here imports trio or asyncio, reads a clock or touches a port.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from ._endpoint import Endpoint, EndpointStatistics
from ._events import ConnectionAborted, LinkDead
from ._pyserial import PortStatistics
from ._state import State

__all__ = [
    "LineFailed",
    "LinkBroken",
    "LinkDeadError",
    "LinkOutcome",
    "PeerAborted",
    "SocketStatistics",
    "counts",
    "ending",
]

log = logging.getLogger(__name__)


class LinkBroken(Exception):
    """Base of the causes chained to ``trio.BrokenResourceError`` (or ``ConnectionError``)."""


class PeerAborted(LinkBroken):
    """The peer ended the connection with an E packet.

    Attributes:
        reason: the peer's text.
    """

    def __init__(self, reason: str) -> None:
        super().__init__(f"the peer aborted the connection: {reason}")
        self.reason = reason


class LinkDeadError(LinkBroken):
    """The peer fell silent for longer than ``dead_after``.

    Attributes:
        report: the endpoint's LinkDead event (bytes acknowledged, in flight,
            never sent).
    """

    def __init__(self, report: LinkDead) -> None:
        super().__init__(
            f"link dead after {report.silence:.1f} s of silence: "
            f"{report.bytes_acknowledged} bytes acknowledged, "
            f"{report.bytes_in_flight} in flight (may or may not have arrived), "
            f"{report.bytes_unsent} never sent"
        )
        self.report = report


class LineFailed(LinkBroken):
    """The port failed or reached EOF (the device went away, the relay stopped)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class SocketStatistics:
    """The ARQ record plus what the port saw.

    Attributes:
        link: the endpoint's statistics.
        port_reads: read calls that returned data.
        port_writes: write calls.
        port_bytes_in: bytes read from the port.
        port_bytes_out: bytes written to the port.
        port: the port's own record (its name and OS errors) when the port
            keeps one (a :class:`~serialsocket.SerialPort`), else None.
    """

    link: EndpointStatistics
    port_reads: int
    port_writes: int
    port_bytes_in: int
    port_bytes_out: int
    port: PortStatistics | None = None


class LinkOutcome:
    """Who ended the current connection, read from the endpoint's events.

    An adapter calls :meth:`take_events` after every ``receive_data`` and
    ``handle_timer``; ``broken`` is then the cause to raise (the peer's
    abort, a dead link, or a failed line recorded with :meth:`fail`), and
    ``ended_by_us`` the reason of our own E packet, if we sent one.
    """

    def __init__(self) -> None:
        self.broken: LinkBroken | None = None
        self.ended_by_us: str | None = None

    def take_events(self, ep: Endpoint) -> None:
        """Drain ``ep.events()``, recording the first cause that ended the connection."""
        for event in ep.events():
            if isinstance(event, ConnectionAborted) and not event.by_peer:
                self.ended_by_us = self.ended_by_us or event.reason
            elif isinstance(event, ConnectionAborted) and self.broken is None:
                self.broken = PeerAborted(event.reason)
            elif isinstance(event, LinkDead) and self.broken is None:
                self.broken = LinkDeadError(event)
            log.debug("endpoint event: %s", event)

    def fail(self, cause: LinkBroken) -> None:
        """The line itself failed (the first cause recorded wins)."""
        if self.broken is None:
            self.broken = cause

    def clear(self) -> None:
        """A new connection on the same endpoint (a listener's reset)."""
        self.broken = None
        self.ended_by_us = None

    def describe(self, ep: Endpoint, *, stopped: bool) -> str:
        """What ended the connection, for :func:`ending`."""
        if self.broken is not None:
            return str(self.broken)
        if self.ended_by_us is not None:
            return f"this side aborted the connection: {self.ended_by_us}"
        if stopped:
            return "the serial socket stopped before the close finished"
        return f"the connection ended ({ep.state.value})"


def ending(ep: Endpoint, what: str) -> str | None:
    """None if the connection on ``ep`` ended delivered, else ``what`` happened, with the counts.

    Delivered: every byte we were given is acknowledged and the peer's EOF
    arrived (the closing handshake done, or only its last ACK missing: that
    is no data lost).  Anything else -- a close given up, an abort either
    way, a dead link, a failed line -- is reported, whichever side noticed.
    """
    if ep.state in (State.CLOSED, State.LINGER) or ep.data_settled:
        return None
    return f"the connection did not close cleanly: {what}; {counts(ep.statistics())}"


def counts(st: EndpointStatistics) -> str:
    """What was delivered each way, in a user's words (for failure reports)."""
    peer_eof = "its EOF received" if st.eof_received else "its EOF not received"
    return (
        f"sent: {st.bytes_acknowledged} bytes acknowledged, {st.bytes_in_flight} in flight "
        f"(may or may not have arrived), {st.bytes_queued} never sent; "
        f"received: {st.bytes_delivered} bytes from the peer, {peer_eof}"
    )
