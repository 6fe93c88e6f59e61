"""Kermit file transfer, sans-I/O: the sender (see :mod:`serialsocket.kermit._core`).

The states, their transition table, the events and the shared machinery
are in :mod:`serialsocket.kermit._core`; this module is the sending role.
"""

from __future__ import annotations

import logging
import math
import zlib
from collections import deque
from collections.abc import Sequence
from pathlib import PurePosixPath

from serialsocket._packet import Packet, data_capacity
from serialsocket._wire import MAX_NORMAL_LEN, SEQ_MODULUS, PacketType

from ._attributes import common_form, decode_reply, encode_attributes, refusal_text, to_crlf
from ._core import (
    _BREAK_RETRIES,
    _READ_AHEAD,
    FileCompleted,
    FileStarted,
    KermitSide,
    KermitState,
    OutgoingFile,
    TransferComplete,
)
from ._params import INIT_TIMEOUT, MIN_TIMEOUT, KermitConfig, line_time, line_timeout
from ._window import SendSlot, SendWindow

_MIN_DYNAMIC_LENGTH = MAX_NORMAL_LEN + 2
"""96: the dynamic length never goes below a normal packet."""
_PACKET_OVERHEAD = 20
"""Characters each D packet costs besides its data: 11 of framing, and its share
of the ACK coming back (the model of :meth:`KermitSender._choose_length`)."""
_PRIOR_CHARS = 2000.0
_PRIOR_ERRORS = 0.5
"""Before anything is measured the error estimate is 0.5 errors in 2000
characters (2.5e-4 per character); measured characters and errors soon
outweigh it."""
_MAX_DAMAGED = 1 / 3
"""The dynamic length keeps the chance a packet arrives damaged below this."""
_RTT_GAIN, _RTTVAR_GAIN = 0.125, 0.25
"""RFC 6298's gains for the smoothed round trip and its variation."""
_STREAM_BURST = 32
"""D packets queued per step while streaming: the driver's port write between
steps paces the sender, and the output buffer stays bounded (32 x 9 KB)."""
_MAX_BACKOFF = 8
"""Consecutive timeouts double the timeout up to this factor (reset by progress)."""

log = logging.getLogger(__name__)

__all__ = ["KermitSender"]


class KermitSender(KermitSide):
    """Sends a batch of files to a Kermit receiver.

    Args:
        files: what to send, in order (may be empty: then only S and B).
        config: local settings.
        now: the current time, to start the S packet's timer.

    The S packet is queued at once: call :meth:`data_to_send`.
    """

    def __init__(self, files: Sequence[OutgoingFile], config: KermitConfig, now: float) -> None:
        super().__init__(config, KermitState.SEND_INIT)
        self._files_left: deque[OutgoingFile] = deque(files)
        self._file: OutgoingFile | None = None
        self._pending = bytearray()
        self._eof = False
        self._discard = False
        self._window = SendWindow(1)
        self._seq = 0
        self._transmissions = 0  # orders every copy sent, for the lost-copy rule
        self._started = now
        self._srtt: float | None = None
        self._rttvar = 0.0
        self._min_rtt: float | None = None  # the shortest sample: the path, not its queue
        self._backoff = 1
        self._length = 0  # current D packet length (0 until negotiated)
        self._d_chars = 0.0  # D characters sent, resends included (error estimate)
        self._d_errors = 0.0  # D packets resent (error estimate)
        self._refusal: str | None = None
        self._refill_at: float | None = None  # streaming: when to queue more D
        self._streamed = 0  # streaming: file bytes sent, confirmed by the ACK of Z
        self._send(PacketType.SEND_INIT, self._mine.encode(), now, init=True)

    def _error_seq(self) -> int:
        return self._seq

    def _acknowledged_bytes(self) -> int:
        return self._window.acknowledged_bytes  # the S window before it carried no file bytes

    def _send(
        self, ptype: str, data: bytes, now: float, *, init: bool = False, file_bytes: int = 0
    ) -> None:
        seq = self._seq
        self._seq = (seq + 1) % SEQ_MODULUS
        self._transmissions += 1
        wire = self._emit(Packet(seq=seq, type=ptype, data=data), init=init)
        if ptype == PacketType.DATA:
            self._d_chars += len(wire)
        self._window.push(seq, wire, self._transmissions, file_bytes, sent_at=now, ptype=str(ptype))
        self._deadline = now + self._timeout()

    # -- timers and packet length ------------------------------------------------

    def _timeout(self) -> float:
        """Line-derived until round trips are measured, then RFC 6298's, with backoff.

        Never below the line's own floor (one round trip of the configured
        delay plus one packet and its ACK), nor :data:`MIN_TIMEOUT`.
        """
        config = self.config
        if config.timeout is not None:
            return config.timeout
        neg = self._neg
        if neg is None:
            return max(INIT_TIMEOUT, self._mine.timeout) * self._backoff
        length = self._length or neg.send_max_length
        if self._srtt is None:
            base = line_timeout(config.delay, config.rate, neg.window, length)
        else:
            floor = 2 * config.delay + line_time(length + 12, config.rate)
            base = max(MIN_TIMEOUT, floor, self._srtt + 4 * self._rttvar)
        return base * self._backoff

    def _measure(self, slot: SendSlot, now: float) -> None:
        """A round-trip sample from a packet sent once (Karn's rule)."""
        if slot.retries:
            return
        sample = max(now - slot.sent_at, 0.0)
        if self._min_rtt is None or sample < self._min_rtt:
            self._min_rtt = sample
        if self._srtt is None:
            self._srtt, self._rttvar = sample, sample / 2
        else:
            self._rttvar += _RTTVAR_GAIN * (abs(self._srtt - sample) - self._rttvar)
            self._srtt += _RTT_GAIN * (sample - self._srtt)

    def _data_packet_length(self) -> int:
        if self._neg is None:
            return 96
        return self._length or self._neg.send_max_length

    def _in_flight_cap(self) -> float:
        """Line characters worth having unacknowledged at once, when the rate is known.

        A round trip's worth at the line rate (the bandwidth-delay product)
        keeps the line busy, plus half again and a packet for slack; more only
        queues at the port, and a resent packet waits behind that queue (at
        2400 bit/s eight 250-character packets are 8 s).  Without ``rate`` the
        window alone bounds it.
        """
        rate = self.config.rate
        if rate is None:
            return math.inf
        packet = self._length + 12
        rtt = max(2 * self.config.delay, self._min_rtt or 0.0)
        return max(2 * packet, 1.5 * rtt / line_time(1, rate) + packet)

    def _choose_length(self) -> int:
        """The D packet length with the best expected goodput on this line.

        Model: a packet of L characters arrives whole with probability
        (1 - p)^L, p being the measured per-character error rate (resent D
        packets over D characters sent, with a small prior); goodput is
        that times the data share (L - overhead) / L times the rate the
        window allows -- the line rate, or a window of packets per round
        trip when the round trip is longer (the configured delay, or the
        shortest one measured: longer samples include the queue the window
        itself builds at the port, which a longer packet would only lengthen).
        Lengths damaged more than one time in three are avoided: with ten
        retries, a packet then fails all of them about once in 10^5.
        Candidates run from 96 to the negotiated maximum.

        (A model that also charged each damaged packet the window's stall
        during its repair chose longer packets -- 222 characters instead of
        126 at 2400 bit/s and 1e-3 -- and was slower against C-Kermit through
        the relay: 149 s and 192 s against 128 s and 130 s.)
        """
        neg = self._neg
        assert neg is not None
        top = neg.send_max_length
        if not self.config.dynamic_length or top <= _MIN_DYNAMIC_LENGTH or neg.streaming:
            return top  # streaming: the transport below repairs, nothing is lost
        p = min((self._d_errors + _PRIOR_ERRORS) / (self._d_chars + _PRIOR_CHARS), 0.5)
        cps = 1.0 / line_time(1, self.config.rate)
        rtt = max(2 * self.config.delay, self._min_rtt or 0.0)
        best, best_rate = _MIN_DYNAMIC_LENGTH, -1.0
        length = float(_MIN_DYNAMIC_LENGTH)
        while True:
            n = min(int(length), top)
            whole = math.exp(n * math.log1p(-p))
            if 1 - whole <= _MAX_DAMAGED or n == _MIN_DYNAMIC_LENGTH:
                window_cps = neg.window * n / (rtt + n / cps) if rtt > 0 else cps
                rate = whole * (n - _PACKET_OVERHEAD) / n * min(cps, window_cps)
                if rate > best_rate:
                    best, best_rate = n, rate
            if n >= top:
                return best
            length *= 1.15

    def _on_packet(self, packet: Packet, now: float) -> None:
        window = self._window
        if packet.type == PacketType.ACK:
            slot = window.get(packet.seq)
            if slot is None or slot.acked:
                oldest = window.oldest()
                if (
                    window.size == 1
                    and oldest is not None
                    and packet.seq == (oldest.seq - 1) % SEQ_MODULUS
                ):
                    # Stop-and-wait: G-Kermit answers a damaged packet by
                    # re-ACKing the one before it.  Resend now (gkermit.c does
                    # the same for a "wrong sequence number") instead of
                    # waiting out the timer.
                    self._retransmit(oldest, now)
                return  # otherwise an old duplicate ACK
            oldest = window.oldest()
            self._measure(slot, now)
            window.ack(packet.seq)
            self._backoff = 1
            self._deadline = now + self._timeout()
            if oldest is not None and slot.first_sent > oldest.last_sent:
                # Every copy of the packet just ACKed left after window-low's
                # last copy, and the line keeps order: that copy or its ACK
                # was lost (see the module doc).  A receiver NAKs a gap only
                # once, so without this a second loss waits out the timer.
                self._retransmit(oldest, now)
                if self.finished:
                    return
            self._after_ack(packet, now)
        elif packet.type == PacketType.NAK:
            self._naks_received += 1
            slot = window.get(packet.seq)
            if self._streaming() and self._state in (KermitState.SEND_DATA, KermitState.SEND_EOF):
                # C-Kermit: any error while streaming is fatal (ckcfn2.c).
                self.abort("NAK received on reliable link")
                return
            if self._state is KermitState.SEND_INIT:
                self._retransmit_oldest(now)  # even NAK(1): the ACK of S carries parameters
            elif slot is not None and not slot.acked:
                self._retransmit(slot, now)
            elif packet.seq == self._seq and window.size == 1:
                # Stop-and-wait only: NAK(n+1) = ACK(n) (Kermit protocol manual).
                window.ack_all()
                self._deadline = now + self._timeout()
                self._after_ack(None, now)
            elif packet.seq == self._seq:
                # With windows a NAK acknowledges nothing: C-Kermit NAKs ahead
                # of a packet it still misses (issue 17, finding 9).  The packet
                # it names was never sent, so it is at most a hint; resend the
                # oldest unacknowledged one, as C-Kermit does (its NAK may have
                # been lost).  Z waits for every ACK (_fill).
                self._retransmit_oldest(now)
            # Any other NAK names a packet already acknowledged or outside the
            # window (a late copy): it acknowledges nothing and asks for nothing.
        # Anything else from a receiver (echoes, stray types) is ignored, as ckcfn2.c does.

    def _after_ack(self, ack: Packet | None, now: float) -> None:
        """The window moved: take the next step of the batch."""
        state = self._state
        if len(self._window) and state is not KermitState.SEND_DATA:
            return
        if state is KermitState.SEND_INIT:
            assert ack is not None
            self._negotiate(ack.data)
            assert self._neg is not None
            self._window = SendWindow(self._neg.window)
            self._length = self._choose_length()
            if self.config.resend and not self._neg.recovery:
                log.warning(
                    "the receiver cannot recover (no RESEND capability): files are sent whole"
                )
            self._next_file(now)
        elif state is KermitState.SEND_FILE:
            assert self._file is not None
            if self._neg is not None and self._neg.attributes and not self._file.screen:
                self._goto(KermitState.SEND_ATTRIBUTES)
                self._send(PacketType.ATTRIBUTES, self._attributes(), now)
            else:
                self._goto(KermitState.SEND_DATA)
                self._fill(now)
        elif state is KermitState.SEND_ATTRIBUTES:
            reply = decode_reply(ack.data if ack is not None else b"")
            if reply.refuse:
                self._discard = True  # the receiver refused the file
                self._refusal = refusal_text(reply.refuse)
                self._goto(KermitState.SEND_EOF)
                self._send(PacketType.EOF, b"D", now)
                return
            if reply.resume_from and self._resending():
                self._resume(reply.resume_from)
            self._goto(KermitState.SEND_DATA)
            self._fill(now)
        elif state is KermitState.SEND_DATA:
            if ack is not None and ack.data[:1] in (b"X", b"Z"):
                self._discard = True  # receiver cancelled the file (X) or batch (Z)
                if ack.data[:1] == b"Z":
                    self._files_left.clear()
            self._fill(now)
        elif state is KermitState.SEND_EOF:
            assert self._file is not None
            self._window.acknowledged_bytes += self._streamed  # Z's ACK confirms them
            self._streamed = 0
            self._files += 1
            self._events.append(FileCompleted(self._file.name, self._discard, reason=self._refusal))
            self._next_file(now)
        elif state is KermitState.SEND_BREAK:
            self._goto(KermitState.DONE)
            self._deadline = None
            self._events.append(TransferComplete())

    def _next_file(self, now: float) -> None:
        if not self._files_left:
            self._goto(KermitState.SEND_BREAK)
            self._send(PacketType.BREAK, b"", now)
            return
        self._file = self._files_left.popleft()
        self._pending.clear()
        self._eof = self._discard = False
        self._refusal = None
        self._goto(KermitState.SEND_FILE)
        assert self._neg is not None
        capacity = data_capacity(self._neg.send_max_length, self._neg.check)
        file = self._file
        if file.screen:  # text for the screen: an X header, as it is, no attributes
            self._send(PacketType.TEXT, self._file_name(file.name, capacity), now)
            self._events.append(FileStarted(file.name, screen=True))
            return
        name = file.name if self.config.literal_names else common_form(file.name)
        self._send(PacketType.FILE, self._file_name(name, capacity), now)
        self._events.append(FileStarted(file.name))

    def _resending(self) -> bool:
        """This file goes with RESEND: asked for, negotiated, binary."""
        neg = self._neg
        return bool(self.config.resend and neg and neg.recovery and not self.config.text)

    def _resume(self, offset: int) -> None:
        """The receiver holds ``offset`` bytes already: start there (C-Kermit's rsattr())."""
        file = self._file
        assert file is not None
        if file.size is not None:
            offset = min(offset, file.size)
        file.source.seek(offset)
        self._resumed += offset
        # Bytes the receiver held before count as acknowledged, not as sent.
        self._window.acknowledged_bytes += offset

    def _file_name(self, name: str, capacity: int) -> bytes:
        """``name`` encoded for the F packet, shortened to fit ``capacity`` if need be.

        Shortened by whole characters, before encoding -- cutting the encoded
        bytes could split a prefix pair (a malformed packet the receiver
        rejects) or a UTF-8 sequence -- to ``<start of the stem>-<tag><extension>``:
        the tag (4 hex digits of a CRC of the whole name) keeps two long names
        with the same start from landing on the same file at the receiver, and
        a short extension is kept so the receiver still knows what the file is.
        """
        assert self._neg is not None
        encoding = self._neg.send_encoding

        def encoded(text: str) -> bytes:
            return encoding.encode(text.encode("utf-8", "replace"))

        whole = encoded(name)
        if len(whole) <= capacity:
            return whole
        tag = f"-{zlib.crc32(name.encode('utf-8', 'replace')) & 0xFFFF:04x}"
        suffix = PurePosixPath(name).suffix
        if len(encoded(tag + suffix)) > capacity // 2:
            suffix = ""
        stem = name[: len(name) - len(suffix)]
        lo, hi = 0, len(stem)  # the longest stem[:k] + tag + suffix that fits
        while lo < hi:
            mid = (lo + hi + 1) // 2
            if len(encoded(stem[:mid] + tag + suffix)) <= capacity:
                lo = mid
            else:
                hi = mid - 1
        short = stem[:lo] + tag + suffix
        log.warning(
            "the file name %r does not fit in one F packet (%d bytes here); it is sent as %r "
            "-- a longer --packet-length keeps whole names",
            name,
            capacity,
            short,
        )
        return encoded(short)[:capacity]  # only a capacity under 5 bytes can cut the tag

    def _attributes(self) -> bytes:
        """A packet: type, date, size (K and bytes), RESEND disposition, end."""
        assert self._file is not None
        fields = encode_attributes(
            size=self._file.size,
            text=self.config.text,
            date=self._file.date,
            resend=self._resending(),
        )
        # Sent literally, as C-Kermit's sattr() does (every character is
        # printable; prefix-encoding it would turn tochar(3) = '#' into '##').
        return fields

    def _streaming(self) -> bool:
        return self._neg is not None and self._neg.streaming

    def get_timer(self) -> float | None:
        """The retransmission timer, or sooner when more D packets are due (streaming)."""
        timer = super().get_timer()
        if self._refill_at is None or self.finished:
            return timer
        return self._refill_at if timer is None else min(timer, self._refill_at)

    def handle_timer(self, now: float) -> None:
        """Call at :meth:`get_timer`'s time: queue more D, or resend, or give up."""
        if self.finished:
            return
        if self._refill_at is not None and now >= self._refill_at:
            self._refill_at = None
            if self._state is KermitState.SEND_DATA:
                if self._streaming():
                    self._deadline = now + self._timeout()
                self._fill(now)
        if self._deadline is not None and now >= self._deadline:
            super().handle_timer(now)

    def _stream(self, now: float, capacity: int) -> None:
        """Streaming: queue D packets without waiting for ACKs; none will come.

        A burst at a time (:data:`_STREAM_BURST`); the timer is set to now so
        that the driver comes back for the next one once it has written this
        one to the port.  Z follows the last D at once; its ACK confirms them.
        """
        neg, file = self._neg, self._file
        assert neg is not None
        assert file is not None
        for _ in range(_STREAM_BURST):
            if len(self._pending) < capacity and not self._eof:
                chunk = file.source.read(capacity * _READ_AHEAD)
                if chunk:
                    self._pending += to_crlf(chunk) if self.config.text else chunk
                else:
                    self._eof = True
            if not self._pending or self._discard:
                break
            field, used = neg.send_encoding.encode_prefix(self._pending, capacity)
            del self._pending[:used]
            self._file_bytes += used
            self._streamed += used
            seq = self._seq
            self._seq = (seq + 1) % SEQ_MODULUS
            self._emit(Packet(seq=seq, type=PacketType.DATA, data=field))
        if self._discard or (self._eof and not self._pending):
            self._goto(KermitState.SEND_EOF)
            self._send(PacketType.EOF, b"D" if self._discard else b"", now)
        else:
            self._refill_at = now

    def _fill(self, now: float) -> None:
        """Send D packets while the window has room; Z once the file is all acknowledged."""
        assert self._neg is not None
        assert self._file is not None
        neg = self._neg
        self._length = self._choose_length()
        capacity = data_capacity(self._length, neg.check)
        if self._streaming():
            self._stream(now, capacity)
            return
        cap = self._in_flight_cap()
        while (
            not self._window.full and not self._discard and self._window.outstanding_chars() < cap
        ):
            if len(self._pending) < capacity and not self._eof:
                chunk = self._file.source.read(capacity * _READ_AHEAD)
                if chunk:
                    self._pending += to_crlf(chunk) if self.config.text else chunk
                else:
                    self._eof = True
            if not self._pending:
                break
            field, used = neg.send_encoding.encode_prefix(self._pending, capacity)
            del self._pending[:used]
            self._file_bytes += used
            self._send(PacketType.DATA, field, now, file_bytes=used)
        done = self._discard or (self._eof and not self._pending)
        if done and not len(self._window):
            self._goto(KermitState.SEND_EOF)
            self._send(PacketType.EOF, b"D" if self._discard else b"", now)

    def _on_damage(self, now: float) -> None:
        if self._streaming() and self._state in (KermitState.SEND_DATA, KermitState.SEND_EOF):
            self.abort("Transmission error on reliable link")
            return
        if self._state is KermitState.SEND_BREAK:
            # The receiver answered B; the answer was damaged.  See _BREAK_RETRIES.
            self._break_unacknowledged()
        elif len(self._window) and self._window.size == 1:
            # Stop-and-wait: a damaged reply means "resend" (gkermit.c); with a
            # window the receiver's NAKs and the timer repair instead.
            self._retransmit_oldest(now)

    def _on_timeout(self, now: float) -> None:
        slot = self._window.oldest()
        if self._state is KermitState.SEND_BREAK and slot and slot.retries >= _BREAK_RETRIES:
            self._break_unacknowledged()
        else:
            self._backoff = min(self._backoff * 2, _MAX_BACKOFF)
            self._retransmit_oldest(now)

    def _break_unacknowledged(self) -> None:
        self._goto(KermitState.DONE)
        self._deadline = None
        self._events.append(TransferComplete(break_acknowledged=False))

    def _retransmit_oldest(self, now: float) -> None:
        slot = self._window.oldest()
        if slot is None:
            self._deadline = now + self._timeout()
        else:
            self._retransmit(slot, now)

    def _retransmit(self, slot: SendSlot, now: float) -> None:
        """Resend one packet, or give up once it has used up its retries."""
        limit = self._retry_limit()
        if limit and slot.retries >= limit:
            self._give_up(
                f"packet {slot.seq} ({slot.ptype}) was never acknowledged", slot.retries + 1, now
            )
            return
        if slot.ptype == PacketType.DATA:
            self._d_errors += 1
            self._d_chars += len(slot.wire)
        slot.retries += 1
        self._transmissions += 1
        slot.last_sent = self._transmissions
        self._resend(slot.wire)
        self._deadline = now + self._timeout()
