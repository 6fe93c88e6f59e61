"""The receiving half of an endpoint: reorder buffer, delivery, NAKs, flow control.

Theory of operation
-------------------
``expected`` is the lowest sequence number not yet received.  A packet with
wire number ``s`` is classified against it (C-Kermit's chkwin, ckcfn3.c):

* ``(s - expected) mod M < window``: in the current window.  Buffered
  (once: a duplicate is only re-acknowledged) and acknowledged.
* ``(s - expected) mod M >= M - window``: the previous window, an old
  duplicate whose ACK was lost.  Re-acknowledged, never delivered again.

``M`` is the wire's sequence space: 64, or 262144 with long sequence numbers
(the window is always less than half of it).
* anything else: impossible for a correct peer; counted and ignored.

Packets are delivered in order as soon as ``expected`` is present, so every
byte is delivered exactly once.  Consecutive fields are decoded together:
tokens never span packets, so decoding the concatenation is exact and lets the
vectorised decoder work on large inputs.  The fields of all the packets one
read delivered are decoded together too (:meth:`Receiver.take_fields`
defers them, the endpoint calls :meth:`Receiver.flush` at the end of the
read): one decoder call per read instead of one per packet (fields too
short for the vectorised decoder on their own; longer ones gain nothing
from company and are decoded at once).  A field is
deferred only when it cannot fail to decode and decodes to at most its own
length, so the window every ACK advertises is computed exactly as if it had
been decoded at once (from a bound when that settles it, else after a flush).

NAK policy (C-Kermit's selective repeat): when a packet arrives beyond a gap,
NAK the oldest missing packet not NAKed within the last timeout; when a
damaged packet arrives, do the same, or NAK ``expected`` if nothing is missing.

Flow control: the bytes held (delivered but unread, plus buffered out-of-order
fields) are bounded by ``receive_buffer``.  The advertised window shrinks with
free space; a packet that does not fit is dropped *unacknowledged* (the sender
still holds it and resends it), so a slow reader closes the window instead of
losing data.  An EOF marker needs no space and is always accepted.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ._encoding import _VECTOR_FROM, Encoding
from ._params import DataCodec  # the negotiated codec may be a dense one

__all__ = ["Arrival", "Receiver"]


@dataclass(slots=True)
class Arrival:
    """What the endpoint must do after a data or EOF packet arrived.

    Attributes:
        ack: sequence number (mod the wire's space) to acknowledge, or None.
        nak: sequence number (mod the wire's space) to NAK, or None.
        delivered: bytes newly readable.
        eof: the peer's EOF was delivered by this arrival.
        classification: ``new``, ``duplicate``, ``old``, ``outside`` or ``full``.
    """

    ack: int | None = None
    nak: int | None = None
    delivered: int = 0
    eof: bool = False
    classification: str = "new"
    fields: list[bytes] = field(default_factory=list)


_EOF = None


class Receiver:
    """Receive-side bookkeeping."""

    def __init__(self, *, receive_buffer: int, window: int, capacity: int) -> None:
        self.receive_buffer = receive_buffer
        self.window = window
        self.capacity = capacity
        self.modulus = 64
        """The wire's sequence space: 64, or 262144 with long sequence numbers."""
        self.expected = 1
        self.buffered: dict[int, bytes | None] = {}
        self.buffered_bytes = 0
        self.readable = bytearray()
        self.naked: dict[int, float] = {}
        self.eof = False
        self.discard = False
        self.delivered_total = 0
        self.discarded_total = 0
        self.advertised = 0
        self.pending: list[bytes] = []
        """Fields delivered in order and not decoded yet (:meth:`flush`)."""
        self.pending_chars = 0
        """Their characters: at least the bytes they decode to."""
        self._pending_codec: DataCodec | None = None

    # -- classification ------------------------------------------------------------

    def _resolve(self, seq_mod: int) -> tuple[str, int]:
        offset = (seq_mod - self.expected) % self.modulus
        if offset < self.window:
            return "new", self.expected + offset
        if offset >= self.modulus - self.window:
            return "old", self.expected - (self.modulus - offset)
        return "outside", -1

    def on_packet(
        self, seq_mod: int, field: bytes, eof: bool, now: float, nak_after: float
    ) -> Arrival:
        """Handle a verified data (``eof=False``) or EOF packet.

        Args:
            seq_mod: its wire sequence number.
            field: its encoded data field.
            eof: True for the EOF (Z) packet.
            now: arrival time.
            nak_after: do not NAK the same packet again within this many seconds.
        """
        kind, seq = self._resolve(seq_mod)
        if kind == "old":
            return Arrival(ack=seq_mod, classification="old")
        if kind == "outside" or (self.eof and seq >= self.expected):
            return Arrival(classification="outside")
        if seq in self.buffered:
            return Arrival(ack=seq_mod, classification="duplicate")
        if not eof and not self.discard and not self._fits(len(field)):
            return Arrival(classification="full")
        self.buffered[seq] = _EOF if eof else field
        if not eof:
            self.buffered_bytes += len(field)
        self.naked.pop(seq, None)
        arrival = Arrival(ack=seq_mod)
        self._deliver(arrival)
        if seq > self.expected:
            arrival.nak = self.gap_to_nak(now, nak_after, upto=seq)
        return arrival

    def missing(self, seq_mod: int) -> bool | None:
        """Whether the packet with wire sequence number ``seq_mod`` is in
        the window and not received yet (True), received already (False),
        or outside the window (None)."""
        kind, seq = self._resolve(seq_mod)
        if kind == "old":
            return False
        if kind == "outside" or (self.eof and seq >= self.expected):
            return None
        return seq not in self.buffered

    def _deliver(self, arrival: Arrival) -> None:
        while self.expected in self.buffered:
            item = self.buffered.pop(self.expected)
            self.naked.pop(self.expected, None)
            self.expected += 1
            if item is _EOF:
                arrival.eof = True
                self.eof = True
                break
            self.buffered_bytes -= len(item)
            arrival.fields.append(item)

    def take_fields(self, arrival: Arrival, encoding: DataCodec) -> int:
        """Decode what an arrival delivered and make it readable.

        Raises:
            MalformedDataError: a field with a valid check does not decode.
        """
        fields = arrival.fields
        if not fields:
            return 0
        if not self.discard and type(encoding) is Encoding:
            chars = 0
            for f in fields:  # (a loop, not all(): usually one field)
                if len(f) >= _VECTOR_FROM or not encoding.plain_whole(f):
                    break
                chars += len(f)
            else:
                # Decoded with the rest of this read's fields (flush): a field
                # that passed plain_whole cannot fail, and counts at its length.
                self.pending += fields
                self.pending_chars += chars
                self._pending_codec = encoding
                fields.clear()
                return 0
        if self.pending:
            self.flush()
        # decode_fields, not decode(join): radix-91 fields end in their own tails.
        data = encoding.decode_fields(fields)
        fields.clear()
        if self.discard:
            self.discarded_total += len(data)
            return 0
        self.readable += data
        self.delivered_total += len(data)
        arrival.delivered = len(data)
        return len(data)

    def flush(self) -> None:
        """Decode the deferred fields (:meth:`take_fields`) and make them readable."""
        pending, codec = self.pending, self._pending_codec
        if not pending or codec is None:
            return
        data = codec.decode_fields(pending)
        pending.clear()
        self.pending_chars = 0
        self.readable += data
        self.delivered_total += len(data)

    def deliver(self, data: bytes) -> None:
        """Make bytes that came outside any data packet readable, ahead of
        everything that follows (early data, PROTOCOL.md section 13)."""
        if self.pending:
            self.flush()
        if self.discard:
            self.discarded_total += len(data)
            return
        self.readable += data
        self.delivered_total += len(data)

    def gap_to_nak(self, now: float, nak_after: float, upto: int | None = None) -> int | None:
        """The oldest missing packet not NAKed lately (mod 64), or None.

        Without ``upto`` (a damaged packet arrived), fall back to ``expected``.
        """
        highest = max(self.buffered, default=self.expected - 1)
        end = upto if upto is not None else highest
        for seq in range(self.expected, end):
            if seq in self.buffered:
                continue
            if now - self.naked.get(seq, -float("inf")) >= nak_after:
                self.naked[seq] = now
                return seq % self.modulus
        if upto is None and not self.eof:
            seq = self.expected
            if now - self.naked.get(seq, -float("inf")) >= nak_after:
                self.naked[seq] = now
                return seq % self.modulus
        return None

    # -- flow control ------------------------------------------------------------------

    def free(self) -> int:
        """Bytes of room left for received data."""
        if self.pending:
            self.flush()
        return max(self.receive_buffer - len(self.readable) - self.buffered_bytes, 0)

    def _free_at_least(self) -> int:
        """A lower bound of :meth:`free` that decodes nothing: deferred
        fields counted at their length (at least what they decode to)."""
        return self.receive_buffer - len(self.readable) - self.pending_chars - self.buffered_bytes

    def _fits(self, n: int) -> bool:
        """``n <= free()``, decoding the deferred fields only when the bound
        does not settle it."""
        return n <= self._free_at_least() or n <= self.free()

    def window_to_advertise(self) -> int:
        """Packets the peer may send beyond ``expected``: room for full packets, capped."""
        if self.discard:
            return self.window
        capacity = max(self.capacity, 1)
        if self.pending and self._free_at_least() >= self.window * capacity:
            return self.window  # free() is at least the bound: the cap applies
        return min(self.window, self.free() // capacity)

    def read(self, max_bytes: int | None) -> bytes:
        """Take up to ``max_bytes`` readable bytes (all of them when None)."""
        if self.pending:
            self.flush()
        n = len(self.readable) if max_bytes is None else min(max_bytes, len(self.readable))
        out = bytes(self.readable[:n])
        del self.readable[:n]
        return out

    def last_in_order(self) -> int:
        """The sequence number (mod 64) of the last packet delivered in order."""
        return (self.expected - 1) % self.modulus
