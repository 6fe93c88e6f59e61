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
from ._params import (
    INIT_TIMEOUT,
    MIN_TIMEOUT,
    TIMER_MARGIN,
    KermitConfig,
    line_time,
    line_timeout,
)
from ._window import SendSlot, SendWindow

_MIN_DYNAMIC_LENGTH = MAX_NORMAL_LEN + 2
"""96: the dynamic length never goes below a normal packet."""
_ACK_CHARS = 12
"""Line characters of an ACK, for the model's cycle (a long-packet ACK with a CRC and EOL)."""
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


def _goodput(length: int, data: int, whole: float, cps: float, rtt: float, window: int) -> float:
    """Data characters a second for ``length``-character packets (the model of
    :meth:`KermitSender._choose_length`): ``data`` characters of each are data,
    ``whole`` is the chance one arrives undamaged, ``cps`` the line's
    characters a second, ``rtt`` the round trip, ``window`` the slots."""
    sent = length / cps
    cycle = rtt + sent + _ACK_CHARS / cps
    covered = int(window * sent / cycle)  # attempts at window-low the window rides out
    stall = (1 - whole) ** covered * cycle
    return min(data / (sent / whole + stall), window * data * whole / cycle)


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
        self._line_free = 0.0  # pacing: when the line will have sent all we wrote
        self._progress_at = now  # the latest ACK that acknowledged something
        self._last_resend_at = -math.inf
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
        self._on_line(len(wire), now)
        if ptype == PacketType.DATA:
            self._d_chars += len(wire)
        self._window.push(seq, wire, self._transmissions, file_bytes, sent_at=now, ptype=str(ptype))
        self._arm(now)

    def _arm(self, now: float) -> None:
        """Run the retransmission timer from window-low's latest copy, or the last progress.

        Not from the latest packet sent: a paced sender sends new D packets
        all the time, and a timer pushed back by each would let a window-low
        whose resend was lost wait until the window is full and then a whole
        timeout more (C-Kermit NAKs a gap once and holds back the ACKs behind
        it, so nothing else repairs it: at 9600 bit/s, 0.2 s and 1e-3 that was
        5.4 s instead of 2).  An ACK restarts it (TCP's rule), so a burst of
        ACKs held back behind a repaired gap does not time out the packets
        it is about to acknowledge.
        """
        oldest = self._window.oldest()
        start = now
        if oldest is not None:
            copy = oldest.resent_at if oldest.resent_at is not None else oldest.sent_at
            start = max(copy, self._progress_at)
        self._deadline = start + self._timeout()

    # -- timers and packet length ------------------------------------------------

    def _timeout(self) -> float:
        """Line-derived until round trips are measured, then RFC 6298's, with backoff.

        Never below the line's own floor (the round trip, two packets and an
        ACK on the line, and a margin), nor :data:`MIN_TIMEOUT`.
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
            # The path (the configured delay's round trip, or the shortest
            # measured), a packet paced ahead of the resent one, the resent
            # one, its ACK, and the margin for scheduling: an RTO just above
            # the round trip fired before the ACK of a repair could come back
            # (9600 bit/s, 1.3 s, 1e-3: 13-17 timeouts in 32 KiB, mostly early).
            path = max(2 * config.delay, self._min_rtt or 0.0)
            floor = path + line_time(2 * length + _ACK_CHARS, config.rate) + TIMER_MARGIN
            base = max(MIN_TIMEOUT, floor, self._srtt + 4 * self._rttvar)
        return base * self._backoff

    def _measure(self, slot: SendSlot, now: float) -> None:
        """A round-trip sample from a packet sent once (Karn's rule).

        Nor from a packet sent before the latest resend: its ACK may have been
        held back until the gap was repaired (C-Kermit's receiver does that),
        which measures the repair, not the path.
        """
        if slot.retries or slot.sent_at <= self._last_resend_at:
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

    def _paced(self) -> bool:
        """D packets leave at the line rate: the rate is known and something can be lost."""
        return self.config.rate is not None and not self._streaming()

    def _next_data_at(self) -> float:
        """Pacing: when a new D packet may go -- at most one packet still ahead of it.

        The port (a UART, a pty into a relay) drains at the line rate and
        whatever is written beyond that waits in its queue; a packet resent
        after a NAK would wait there behind every new packet already handed
        over (at 2400 bit/s eight 250-character packets are 8 s).  Writing new
        packets only as fast as the line takes them keeps that queue at one
        packet, so a resend goes out next -- and the window can then be as
        large as a repair needs without queueing a window of packets.
        """
        if not self._paced():
            return -math.inf
        return self._line_free - line_time(self._length, self.config.rate)

    def _on_line(self, chars: int, now: float) -> None:
        """Account ``chars`` characters written now: the line is busy until ``_line_free``."""
        if self.config.rate is not None:
            self._line_free = max(self._line_free, now) + line_time(chars, self.config.rate)

    def _choose_length(self) -> int:
        """The D packet length with the best expected goodput on this line and window.

        With a per-character error rate p (resent D packets over D characters
        sent, with a small prior), a packet of L characters arrives whole with
        probability w = (1 - p)^L, and a damaged one costs its line time again,
        so a paced sender moves ``data(L) / (t(L) / w)`` characters a second,
        data(L) being the data field of an L-character packet and t(L) its
        line time.  That holds only while the window keeps the line busy
        through a repair: one attempt of window-low takes a cycle c = the
        round trip + t(L) + an ACK's line time, and a window of W packets
        covers k = floor(W t(L) / c) attempts; a packet that needs more than k
        (probability (1 - w)^k) stalls the line for about a cycle, and with
        k = 0 the window limits the rate to W data(L) w / c even without
        errors.  The best L trades the header's share (short packets) against
        damage (long ones) and against the window's reach (at 9600 bit/s and
        1.3 s one way 30 short packets do not cover two round trips).  The
        round trip is ``--delay``'s, or the shortest one measured (longer
        samples include queueing).  Lengths damaged more than one time in
        three are avoided: with ten retries a packet then fails all of them
        about once in 10^5.  Candidates run from 96 to the negotiated maximum
        in 15 % steps.
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
                rate = _goodput(n, data_capacity(n, neg.check), whole, cps, rtt, neg.window)
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
            lost = [s for s in window.unacked() if s is not slot and s.last_sent < slot.first_sent]
            self._measure(slot, now)
            window.ack(packet.seq)
            self._backoff = 1
            self._progress_at = now
            self._arm(now)
            for older in lost:
                # Every copy of the packet just ACKed left after the latest
                # copy of ``older``, and the line keeps order: that copy or
                # its ACK was lost (see the module doc).  A receiver NAKs a
                # gap only once, so without this a second loss -- of any
                # packet in the window, not only window-low -- waits out the
                # timer (at 9600 bit/s, 1.3 s and 1e-3, four timeouts in a
                # 32 KiB transfer when only window-low was resent).
                self._retransmit(older, now)
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
                if not self._nak_predates_copy(slot, now):
                    self._retransmit(slot, now)
            elif packet.seq == self._seq and window.size == 1:
                # Stop-and-wait only: NAK(n+1) = ACK(n) (Kermit protocol manual).
                window.ack_all()
                self._progress_at = now
                self._arm(now)
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

    def _nak_predates_copy(self, slot: SendSlot, now: float) -> bool:
        """A NAK that left the receiver before the latest copy of ``slot`` could arrive.

        The shortest round trip (measured, else the configured delay's) has
        not passed since that copy went out, so the NAK is about an earlier
        copy, already repaired by this one: a receiver that NAKs window-low
        again on every damaged packet (ours; our own measurement at 9600
        bit/s, 1.3 s, 1e-3: 97 NAKs for 64 damaged packets) would otherwise
        have each repair sent twice or more.
        """
        if slot.resent_at is None:
            return False
        rtt = self._min_rtt if self._min_rtt is not None else 2 * self.config.delay
        return now - slot.resent_at < rtt

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
        while not self._window.full and not self._discard:
            send_at = self._next_data_at()
            if now < send_at:
                self._refill_at = send_at  # paced: come back when the line has room
                break
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
            self._arm(now)
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
        slot.resent_at = now
        self._last_resend_at = now
        self._resend(slot.wire)
        self._on_line(len(slot.wire), now)
        self._arm(now)
