"""Kermit file transfer, sans-I/O: the sender (see :mod:`serialsocket.kermit._core`).

The states, their transition table, the events and the shared machinery
are in :mod:`serialsocket.kermit._core`; this module is the sending role.
"""

from __future__ import annotations

import logging
import zlib
from collections import deque
from collections.abc import Sequence
from pathlib import PurePosixPath

from serialsocket._packet import Packet, data_capacity
from serialsocket._wire import SEQ_MODULUS, PacketType

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
from ._params import KermitConfig
from ._window import SendSlot, SendWindow

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
        self._window.push(seq, wire, self._transmissions, file_bytes)
        self._deadline = now + self._timeout()

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
            window.ack(packet.seq)
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
            self._next_file(now)
        elif state is KermitState.SEND_FILE:
            if self._neg is not None and self._neg.attributes:
                self._goto(KermitState.SEND_ATTRIBUTES)
                self._send(PacketType.ATTRIBUTES, self._attributes(), now)
            else:
                self._goto(KermitState.SEND_DATA)
                self._fill(now)
        elif state is KermitState.SEND_ATTRIBUTES:
            if ack is not None and ack.data[:1] == b"N":
                self._discard = True  # the receiver refused the file
                self._goto(KermitState.SEND_EOF)
                self._send(PacketType.EOF, b"D", now)
            else:
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
            self._files += 1
            self._events.append(FileCompleted(self._file.name, self._discard))
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
        self._goto(KermitState.SEND_FILE)
        assert self._neg is not None
        capacity = data_capacity(self._neg.send_max_length, self._neg.check)
        self._send(PacketType.FILE, self._file_name(self._file.name, capacity), now)
        self._events.append(FileStarted(self._file.name))

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
        """A packet: ``"`` type = binary 8-bit, ``1`` = length in bytes when known."""
        assert self._file is not None
        assert self._neg is not None
        fields = b'"' + bytes([32 + 2]) + b"B8"
        if self._file.size is not None:
            size = str(self._file.size).encode()
            fields += b"1" + bytes([32 + len(size)]) + size
        return self._neg.send_encoding.encode(fields)

    def _fill(self, now: float) -> None:
        """Send D packets while the window has room; Z once the file is all acknowledged."""
        assert self._neg is not None
        assert self._file is not None
        neg = self._neg
        capacity = data_capacity(neg.send_max_length, neg.check)
        while not self._window.full and not self._discard:
            if len(self._pending) < capacity and not self._eof:
                chunk = self._file.source.read(capacity * _READ_AHEAD)
                if chunk:
                    self._pending += chunk
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
            self.abort("Too many retries", message=f"too many retries ({limit}): the link is down")
            return
        slot.retries += 1
        self._transmissions += 1
        slot.last_sent = self._transmissions
        self._resend(slot.wire)
        self._deadline = now + self._timeout()
