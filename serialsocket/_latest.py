"""The latest-value lane (PROTOCOL.md section 12): the newest of a series of
values, each superseding the one before, with no value ever holding up a
newer one.

Sans-I/O bookkeeping only: the sending half holds the value waiting for the
line and the last one sent; the receiving half the newest value not yet
read.  The endpoint builds and parses the packets (``L`` carries a value,
``M`` acknowledges one) and decides when a value may go on the line.

Why a lane of its own: a stream (and the expedited lane) delivers every
message in order, so when the packet carrying one hand-controller sample is
lost, every sample behind it waits at the receiver for its repair, a round
trip -- though the arm wants only the newest.  Here a lost value is never
resent once a newer one exists: the newer one replaces it on the line, and
the receiver takes whatever arrives, skipping nothing it could still use.
Only the newest value is carried to the peer reliably (resent until
acknowledged), so when the sender stops offering, the peer ends up holding
exactly the last value offered.

Numbers: each value sent gets the next number of a 12-bit space (the
packet's sequence character carries the low 6 bits, the first data
character the high 6).  A serial line never reorders, so whatever arrives
after a value is newer than it: the receiver needs only to tell a copy of
the value it delivered last (the same number) from a new one (any other).
That holds while the numbers the receiver may hold last -- from the newest
acknowledged through the newest sent -- never wrap: the sender keeps that
span under :data:`LATEST_SPAN`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "LATEST",
    "LATEST_ACK",
    "LATEST_LEAD",
    "LATEST_MAX_BYTES",
    "LATEST_MODULUS",
    "LATEST_SPAN",
    "LatestReceiver",
    "LatestSender",
]

LATEST = "L"
"""Packet type of a latest value (never negotiated with a classic peer)."""
LATEST_ACK = "M"
"""Packet type of a latest value's acknowledgement."""

LATEST_MODULUS = 4096
"""Value numbers on the wire: two ``tochar`` characters of 6 bits."""

LATEST_SPAN = LATEST_MODULUS - 1
"""Numbers the sender may have sent beyond the newest one acknowledged: below
the modulus, so the receiver's last number is never spelled like a new one."""

LATEST_LEAD = 0.02
"""Seconds of bytes the UART may still hold when a latest value is handed to
it: enough to cover the scheduling of the hand-over, so the line does not
idle, and little enough that the value waits behind next to nothing (the
stream's data may queue up to the pacer's horizon, 0.1 s or two packets)."""

LATEST_MAX_BYTES = 1024
"""The longest value the lane takes; it must also fit one packet at the
negotiated length once encoded."""


@dataclass(slots=True)
class LatestSender:
    """The sending half: the waiting value, the last one sent, its timer.

    Attributes:
        pending: the value waiting for the line (replaced by a newer offer).
        number: the last number sent (0: none yet).
        wire: the packet that carried it (a resend is a copy).
        acked: the newest number the peer acknowledged (0: none).
        transmissions: copies of ``number`` handed to the line.
        deadline: when that copy is given up as lost (inf: not armed).
        resend_due: the timer ran out with nothing newer to send.
        done_at: when that copy finishes leaving the UART.
    """

    pending: bytes | None = None
    number: int = 0
    wire: bytes = b""
    acked: int = 0
    transmissions: int = 0
    deadline: float = math.inf
    resend_due: bool = False
    done_at: float = -math.inf
    offered: int = 0
    coalesced: int = 0
    sent_values: int = 0
    resent: int = 0

    def offer(self, value: bytes) -> None:
        """The newest value: it replaces one still waiting for the line."""
        if self.pending is not None:
            self.coalesced += 1
        self.pending = value
        self.offered += 1

    @property
    def may_send_new(self) -> bool:
        """A waiting value may take a new number now (the span allows it)."""
        return self.pending is not None and self.number + 1 - self.acked <= LATEST_SPAN

    @property
    def unacknowledged(self) -> bool:
        """The last value sent has not been acknowledged."""
        return self.number > self.acked

    @property
    def idle(self) -> bool:
        """Nothing waits and the newest value sent was acknowledged."""
        return self.pending is None and not self.unacknowledged

    def take_new(self) -> tuple[int, bytes]:
        """Number the waiting value and take it for the line (``may_send_new``)."""
        assert self.pending is not None
        value, self.pending = self.pending, None
        self.number += 1
        self.transmissions = 0
        self.resend_due = False
        self.sent_values += 1
        return self.number, value

    def sent(self, wire: bytes, done_at: float, timeout: float, ceiling: float) -> None:
        """A copy of the current value was handed to the line; it leaves the
        UART at ``done_at``.  Each copy waits twice as long as the one before
        (up to ``ceiling``), as the expedited lane's do."""
        if self.transmissions:
            self.resent += 1
        self.wire = wire
        self.transmissions += 1
        self.resend_due = False
        self.done_at = done_at
        self.deadline = done_at + min(timeout * 2 ** (self.transmissions - 1), ceiling)

    def requeue_unsent(self, now: float) -> bool:
        """The unacknowledged value's copy was still to leave the UART at
        ``now`` (the port dropped it): resend it at once.  Returns whether."""
        if self.unacknowledged and self.deadline < math.inf and self.done_at > now:
            self.deadline = math.inf
            self.resend_due = True
            return True
        return False

    def expired(self, now: float) -> bool:
        """Whether the last value's copy timed out (the resend is then due
        unless a newer value goes instead)."""
        if self.unacknowledged and self.deadline <= now:
            self.deadline = math.inf
            self.resend_due = True
            return True
        return False

    def next_deadline(self) -> float | None:
        return self.deadline if self.unacknowledged and self.deadline < math.inf else None

    def on_ack(self, number_mod: int) -> bool:
        """An ``M`` for ``number_mod``; True if it acknowledged the last value sent."""
        if not 0 <= number_mod < LATEST_MODULUS or self.number == 0:
            return False
        absolute = self.number - (self.number - number_mod) % LATEST_MODULUS
        if absolute <= self.acked:
            return False  # older than what we know: superseded already
        self.acked = absolute
        if absolute == self.number:
            self.deadline = math.inf
            self.resend_due = False
            return True
        return False


@dataclass(slots=True)
class LatestReceiver:
    """The receiving half: the last number delivered and the newest unread value."""

    last: int | None = None
    value: bytes | None = None
    received: int = 0
    duplicates: int = 0
    superseded: int = 0

    def on_value(self, number_mod: int, value: bytes | None) -> bool:
        """Take the value numbered ``number_mod`` (``value`` None: decode it only
        if this returns True).  True when it is new: the caller then stores
        it with :meth:`deliver`.  Every value, new or a copy, is acknowledged."""
        if number_mod == self.last:
            self.duplicates += 1
            return False
        self.last = number_mod
        if value is not None:
            self.deliver(value)
        return True

    def deliver(self, value: bytes) -> None:
        if self.value is not None:
            self.superseded += 1
        self.value = value
        self.received += 1

    def read(self) -> bytes | None:
        value, self.value = self.value, None
        return value
