"""Round-trip estimation and the retransmission timeout (RFC 6298 with a floor).

Samples come only from packets sent once (Karn's rule), measured from the
moment the packet finished leaving the UART, so the line's own queue does not
inflate them.  The timeout never drops below the physical round trip plus a
margin: on a long-delay link the measured variance can become tiny, and an
adaptive timer that shrinks to the mean fires on every slightly late ACK
(reference/kermit.md section 5, high-latency notes).
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["RttEstimator"]

_ALPHA = 1 / 8
_BETA = 1 / 4
_K = 4


@dataclass(slots=True)
class RttEstimator:
    """Smoothed RTT, its variation, and the current timeout with backoff.

    Attributes:
        floor: the least timeout ever used (physical round trip + margin).
        ceiling: the most backoff may reach (the floor still wins over it).
        initial: the timeout before any sample.
    """

    floor: float
    ceiling: float
    initial: float
    srtt: float | None = None
    rttvar: float = 0.0
    backoff: int = 0
    samples: int = field(default=0)

    def seed(self, upper_bound: float) -> None:
        """Start the estimate from a round trip known only to be at most this.

        For a side with no unambiguous sample yet (a listener, which sent no
        init of its own): the time from its init answer to the connector's
        first packet after it.  Too large rather than too small: a timeout
        that is too long repairs a loss late; one that is too short resends
        every packet.  Real samples then pull the estimate down (RFC 6298's
        smoothing).  Does nothing once there is an estimate."""
        if self.srtt is None:
            self.srtt = max(upper_bound, 0.0)
            self.rttvar = self.srtt / 2
            self.backoff = 0

    def sample(self, rtt: float) -> None:
        """Feed one round-trip measurement (never from a retransmitted packet)."""
        rtt = max(rtt, 0.0)
        if self.srtt is None:
            self.srtt = rtt
            self.rttvar = rtt / 2
        else:
            self.rttvar = (1 - _BETA) * self.rttvar + _BETA * abs(self.srtt - rtt)
            self.srtt = (1 - _ALPHA) * self.srtt + _ALPHA * rtt
        self.samples += 1
        self.backoff = 0

    def on_progress(self) -> None:
        """New data was acknowledged: the line works again, so drop the backoff.

        Karn's rule keeps a retransmitted packet's ACK from giving a *sample*,
        but not from proving that the path delivers: on a noisy serial line a
        timeout means a damaged packet, not congestion, and a backoff carried
        over to the next packet only delays its repair (and, stacked, outgrows
        ``dead_after``).  The estimate itself is untouched.

        Before the first sample there is no estimate to fall back to: the
        timeout is a guess (no hints: 50 ms), and dropping the backoff would
        send every packet again before its ACK could arrive, forever.  So the
        backoff stays until a packet sent once is acknowledged -- Karn's
        algorithm as he gave it -- and then the estimate takes over.
        """
        if self.srtt is not None:
            self.backoff = 0

    def on_timeout(self) -> None:
        """Double the timeout (up to the ceiling) after a retransmission timeout."""
        if self.timeout() < self.ceiling:
            self.backoff += 1

    def base_timeout(self) -> float:
        """The timeout without backoff."""
        if self.srtt is None:
            return max(self.initial, self.floor)
        return max(self.srtt + _K * self.rttvar, self.floor)

    def timeout(self) -> float:
        """The current retransmission timeout, backoff included."""
        backed_off: float = self.base_timeout() * 2.0**self.backoff
        return min(backed_off, max(self.ceiling, self.floor))
