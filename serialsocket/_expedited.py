"""The expedited lane (PROTOCOL.md section 11): small urgent messages that
overtake the byte stream, reliably and exactly once.

Sans-I/O bookkeeping only: which fragments are outstanding, due or expired on
the sending side, which are stored and which messages are complete on the
receiving side.  The endpoint builds and parses the packets (``U`` carries a
fragment, ``V`` acknowledges one), times them with its own round-trip
estimate and hands them to the line ahead of paced data.

Why a lane of its own rather than a flag on data: a byte stream delivers in
order, so anything written into it waits behind every byte queued before it
-- at 2400 bit/s and 1.3 s one way, a round trip of queued data is 2.6 s of
line time in front of an emergency stop.  The lane has its own sequence
space (mod 64, window :data:`EXPEDITED_WINDOW`, so the current and the
previous window never overlap), its own acknowledgements, and messages, not
bytes: the receiver hands each message over whole, once, as soon as all of
its fragments are in, whatever the stream is doing.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

from ._errors import LocalProtocolError, RemoteProtocolError

__all__ = [
    "EXPEDITED_INBOX",
    "EXPEDITED_MAX_BYTES",
    "EXPEDITED_QUEUE",
    "EXPEDITED_WINDOW",
    "URGENT",
    "URGENT_ACK",
    "ExpeditedReceiver",
    "ExpeditedSender",
    "Fragment",
]

URGENT = "U"
"""Packet type of an expedited fragment (not a Kermit type: a classic peer
never negotiates the lane, so never sees one)."""
URGENT_ACK = "V"
"""Packet type of an expedited fragment's acknowledgement."""

EXPEDITED_WINDOW = 31
"""Fragments unacknowledged at once, and the most one message may take.  Below
half of the mod-64 space, so a receiver tells a new fragment from an old
duplicate exactly as section 4.2 does for data."""

EXPEDITED_MAX_BYTES = 1024
"""The longest message the lane takes.  It must also fit in
:data:`EXPEDITED_WINDOW` fragments at the negotiated packet length: 216 bytes
of anything always do (the shortest legal packet, 38 characters, carries 8
bytes of the worst case, three characters a byte)."""

EXPEDITED_QUEUE = 8
"""Messages a sender holds that wait for room in the lane's window."""

EXPEDITED_INBOX = 8
"""Delivered messages a receiver holds unread; while that many wait, new
fragments are not acknowledged (the sender's timer brings them again), so a
peer that floods the lane costs bounded memory and loses nothing."""


@dataclass(slots=True, eq=False)
class Fragment:
    """One expedited packet in flight (sending side).

    Attributes:
        seq: absolute number in the lane (1 for the first fragment of a
            connection); ``seq % 64`` is on the wire.
        more: fragments of the same message after this one.
        field: the encoded data field, without the ``more`` character.
        wire: the whole packet once built (rebuilt never: a resend is a copy).
        transmissions: copies handed to the line so far.
        deadline: when the current copy is given up as lost (inf: not armed).
        order: a stamp that grows with every copy handed to the line, so an
            acknowledgement tells which copies left before the one it answers.
        done_at: when the current copy finishes leaving the UART.
    """

    seq: int
    more: int
    field: bytes
    wire: bytes = b""
    transmissions: int = 0
    deadline: float = math.inf
    order: int = 0
    done_at: float = -math.inf


@dataclass(slots=True)
class ExpeditedSender:
    """The sending half: admission, retransmission and acknowledgement."""

    next: int = 1
    outstanding: dict[int, Fragment] = field(default_factory=dict)
    waiting: deque[list[bytes]] = field(default_factory=deque)
    due: deque[int] = field(default_factory=deque)
    messages_sent: int = 0
    retransmissions: int = 0
    _order: int = 0

    @property
    def full(self) -> bool:
        """:meth:`submit` would refuse: the queue of waiting messages is full."""
        return len(self.waiting) >= EXPEDITED_QUEUE

    @property
    def idle(self) -> bool:
        """Nothing waits and nothing is unacknowledged."""
        return not self.outstanding and not self.waiting

    def submit(self, fields: list[bytes]) -> None:
        """Queue one message, already cut into encoded fields.

        Raises:
            LocalProtocolError: :data:`EXPEDITED_QUEUE` messages already wait
                for room in the window (the peer is not acknowledging).
        """
        if self.full:
            raise LocalProtocolError(
                f"{EXPEDITED_QUEUE} expedited messages already wait for the peer; "
                "wait for one to be acknowledged"
            )
        self.waiting.append(fields)
        self.messages_sent += 1
        self._admit()

    def _admit(self) -> None:
        # The span from the oldest unacknowledged fragment, not their count,
        # is what the window bounds: with 1 and 33 outstanding the receiver,
        # still expecting 1, would take 33 for an old duplicate.
        while self.waiting:
            low = min(self.outstanding, default=self.next)
            if self.next + len(self.waiting[0]) > low + EXPEDITED_WINDOW:
                return
            fields = self.waiting.popleft()
            for i, data in enumerate(fields):
                frag = Fragment(seq=self.next, more=len(fields) - 1 - i, field=data)
                self.outstanding[frag.seq] = frag
                self.due.append(frag.seq)
                self.next += 1

    def has_due(self) -> bool:
        """A fragment waits to be handed to the line (new or a resend)."""
        due = self.due
        while due and due[0] not in self.outstanding:
            due.popleft()
        return bool(due)

    def requeue_unsent(self, now: float) -> int:
        """Schedule again every fragment whose copy was still to leave the
        UART at ``now`` (the port dropped it); returns how many."""
        count = 0
        for seq in sorted(self.outstanding):
            frag = self.outstanding[seq]
            if frag.deadline < math.inf and frag.done_at > now:
                frag.deadline = math.inf
                self.due.append(seq)
                count += 1
        return count

    def pop_due(self) -> Fragment | None:
        """The next fragment to hand to the line (new or a resend), or None."""
        while self.due:
            frag = self.outstanding.get(self.due.popleft())
            if frag is not None:
                return frag
        return None

    def sent(self, frag: Fragment, done_at: float, timeout: float, ceiling: float) -> None:
        """``frag`` was handed to the line and leaves the UART at ``done_at``.

        Each copy waits twice as long as the one before (up to ``ceiling``):
        the lane shares the data's round-trip estimate, and a lost copy on a
        noisy line is damage, but a dead line must not be flooded either.
        """
        if frag.transmissions:
            self.retransmissions += 1
        frag.transmissions += 1
        frag.done_at = done_at
        self._order += 1
        frag.order = self._order
        frag.deadline = done_at + min(timeout * 2 ** (frag.transmissions - 1), ceiling)

    def expired(self, now: float) -> int:
        """Schedule every fragment whose copy timed out; returns how many."""
        count = 0
        for frag in self.outstanding.values():
            if frag.deadline <= now:
                frag.deadline = math.inf
                self.due.append(frag.seq)
                count += 1
        return count

    def next_deadline(self) -> float | None:
        deadlines = [f.deadline for f in self.outstanding.values() if f.deadline < math.inf]
        return min(deadlines) if deadlines else None

    def _absolute(self, seq_mod: int, low: int) -> int:
        """The absolute number at or above ``low`` (within 63) spelled ``seq_mod``."""
        return low + (seq_mod - low) % 64

    def on_ack(self, seq_mod: int, cumulative_mod: int | None) -> int:
        """A ``V``: the peer holds fragment ``seq_mod`` and (``cumulative_mod``)
        every fragment before that number.  Returns fragments scheduled for a
        fast resend: ones still unacknowledged below the one answered whose
        last copy left before it (a serial line never reorders, so they are
        lost)."""
        if not self.outstanding:
            return 0
        low = min(self.outstanding)
        acked = self.outstanding.pop(self._absolute(seq_mod, low), None)
        if cumulative_mod is not None:
            cum = self._absolute(cumulative_mod, low)
            if cum <= self.next:
                for seq in [s for s in self.outstanding if s < cum]:
                    del self.outstanding[seq]
        fast = 0
        if acked is not None:
            for frag in self.outstanding.values():
                if frag.seq < acked.seq and frag.order < acked.order and frag.deadline < math.inf:
                    frag.deadline = math.inf
                    self.due.append(frag.seq)
                    fast += 1
        self._admit()
        return fast


@dataclass(slots=True)
class ExpeditedReceiver:
    """The receiving half: duplicates, reassembly, the bounded inbox."""

    expected: int = 1
    stored: dict[int, tuple[int, bytes]] = field(default_factory=dict)
    inbox: deque[bytes] = field(default_factory=deque)
    messages_received: int = 0
    duplicates: int = 0
    refused: int = 0

    def classify(self, seq_mod: int) -> tuple[str, int]:
        """``("current" | "old" | "outside", absolute number)`` of a fragment."""
        offset = (seq_mod - self.expected) % 64
        if offset < EXPEDITED_WINDOW:
            return "current", self.expected + offset
        if offset >= 64 - EXPEDITED_WINDOW:
            return "old", self.expected + offset - 64
        return "outside", -1

    def on_fragment(self, seq_mod: int, more: int, data: bytes) -> tuple[str, list[list[bytes]]]:
        """Take one fragment.

        Returns ``(classification, completed)``: the classification is
        ``"new"``, ``"duplicate"`` (held already, or of the previous window:
        acknowledge again, deliver never), ``"full"`` (the inbox is full: not
        stored, not acknowledged) or ``"outside"`` (ignore); ``completed``
        lists the fields of each message this fragment completed, in order.

        Raises:
            RemoteProtocolError: the fragments of a message disagree on how
                many there are (a peer bug; the check was good).
        """
        kind, seq = self.classify(seq_mod)
        if kind == "outside":
            return "outside", []
        if kind == "old" or seq in self.stored:
            self.duplicates += 1
            return "duplicate", []
        if len(self.inbox) >= EXPEDITED_INBOX:
            self.refused += 1
            return "full", []
        self.stored[seq] = (more, data)
        return "new", self._assemble()

    def _assemble(self) -> list[list[bytes]]:
        done: list[list[bytes]] = []
        while (first := self.stored.get(self.expected)) is not None:
            count = first[0] + 1
            seqs = range(self.expected, self.expected + count)
            if not all(s in self.stored for s in seqs):
                break
            fields = []
            for i, s in enumerate(seqs):
                more, data = self.stored.pop(s)
                if more != count - 1 - i:
                    raise RemoteProtocolError(
                        f"expedited fragment {s % 64} says {more} follow, expected {count - 1 - i}",
                        error_hint="Malformed expedited message (fragment count)",
                    )
                fields.append(data)
            self.expected += count
            self.messages_received += 1
            done.append(fields)
        return done

    def read(self) -> bytes | None:
        return self.inbox.popleft() if self.inbox else None
