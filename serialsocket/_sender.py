"""The sending half of an endpoint: send queue, outstanding packets, retransmission.

Theory of operation
-------------------
Sequence numbers are kept *absolute* (1, 2, 3, ...) inside and reduced mod
``modulus`` (64, or 262144 with long sequence numbers) only on the wire.  An
ACK or NAK carrying ``s mod modulus`` is mapped back to the one outstanding
packet it can mean: outstanding packets span fewer than half the space, so
the mapping is unique.

A packet is acknowledged three ways:

* its own ACK (selective repeat);
* the cumulative "next expected" in any ACK: the peer holds every packet
  below it (this heals lost ACKs without retransmission);
* for window 1 only, a NAK for the *next* packet (Kermit's NAK(n+1) = ACK(n),
  seed 003's stop-and-wait).

A packet is retransmitted when

* its timer expires (deadline = moment it finished leaving the UART + timeout);
* the peer NAKs it, unless the NAK came too soon to be about our last copy;
* an ACK shows the peer holds a later packet but still expects this one
  (fast retransmit: a serial line never reorders, so the packet was lost);
* the ACK of a packet whose first copy left after this packet's last copy
  arrives while this one is unacknowledged: the line and the peer's ACKs
  are both first in, first out, so this copy's ACK would have come first
  (time-order loss detection, as TCP's RACK; it finds every hole, not only
  the first).

With long sequence numbers thousands of packets may be outstanding, so no
per-event operation walks them all: unacknowledged packets are counted, the
retransmission timers sit in a heap, and the retransmission queue drops
packets acknowledged meanwhile lazily, when they reach its head.
"""

from __future__ import annotations

import heapq
import math
from collections import deque
from dataclasses import dataclass

from ._rate import RateMark

__all__ = ["Outstanding", "Sender"]


@dataclass(slots=True)
class Outstanding:
    """One packet sent and not yet acknowledged.

    Attributes:
        seq: absolute sequence number.
        wire: the exact bytes to resend.
        payload: source bytes it carries (0 for EOF).
        eof: True for the EOF (Z) packet.
        done_at: when the last copy finished leaving the UART (estimated).
        deadline: when the retransmission timer fires, or None while queued.
        transmissions: copies sent so far.
        acked: acknowledged (kept until the window slides past it).
        mark: what the rate estimator knew when the first copy left.
        copies: idle copies sent (see :meth:`Sender.peek_copy`).
        sent_index: when its last copy was handed to the line, as a count
            of all copies handed so far (:meth:`Sender.note_sent`).
        first_index: the same for its first copy.
        repair_sent: a repair packet went in place of a resend
            (PROTOCOL.md 15.6); the next resend is whole.
    """

    seq: int
    wire: bytes
    payload: int
    eof: bool
    done_at: float = 0.0
    deadline: float | None = None
    transmissions: int = 0
    acked: bool = False
    mark: RateMark | None = None
    copies: int = 0
    sent_index: int = 0
    first_index: int = 0
    repair_sent: bool = False


class Sender:
    """Send-side bookkeeping; the endpoint decides when and what to put on the line."""

    def __init__(self, *, send_buffer: int) -> None:
        self.send_buffer = send_buffer
        self.queue = bytearray()
        self.base = 1
        self.next = 1
        self.window = 1
        self.modulus = 64
        """The wire's sequence space: 64, or 262144 with long sequence numbers."""
        self.peer_cum = 1
        self.peer_window = 1
        self.outstanding: dict[int, Outstanding] = {}
        self.retransmit: deque[int] = deque()
        """Packets to send again, in sequence order; may hold packets
        acknowledged since they were queued (skipped by :meth:`pop_retransmit`)."""
        self._queued: set[int] = set()
        self._timers: list[tuple[float, int]] = []
        """Heap of (deadline, seq); an entry is stale once its packet is
        acknowledged, queued again, or re-armed with another deadline."""
        self._unacked = 0
        self.fast_retransmit_count = 0
        """Packets queued again because a later packet's ACK proved them lost
        (the cumulative hole, or time-order loss detection)."""
        self.eof_requested = False
        self.eof_sent = False
        self.eof_acked = False
        self.bytes_acked = 0
        self.packets_acked = 0
        self.bytes_in_flight = 0
        self.base_advanced_at = -math.inf
        """When an ACK last moved the window's base: the line delivers in order."""
        self._sent_count = 0
        self._sent_order: deque[tuple[int, int]] = deque()
        """(sent_index, seq) of every copy handed to the line, oldest first;
        entries leave at the head once a later copy is acknowledged."""
        self._copy_top = 0
        self._copy_cursor = 0
        self._copy_round = 1
        """The walk :meth:`peek_copy` makes: down from the newest packet
        (``_copy_top`` - 1 when it began) to the base, once per round."""
        self.delivered: list[Outstanding] = []
        """Packets whose only copy was acknowledged since the endpoint last
        took them (:meth:`take_delivered`): the ACK clock's samples."""

    # -- application side ----------------------------------------------------------

    def free(self) -> int:
        """Bytes ``queue_data`` would accept now."""
        return max(self.send_buffer - len(self.queue), 0)

    def queue_data(self, data: bytes | bytearray | memoryview) -> int:
        """Queue up to ``free()`` bytes; returns how many were taken."""
        n = min(len(data), self.free())
        self.queue += memoryview(data)[:n]
        return n

    # -- window --------------------------------------------------------------------

    def in_flight(self) -> int:
        """Packets sent and not yet acknowledged."""
        return self._unacked

    def room(self, limit: int) -> int:
        """New packets the windows allow now.

        Args:
            limit: the effective window (negotiated window capped by the
                bandwidth-delay bound).
        """
        by_window = self.base + min(self.window, limit) - self.next
        by_peer = self.peer_cum + self.peer_window - self.next
        return max(min(by_window, by_peer), 0)

    def has_new_data(self) -> bool:
        """Something not yet packetised waits (data, or the EOF marker)."""
        return bool(self.queue) or (self.eof_requested and not self.eof_sent)

    def add(self, wire: bytes, payload: int, eof: bool) -> Outstanding:
        """Register a new packet with the next sequence number."""
        pkt = Outstanding(self.next, wire, payload, eof)  # (positional: once per packet)
        self.outstanding[self.next] = pkt
        self.next += 1
        self._unacked += 1
        self.bytes_in_flight += payload
        if eof:
            self.eof_sent = True
        return pkt

    def resolve(self, seq_mod: int) -> int | None:
        """The absolute number of an outstanding packet with this wire seq, if any."""
        offset = (seq_mod - self.base) % self.modulus
        return self.base + offset if offset < self.next - self.base else None

    # -- acknowledgements -------------------------------------------------------------

    def on_ack(
        self, seq_mod: int, cum_mod: int | None, window: int | None, now: float
    ) -> list[float]:
        """Apply an ACK; returns round-trip samples (Karn: first copies only).

        Args:
            seq_mod: the ACK's sequence number (the packet it acknowledges).
            cum_mod: the peer's next expected sequence number, mod ``modulus``.
            window: packets the peer can accept beyond ``cum``.
            now: arrival time.
        """
        samples: list[float] = []
        base = self.base
        seq = self.resolve(seq_mod)
        if seq is not None:
            own = self.outstanding[seq]
            self._ack_one(seq, now, samples, own=True)
            # Whichever copy this ACK is for, it left no earlier than the
            # first: copies handed before that one would have been answered.
            self._losses_before(own.first_index)
        if cum_mod is not None:
            offset = (cum_mod - self.base) % self.modulus
            if offset <= self.next - self.base:
                cum = self.base + offset
                for s in range(self.base, cum):
                    self._ack_one(s, now, samples)
                if cum >= self.peer_cum:
                    self.peer_cum = cum
                    if window is not None:
                        self.peer_window = window
                # Fast retransmit: the peer holds `seq` (sent after `cum`) but not
                # `cum`; on a line that never reorders, `cum` was lost.
                lost = self.outstanding.get(cum)
                later = self.outstanding.get(seq) if seq is not None else None
                if (
                    lost is not None
                    and later is not None
                    and not lost.acked
                    and later.seq > lost.seq
                    and lost.done_at <= later.done_at
                    and lost.deadline is not None
                    and lost.seq not in self._queued
                ):
                    self.schedule(lost.seq)
                    self.fast_retransmit_count += 1
        self._slide()
        if self.base > base:
            self.base_advanced_at = now
        return samples

    def note_sent(self, pkt: Outstanding) -> None:
        """A copy of ``pkt`` was handed to the line (after this call, its
        timer is armed by the caller)."""
        self._sent_count += 1
        pkt.sent_index = self._sent_count
        if not pkt.first_index:
            pkt.first_index = self._sent_count
        self._sent_order.append((self._sent_count, pkt.seq))

    def _losses_before(self, index: int) -> None:
        """The copy handed at ``index`` was acknowledged: every copy handed
        before it whose packet is still unacknowledged was lost (or its ACK
        was: a spare copy then, which the peer drops as a duplicate)."""
        order = self._sent_order
        while order and order[0][0] < index:
            sent, seq = order.popleft()
            pkt = self.outstanding.get(seq)
            if (
                pkt is None
                or pkt.acked
                or pkt.sent_index != sent  # a later copy is on its way
                or pkt.deadline is None
                or seq in self._queued
            ):
                continue
            self.schedule(seq)
            self.fast_retransmit_count += 1

    def on_nak(
        self, seq_mod: int, now: float, min_rtt: float, *, first_min_rtt: float | None = None
    ) -> None:
        """Apply a NAK: resend that packet unless our last copy is still on its way.

        Args:
            seq_mod: the NAK's sequence number.
            now: arrival time.
            min_rtt: the least time from a copy finishing leaving the UART to a
                NAK provoked by that copy (two delays plus the NAK's transmit
                time); a NAK sooner than that is about an earlier copy.
            first_min_rtt: the same for a packet sent once (there is no
                earlier copy; a NAK may still come before it could have
                arrived): None is ``min_rtt``.
        """
        seq = self.resolve(seq_mod)
        if seq is None:
            if (
                self.window == 1
                and seq_mod == self.next % self.modulus
                and self.next - 1 in self.outstanding
            ):
                # Stop-and-wait: NAK(n+1) = ACK(n) (seed 003; Kermit ckcfn2.c input()).
                # It also says the peer now expects n+1, exactly as an ACK's
                # cumulative field would: without advancing peer_cum, room()
                # stays 0 and nothing more is sent until a keepalive answer.
                self._ack_one(self.next - 1, now, [], own=True)
                self.peer_cum = max(self.peer_cum, self.next)
                self._slide()
            return
        pkt = self.outstanding[seq]
        if pkt.acked or pkt.deadline is None:
            return
        if pkt.transmissions == 1 and first_min_rtt is not None:
            min_rtt = first_min_rtt
        if now - pkt.done_at >= min_rtt:
            self.schedule(seq)

    def _ack_one(self, seq: int, now: float, samples: list[float], *, own: bool = False) -> None:
        pkt = self.outstanding.get(seq)
        if pkt is None or pkt.acked:
            return
        pkt.acked = True
        self._unacked -= 1
        self.packets_acked += 1
        self.bytes_acked += pkt.payload
        self.bytes_in_flight -= pkt.payload
        if pkt.transmissions == 1 and pkt.deadline is not None:
            samples.append(now - pkt.done_at)
            if own:
                # Only its own ACK times a packet: one acknowledged by a later
                # ACK's cumulative field lost its ACK, and the wait for the
                # next one is neither the path's round trip nor a queue.
                self.delivered.append(pkt)

    def take_delivered(self) -> list[Outstanding]:
        """The packets acknowledged on their first copy since the last call."""
        taken, self.delivered = self.delivered, []
        return taken

    def _slide(self) -> None:
        while self.base < self.next and self.outstanding[self.base].acked:
            # EOF counts as acknowledged only when the window slides past it,
            # i.e. when every packet before it is acknowledged too: a selective
            # ACK of Z alone must not close the stream over a missing packet.
            if self.outstanding.pop(self.base).eof:
                self.eof_acked = True
            self.base += 1
        self._drop_stale_head()

    def _drop_stale_head(self) -> None:
        """Forget queued retransmissions at the head that were acknowledged meanwhile."""
        while self.retransmit:
            pkt = self.outstanding.get(self.retransmit[0])
            if pkt is not None and not pkt.acked:
                return
            self._queued.discard(self.retransmit.popleft())

    # -- retransmission --------------------------------------------------------------

    def schedule(self, seq: int) -> None:
        """Queue a packet for retransmission (once, in sequence order)."""
        if seq in self._queued:
            return
        self._queued.add(seq)
        self.retransmit.append(seq)
        if len(self.retransmit) > 1 and self.retransmit[-2] > seq:
            self.retransmit = deque(sorted(self.retransmit))

    def requeue_unsent(self, now: float) -> list[int]:
        """Schedule for resending every unacknowledged packet whose last copy
        was still to leave the UART at ``now`` (the port dropped what it had
        not sent); returns their numbers."""
        cut = [
            seq
            for seq, pkt in self.outstanding.items()
            if not pkt.acked
            and pkt.deadline is not None
            and seq not in self._queued
            and pkt.done_at > now
        ]
        for seq in cut:
            self.schedule(seq)
        return cut

    def restart_at(self, seq: int) -> None:
        """Forget every packet sent (a first flight the peer did not take,
        PROTOCOL.md 14): the next packet is ``seq``.  The caller puts their
        bytes back in :attr:`queue` first; none of them counts as sent."""
        self.outstanding.clear()
        self.retransmit.clear()
        self._queued.clear()
        self._timers.clear()
        self._sent_order.clear()
        self.delivered.clear()
        self._unacked = 0
        self.bytes_in_flight = 0
        self.eof_sent = False
        self.base = self.next = self.peer_cum = seq
        self._copy_top = self._copy_cursor = 0
        self._copy_round = 1

    def has_retransmit(self) -> bool:
        """A packet waits to be sent again."""
        self._drop_stale_head()
        return bool(self.retransmit)

    def pop_retransmit(self) -> Outstanding | None:
        """The next packet to send again (oldest first), or None."""
        self._drop_stale_head()
        if not self.retransmit:
            return None
        seq = self.retransmit.popleft()
        self._queued.discard(seq)
        return self.outstanding[seq]

    def retransmit_pending(self) -> int:
        """Packets queued to be sent again and still unacknowledged."""
        return sum(1 for s in self.retransmit if not self._stale(s))

    def _stale(self, seq: int) -> bool:
        pkt = self.outstanding.get(seq)
        return pkt is None or pkt.acked

    def arm(self, pkt: Outstanding, deadline: float) -> None:
        """Start (or restart) ``pkt``'s retransmission timer."""
        pkt.deadline = deadline
        heapq.heappush(self._timers, (deadline, pkt.seq))

    def _timer_valid(self, deadline: float, seq: int) -> bool:
        pkt = self.outstanding.get(seq)
        return (
            pkt is not None
            and not pkt.acked
            and pkt.deadline == deadline
            and seq not in self._queued
        )

    def expired(self, now: float) -> list[int]:
        """Unacknowledged packets whose timer has fired and are not yet queued
        again, oldest deadline first.  The caller queues each (or gives up):
        their timers are spent."""
        out: list[int] = []
        timers = self._timers
        while timers and timers[0][0] <= now:
            deadline, seq = heapq.heappop(timers)
            if self._timer_valid(deadline, seq):
                out.append(seq)
        return out

    def next_deadline(self) -> float | None:
        """The earliest retransmission deadline among packets on the line."""
        timers = self._timers
        while timers and not self._timer_valid(*timers[0]):
            heapq.heappop(timers)
        return timers[0][0] if timers else None

    # -- idle copies --------------------------------------------------------------------

    def peek_copy(self, limit: int) -> Outstanding | None:
        """The packet an idle line should carry another copy of, or None.

        Candidates are unacknowledged, on the line (not waiting for a
        resend) and copied fewer than ``limit`` times.  Newest first, one
        round of copies at a time: a newer packet's loss would be revealed
        latest (the newest has no later packet to reveal it at all, only its
        timer), so its copy saves the most waiting.  The walk goes down from
        the newest packet to the base and starts again at the top for the
        next round, or when packets were sent since; each step passes a
        packet for good in that round, so a round costs one pass over the
        window however often it is asked.
        """
        if self._copy_top != self.next:
            self._copy_top = self.next
            self._copy_cursor = self.next - 1
            self._copy_round = 1
        while self._copy_round <= limit:
            while self._copy_cursor >= self.base:
                pkt = self.outstanding.get(self._copy_cursor)
                if pkt is not None and self._copyable(pkt, self._copy_round):
                    return pkt
                self._copy_cursor -= 1
            self._copy_round += 1
            self._copy_cursor = self.next - 1
        return None

    def peek_base_copy(self, limit: int) -> Outstanding | None:
        """The packet at the window's base, if it may be copied (as
        :meth:`peek_copy`'s candidates): with the window full, it is the
        one holding everything behind it."""
        pkt = self.outstanding.get(self.base)
        return pkt if pkt is not None and self._copyable(pkt, limit) else None

    def _copyable(self, pkt: Outstanding, below: int) -> bool:
        """Unacknowledged, on the line (not waiting for a resend), and
        copied fewer than ``below`` times."""
        return (
            not pkt.acked
            and pkt.deadline is not None
            and pkt.seq not in self._queued
            and pkt.copies < below
        )

    def take_copy(self, pkt: Outstanding, *, walk: bool = True) -> None:
        """``pkt`` (from :meth:`peek_copy`, or :meth:`peek_base_copy` with
        ``walk`` False) is being copied onto the line."""
        pkt.copies += 1
        if walk:
            self._copy_cursor = pkt.seq - 1

    def unsent_bytes(self) -> int:
        """Bytes queued by the application that never left."""
        return len(self.queue)
