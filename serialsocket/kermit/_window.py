"""Kermit sliding windows for file transfer: the sender's slots and the receiver's buffer.

Why not the ARQ's :mod:`serialsocket._sender` / :mod:`serialsocket._receiver`:
those serve telelink's full-duplex connection protocol, where both sides send
data, ACKs are cumulative plus selective and carry window updates, and
sequence numbers are extended beyond 64.  Kermit file transfer is half duplex
by role: only the sender sends data, the receiver ACKs *each* packet by its
6-bit sequence number (ACKs may arrive out of order), and NAK(n) asks for
exactly packet n (reference/kermit.md section 5, C-Kermit's ``ckcfn2.c``
input()).  These two small classes hold exactly that bookkeeping.
"""

from __future__ import annotations

from dataclasses import dataclass

from serialsocket._packet import Packet
from serialsocket._wire import SEQ_MODULUS

__all__ = ["ReceiveWindow", "SendSlot", "SendWindow"]


@dataclass(slots=True)
class SendSlot:
    """One sent, not yet acknowledged packet.

    Attributes:
        seq: its sequence number.
        wire: its exact bytes on the line (resent as they are).
        first_sent, last_sent: positions of its first and latest copy in
            the sender's sequence of transmissions (to tell which copies an
            ACK for a later packet proves lost).
        retries: retransmissions so far.
        acked: an ACK arrived (the slot stays until every older slot is acked).
        file_bytes: file bytes this packet carries (D packets; 0 for the others).
        sent_at: when its first copy was handed out (for round-trip samples:
            only packets sent once are measured, Karn's rule).
        ptype: its type letter (for error messages).
        resent_at: when its latest copy was resent (None: sent once).
    """

    seq: int
    wire: bytes
    first_sent: int
    last_sent: int
    retries: int = 0
    acked: bool = False
    file_bytes: int = 0
    sent_at: float = 0.0
    ptype: str = "D"
    resent_at: float | None = None


class SendWindow:
    """The sender's outstanding packets, oldest first; at most ``size`` of them.

    The bound is the negotiated window (<= 31, so that the current and the
    previous window never overlap in the 64 sequence numbers).
    """

    def __init__(self, size: int) -> None:
        self.size = size
        self._slots: dict[int, SendSlot] = {}  # insertion order = send order
        self.acknowledged_bytes = 0
        """File bytes of the packets acknowledged in order (window-low slid past them)."""

    def __len__(self) -> int:
        return len(self._slots)

    @property
    def full(self) -> bool:
        """No room for another packet."""
        return len(self._slots) >= self.size

    def push(
        self,
        seq: int,
        wire: bytes,
        sent: int,
        file_bytes: int = 0,
        *,
        sent_at: float = 0.0,
        ptype: str = "D",
    ) -> None:
        """Record a newly sent packet, ``sent`` being its transmission number."""
        self._slots[seq] = SendSlot(
            seq, wire, sent, sent, file_bytes=file_bytes, sent_at=sent_at, ptype=ptype
        )

    def outstanding_chars(self) -> int:
        """Line characters of the packets not yet acknowledged."""
        return sum(len(slot.wire) for slot in self._slots.values() if not slot.acked)

    def get(self, seq: int) -> SendSlot | None:
        """The outstanding slot with this sequence number, if any."""
        return self._slots.get(seq)

    def unacked(self) -> list[SendSlot]:
        """The outstanding slots not acknowledged yet, oldest first."""
        return [slot for slot in self._slots.values() if not slot.acked]

    def oldest(self) -> SendSlot | None:
        """The oldest unacknowledged slot (window-low), if any."""
        for slot in self._slots.values():
            if not slot.acked:
                return slot
        return None

    def ack(self, seq: int) -> bool:
        """Mark ``seq`` acknowledged and slide past every acked slot at the bottom.

        Returns:
            True when ``seq`` was outstanding and not yet acked.
        """
        slot = self._slots.get(seq)
        if slot is None or slot.acked:
            return False
        slot.acked = True
        while self._slots:
            first = next(iter(self._slots.values()))
            if not first.acked:
                break
            del self._slots[first.seq]
            self.acknowledged_bytes += first.file_bytes
        return True

    def ack_all(self) -> None:
        """Everything outstanding is acknowledged (stop-and-wait's NAK(n+1) = ACK(n) only)."""
        self.acknowledged_bytes += sum(slot.file_bytes for slot in self._slots.values())
        self._slots.clear()


class ReceiveWindow:
    """The receiver's window: ``size`` sequence numbers from ``low`` (the next in order).

    Packets that arrive early are held until the gap before them is filled, so
    at most ``size - 1`` packets are buffered.
    """

    def __init__(self, size: int, low: int) -> None:
        self.size = size
        self.low = low
        self._held: dict[int, Packet] = {}
        self._naked: set[int] = set()

    def offset(self, seq: int) -> int:
        """Distance of ``seq`` above window-low, modulo 64."""
        return (seq - self.low) % SEQ_MODULUS

    def in_window(self, seq: int) -> bool:
        """``seq`` is one we may accept now."""
        return self.offset(seq) < self.size

    def in_previous(self, seq: int) -> bool:
        """``seq`` belongs to the window before this one: an old duplicate to re-ACK."""
        return self.offset(seq) >= SEQ_MODULUS - self.size

    def hold(self, packet: Packet) -> None:
        """Keep an in-window packet until it can be delivered in order."""
        self._held[packet.seq] = packet
        self._naked.discard(packet.seq)

    def pop_ready(self) -> Packet | None:
        """The packet at window-low if it has arrived; the window slides by one."""
        packet = self._held.pop(self.low, None)
        if packet is not None:
            self._naked.discard(self.low)
            self.low = (self.low + 1) % SEQ_MODULUS
        return packet

    def gap_to_nak(self) -> int | None:
        """The oldest missing packet below the highest one held that was not NAKed yet.

        C-Kermit's receiver rule: NAK each gap once, never ahead of what arrived.
        The caller marks it with :meth:`naked`.
        """
        if not self._held:
            return None
        top = max(self.offset(s) for s in self._held)
        for d in range(top):
            seq = (self.low + d) % SEQ_MODULUS
            if seq not in self._held and seq not in self._naked:
                return seq
        return None

    def naked(self, seq: int) -> None:
        """Remember that ``seq`` was NAKed (so a later gap check NAKs the next gap)."""
        self._naked.add(seq)

    def forget_naks(self) -> None:
        """After a timeout every gap may be NAKed again."""
        self._naked.clear()
