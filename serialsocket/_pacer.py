"""Output pacing: the endpoint's model of its own UART queue (sans-I/O).

When the line rate is known, the endpoint tracks when the bytes it has handed
to the line will have finished leaving the UART (``free_at``) and releases
data packets only while less than :meth:`Pacer.horizon` seconds of bytes are
queued there.  Everything else waits inside the endpoint, where ACKs and NAKs
can overtake it.  Without pacing, a 2400 bit/s line with a few KB in the tty
buffer holds every ACK for seconds and timers fire spuriously (issue 3).

Nothing here reads a clock: every method that depends on time takes ``now``.
With the line rate unknown (``paced=False``) the line always has room and
nothing is held back.
"""

from __future__ import annotations

import math
from collections.abc import Callable

__all__ = ["HORIZON_CAP", "TIME_EPSILON", "Pacer"]

HORIZON_CAP = 0.1
"""The most line time, in seconds, data may queue in the UART (see
:meth:`Pacer.horizon`): with it an ACK or an expedited message waits behind
at most the packet on the wire plus 0.1 s, where two 128-character packets
at 2400 bit/s held it for up to 1.6 s."""

TIME_EPSILON = 1e-9
"""Tolerance for comparing computed instants (far below any line's byte time)."""


class Pacer:
    """When the line will be free, and whether data may join its queue now.

    Args:
        transmit_time: seconds the UART needs for a number of wire bytes
            (:meth:`EndpointConfig.transmit_time`).
        paced: the line rate is known; without it nothing is held back.
        full_packet: wire bytes of a full data packet (the horizon is two of
            them); updated once the packet length is negotiated.
    """

    def __init__(
        self, transmit_time: Callable[[int], float], *, paced: bool, full_packet: int
    ) -> None:
        self._transmit_time = transmit_time
        self.paced = paced
        self.full_packet = full_packet
        self.tight = False
        """Keep the queue to :data:`HORIZON_CAP` (see :meth:`horizon`); the
        endpoint sets it while the rate in use is a confirmed one."""
        self.probe = False
        """Release at least two packets at once (:meth:`batch`), even into a
        :attr:`tight` horizon: the endpoint wants a rate pair, two packets
        that leave the line back to back (a packet handed into an idle line
        cannot show that the line is faster than the rate in use)."""
        self.free_at: float | None = None
        """When the last byte handed to the line finishes leaving the UART
        (None before the first packet of a connection)."""

    def reset(self) -> None:
        """A new connection: the line is idle."""
        self.free_at = None

    def send(self, wire_bytes: int, now: float) -> float:
        """Count ``wire_bytes`` handed to the line at ``now``; returns when they
        finish leaving the UART (after whatever was queued before them)."""
        start = now if self.free_at is None else max(now, self.free_at)
        self.free_at = start + self._transmit_time(wire_bytes)
        return self.free_at

    def catch_up(self, free_at: float) -> bool:
        """The line is measured to be busy until ``free_at`` (a queue the model
        did not know about): hold data back until then.  Never earlier than
        the model already says.  Returns whether the model moved."""
        if self.free_at is None or free_at > self.free_at:
            self.free_at = free_at
            return True
        return False

    def pull_back(self, seconds: float, now: float) -> None:
        """The model drains later than the line really does: move the end of
        its queue ``seconds`` earlier (not before ``now``)."""
        if self.free_at is not None and self.free_at > now:
            self.free_at = max(self.free_at - seconds, now)

    def horizon(self) -> float:
        """Seconds of bytes allowed queued in the UART before data waits here.

        Two full packets; with :attr:`tight`, never more than
        :data:`HORIZON_CAP`: on a slow line two packets are over a second,
        and everything the endpoint sends ahead of data -- ACKs, NAKs,
        expedited messages -- waits behind that much.  A tenth of a second
        still covers any scheduling delay in handing the next packet over.
        Only with a rate the line has confirmed: while the rate is being
        measured, the second packet's queue is what lets the ACK clock see
        the line's capacity (without it a low estimate paced the line below
        its rate and never learned better: a third of the speed without
        hints at 2400 bit/s and 1.3 s).
        """
        two = 2 * self._transmit_time(self.full_packet)
        return min(two, HORIZON_CAP) if self.tight else two

    def has_room(self, now: float) -> bool:
        """Data may be handed to the line at ``now``."""
        if not self.paced or self.free_at is None:
            return True
        # The same expression as wake(), so waking at that time always finds
        # room (a float-rounding mismatch here would spin forever).
        return now >= self.free_at - self.horizon() - TIME_EPSILON

    def idle_within(self, now: float, lead: float) -> bool:
        """The UART's queue drains within ``lead`` seconds of ``now`` (always
        True unpaced): when a latest value may go, so it waits behind next
        to nothing and leaves as fresh as it can."""
        if not self.paced or self.free_at is None:
            return True
        return now >= self.free_at - min(lead, self.horizon()) - TIME_EPSILON

    def idle_wake(self, lead: float) -> float | None:
        """When :meth:`idle_within` will next hold, or None if it always does."""
        if not self.paced or self.free_at is None:
            return None
        return self.free_at - min(lead, self.horizon())

    def wake(self) -> float | None:
        """When the line will next have room, or None if it is never held back."""
        if not self.paced or self.free_at is None:
            return None
        return self.free_at - self.horizon()

    def batch(self, room: int, now: float) -> int:
        """How many of ``room`` full packets to release at once (at least one):
        as many as fill the horizon's spare time, and two for a :attr:`probe`."""
        if not self.paced or self.free_at is None:
            return room
        spare = self.horizon() - max(self.free_at - now, 0.0)
        fill = math.ceil(spare / max(self._transmit_time(self.full_packet), 1e-9))
        return max(1, min(room, max(fill, 2 if self.probe else 1)))

    def backlog(self, now: float) -> float:
        """Seconds of bytes still queued in the UART at ``now``."""
        return 0.0 if self.free_at is None else max(self.free_at - now, 0.0)
