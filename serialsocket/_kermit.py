"""Kermit file transfer, sans-I/O: a sender and a receiver state machine.

This is Kermit's own file-transfer protocol (reference/kermit.md section 5),
spoken with C-Kermit, G-Kermit and anything else that speaks it, on the same
packet layer as telelink's connection protocol (:func:`build_packet`,
:class:`PacketParser`, :class:`Encoding`).  Roles are half duplex: the sender
sends S, F, [A], D..., Z, (F...Z)..., B; the receiver ACKs each packet (Y,
same sequence number) or NAKs one it wants again (N).  E ends the transfer
from either side and is never ACKed.

Both machines have the sans-I/O surface of the rest of the package:
``receive_data(bytes, now)``, ``data_to_send()``, ``next_event()``,
``get_timer()``, ``handle_timer(now)``.  They do no I/O of their own except
that the sender reads file contents from the ``source`` objects it is given
(any object with ``read(n) -> bytes``; the caller opens and closes files).

ARQ, as C-Kermit does it (ckcfn2.c input()):

* S, F, A, Z and B are stop-and-wait: each is sent alone and the next step
  waits for its ACK (the ACK of S carries the receiver's parameters; the ACK
  of A may refuse the file).  D packets fill the window.
* The sender resends exactly the packet a NAK names, or window-low on a
  timeout.  A NAK for the packet after the last one sent means everything was
  received (NAK(n+1) = ACK(n)), except while waiting for the ACK of S.  When
  an ACK arrives for a packet whose every copy was sent after window-low's
  last copy, window-low is resent at once: the line keeps order, so that copy
  or its ACK was lost, and waiting for a timeout would stall the window for
  seconds on a delayed link.  (This generalises the 1985 windowing draft's
  heuristic, which did it once, for a packet never resent.)
* The receiver ACKs every in-window packet on arrival, buffers out-of-order
  ones, NAKs the oldest gap not NAKed yet, re-ACKs duplicates from the
  previous window, and on a timeout or a damaged packet NAKs window-low.
* Each packet may be retried ``retry_limit`` times (0 = forever); then the
  side sends ``E`` "Too many retries" and fails.
"""

from __future__ import annotations

import enum
import logging
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from ._checks import BlockCheck
from ._encoding import Encoding
from ._errors import LocalProtocolError, MalformedDataError, RemoteProtocolError
from ._kermit_params import KermitConfig, KermitInit, KermitNegotiated, negotiate_kermit
from ._kermit_window import ReceiveWindow, SendSlot, SendWindow
from ._packet import Packet, build_packet, data_capacity
from ._parser import PacketParser, PacketReceived
from ._wire import CR, MAX_PACKET_LENGTH, SEQ_MODULUS, PacketType

__all__ = [
    "FileCompleted",
    "FileData",
    "FileStarted",
    "KermitEvent",
    "KermitReceiver",
    "KermitSender",
    "KermitState",
    "KermitStatistics",
    "OutgoingFile",
    "TransferComplete",
    "TransferFailed",
]

log = logging.getLogger(__name__)

_PLAIN = Encoding(qbin=None, rept=None)
"""Encoding for E packets sent before negotiation (controls prefixed, 8 bits raw)."""
_PARSER_SLACK = 16
"""Extra characters accepted beyond what we advertise: C-Kermit 10.0 was seen
sending LENX 1000 after we advertised 999 (reference/kermit.md section 4)."""
_READ_AHEAD = 8
"""File bytes buffered ahead of the encoder, in data fields: enough for a
window's refill without a read per packet, bounded by 8 x 9024 bytes."""
_BREAK_RETRIES = 2
"""Copies of B resent before the sender stops waiting for its ACK.  Every file
is already acknowledged by then, and C-Kermit and G-Kermit exit as soon as
they have ACKed B: a lost ACK would otherwise cost retry-limit x timeout and
end in a spurious failure (seen through the relay at a byte error rate of 1e-4)."""
_MAX_ERROR_TEXT = 80
"""E-packet messages are cut to this many characters: they must fit a normal packet."""


class KermitState(enum.Enum):
    """States of both roles (a sender uses the SEND_* ones, a receiver the RECEIVE_* ones)."""

    SEND_INIT = "send-init"
    """Sender: S sent, waiting for its ACK with the receiver's parameters."""
    SEND_FILE = "send-file"
    """Sender: F sent, waiting for its ACK."""
    SEND_ATTRIBUTES = "send-attributes"
    """Sender: A sent, waiting for its ACK (which may refuse the file)."""
    SEND_DATA = "send-data"
    """Sender: D packets in flight."""
    SEND_EOF = "send-eof"
    """Sender: Z sent, waiting for its ACK."""
    SEND_BREAK = "send-break"
    """Sender: B sent, waiting for its ACK."""
    RECEIVE_INIT = "receive-init"
    """Receiver: waiting for S."""
    RECEIVE_FILE = "receive-file"
    """Receiver: waiting for F (next file) or B (end of batch)."""
    RECEIVE_DATA = "receive-data"
    """Receiver: in a file, waiting for A, D or Z."""
    DONE = "done"
    """The batch ended normally (B acknowledged)."""
    FAILED = "failed"
    """An E packet was sent or received; nothing more happens."""


_S = KermitState
TRANSITIONS: dict[KermitState, frozenset[KermitState]] = {
    _S.SEND_INIT: frozenset({_S.SEND_FILE, _S.SEND_BREAK, _S.FAILED}),
    _S.SEND_FILE: frozenset({_S.SEND_ATTRIBUTES, _S.SEND_DATA, _S.FAILED}),
    _S.SEND_ATTRIBUTES: frozenset({_S.SEND_DATA, _S.SEND_EOF, _S.FAILED}),
    _S.SEND_DATA: frozenset({_S.SEND_EOF, _S.FAILED}),
    _S.SEND_EOF: frozenset({_S.SEND_FILE, _S.SEND_BREAK, _S.FAILED}),
    _S.SEND_BREAK: frozenset({_S.DONE, _S.FAILED}),
    _S.RECEIVE_INIT: frozenset({_S.RECEIVE_FILE, _S.FAILED}),
    _S.RECEIVE_FILE: frozenset({_S.RECEIVE_DATA, _S.DONE, _S.FAILED}),
    _S.RECEIVE_DATA: frozenset({_S.RECEIVE_FILE, _S.FAILED}),
    _S.DONE: frozenset(),
    _S.FAILED: frozenset(),
}
"""Every legal state change, in one table; anything else raises LocalProtocolError."""


class Readable(Protocol):
    """What the sender reads file contents from (a binary file, ``io.BytesIO``)."""

    def read(self, size: int, /) -> bytes: ...


@dataclass(frozen=True, slots=True)
class OutgoingFile:
    """A file to send: the name the receiver sees, its size if known, and its bytes."""

    name: str
    size: int | None
    source: Readable


@dataclass(frozen=True, slots=True)
class FileStarted:
    """A file began (F packet); ``size`` comes from the A packet, when one is sent later."""

    name: str


@dataclass(frozen=True, slots=True)
class FileData:
    """Received file bytes, in order (receiver only)."""

    data: bytes


@dataclass(frozen=True, slots=True)
class FileCompleted:
    """A file ended (Z acknowledged); ``discarded`` when the sender cancelled it (Z ``D``).

    ``size`` is the length the A packet announced, if any (receiver only).
    """

    name: str
    discarded: bool
    size: int | None = None


@dataclass(frozen=True, slots=True)
class TransferComplete:
    """The batch ended normally: every file's Z was acknowledged and B was sent.

    ``break_acknowledged`` is False when the sender stopped waiting for the
    ACK of B (it came back damaged, or :data:`_BREAK_RETRIES` copies of B went
    unanswered): the receiver had already acknowledged every file, and most
    Kermit receivers exit right after ACKing B, so nothing could repair it.
    """

    break_acknowledged: bool = True


@dataclass(frozen=True, slots=True)
class TransferFailed:
    """The transfer stopped: ``by_peer`` when the peer sent E, else we did."""

    message: str
    by_peer: bool


KermitEvent = FileStarted | FileData | FileCompleted | TransferComplete | TransferFailed


@dataclass(frozen=True, slots=True, kw_only=True)
class KermitStatistics:
    """Counters of one transfer (a snapshot).

    Attributes:
        state: the current state.
        window: negotiated window (1 before the exchange).
        packet_length: longest packet we send, MARK through CHECK.
        check: block check in force.
        files: files completed.
        file_bytes: file bytes sent (sender) or delivered (receiver).
        packets_sent, packets_received: packets, retransmissions included.
        retransmissions: packets sent again.
        naks_sent, naks_received: NAK packets.
        timeouts: timer expiries.
        damaged: packets or garbage runs the parser rejected.
        bytes_sent, bytes_received: line bytes.
        eighth_bit_prefix: the agreed 8th-bit prefix (``&``), or None when
            8-bit bytes travel raw (or before the exchange).
        repeat_prefix: the agreed repeat prefix (``~``), or None.
    """

    state: KermitState
    window: int
    packet_length: int
    check: BlockCheck
    files: int
    file_bytes: int
    packets_sent: int
    packets_received: int
    retransmissions: int
    naks_sent: int
    naks_received: int
    timeouts: int
    damaged: int
    bytes_sent: int
    bytes_received: int
    eighth_bit_prefix: str | None
    repeat_prefix: str | None


class _Side:
    """What both roles share: parser, output buffer, events, E packets, counters."""

    def __init__(self, config: KermitConfig, state: KermitState) -> None:
        self.config = config
        self._state = state
        self._mine = KermitInit.mine(config)
        self._neg: KermitNegotiated | None = None
        self._parser = PacketParser(
            max_length=min(max(config.max_packet_length, 96) + _PARSER_SLACK, MAX_PACKET_LENGTH),
            check=BlockCheck.SUM6,
            init_check=BlockCheck.SUM6,
        )
        self._out = bytearray()
        self._events: deque[KermitEvent] = deque()
        self._deadline: float | None = None
        self._retries = 0
        self._files = 0
        self._file_bytes = 0
        self._sent = self._received = self._retransmissions = 0
        self._naks_sent = self._naks_received = self._timeouts = self._damaged = 0
        self._bytes_sent = self._bytes_received = 0

    # -- public surface ---------------------------------------------------------

    @property
    def state(self) -> KermitState:
        """The current state."""
        return self._state

    @property
    def finished(self) -> bool:
        """True once DONE or FAILED: nothing more will be sent or timed."""
        return self._state in (KermitState.DONE, KermitState.FAILED)

    def data_to_send(self) -> bytes:
        """Bytes for the line, in order; empty when there is nothing to send."""
        out = bytes(self._out)
        self._out.clear()
        self._bytes_sent += len(out)
        return out

    def next_event(self) -> KermitEvent | None:
        """The next event, or None."""
        return self._events.popleft() if self._events else None

    def get_timer(self) -> float | None:
        """When :meth:`handle_timer` must be called, or None (finished)."""
        return None if self.finished else self._deadline

    def receive_data(self, data: bytes | bytearray | memoryview, now: float) -> None:
        """Bytes from the line (any chunking)."""
        self._bytes_received += len(data)
        if self.finished:
            return
        self._parser.receive_data(data)
        while not self.finished and (event := self._parser.next_event()) is not None:
            if not isinstance(event, PacketReceived):
                self._damaged += 1
                if log.isEnabledFor(logging.DEBUG):
                    log.debug("%.3f <- damaged: %s %r", now, event.reason.value, event.raw[:12])
                self._on_damage(now)
                continue
            self._received += 1
            packet = event.packet
            if log.isEnabledFor(logging.DEBUG):
                log.debug("%.3f <- %s %d %r", now, packet.type, packet.seq, packet.data[:40])
            if packet.type == PacketType.ERROR:
                text = self._decode_text(packet.data)
                self._finish_failed(f"peer reported: {text}", by_peer=True)
                return
            try:
                self._on_packet(packet, now)
            except RemoteProtocolError as exc:
                self.abort(exc.error_hint, message=str(exc))

    def handle_timer(self, now: float) -> None:
        """Call at :meth:`get_timer`'s time: resend or NAK, or give up."""
        if self.finished or self._deadline is None or now < self._deadline:
            return
        self._timeouts += 1
        self._on_timeout(now)

    def abort(self, reason: str, *, message: str | None = None) -> None:
        """Stop the transfer now: send E with ``reason`` and fail (local cancel, bad data)."""
        if self.finished:
            return
        text = reason[:_MAX_ERROR_TEXT]
        enc = self._neg.send_encoding if self._neg else _PLAIN
        field, _ = enc.encode_prefix(text.encode("utf-8", "replace"), 4 * _MAX_ERROR_TEXT)
        self._emit(Packet(seq=self._error_seq(), type=PacketType.ERROR, data=field))
        self._finish_failed(message or reason, by_peer=False)

    def statistics(self) -> KermitStatistics:
        """A snapshot of the counters."""
        neg = self._neg
        return KermitStatistics(
            state=self._state,
            window=neg.window if neg else 1,
            packet_length=neg.send_max_length if neg else 96,
            check=neg.check if neg else BlockCheck.SUM6,
            files=self._files,
            file_bytes=self._file_bytes,
            packets_sent=self._sent,
            packets_received=self._received,
            retransmissions=self._retransmissions,
            naks_sent=self._naks_sent,
            naks_received=self._naks_received,
            timeouts=self._timeouts,
            damaged=self._damaged,
            bytes_sent=self._bytes_sent,
            bytes_received=self._bytes_received,
            eighth_bit_prefix=_prefix(neg.send_encoding.qbin if neg else None),
            repeat_prefix=_prefix(neg.send_encoding.rept if neg else None),
        )

    # -- shared internals -------------------------------------------------------

    def _goto(self, state: KermitState) -> None:
        if state not in TRANSITIONS[self._state]:
            raise LocalProtocolError(f"illegal Kermit transition {self._state.value} -> {state}")
        self._state = state

    def _finish_failed(self, message: str, *, by_peer: bool) -> None:
        self._goto(KermitState.FAILED)
        self._deadline = None
        self._events.append(TransferFailed(message, by_peer))

    def _timeout(self) -> float:
        if self._neg is not None:
            return self._neg.timeout
        return self._mine.timeout

    def _retry_limit(self) -> int:
        return self._neg.retry_limit if self._neg else self.config.retry_limit

    def _emit(self, packet: Packet, *, init: bool = False) -> bytes:
        """Append a packet to the output; returns its wire bytes."""
        neg = self._neg
        if neg is None or init:
            wire = build_packet(packet, BlockCheck.SUM6, eol=CR)
        else:
            wire = build_packet(packet, neg.check, eol=neg.eol, padding=neg.padding)
        self._out += wire
        self._sent += 1
        if log.isEnabledFor(logging.DEBUG):
            log.debug("-> %s %d %r", packet.type, packet.seq, packet.data[:40])
        return wire

    def _resend(self, wire: bytes) -> None:
        if log.isEnabledFor(logging.DEBUG):
            log.debug("-> resend %r", wire[:6])
        self._out += wire
        self._sent += 1
        self._retransmissions += 1

    def _decode_text(self, field: bytes) -> str:
        enc = self._neg.receive_encoding if self._neg else _PLAIN
        try:
            raw = enc.decode(field)
        except MalformedDataError:
            raw = field
        return raw.decode("utf-8", "replace")

    def _decode(self, field: bytes) -> bytes:
        assert self._neg is not None
        return self._neg.receive_encoding.decode(field)

    def _count_retry(self) -> bool:
        """Count one more retry; on exceeding the limit abort and return False."""
        self._retries += 1
        limit = self._retry_limit()
        if limit and self._retries > limit:
            self.abort("Too many retries", message=f"too many retries ({limit}): the link is down")
            return False
        return True

    def _negotiate(self, theirs: bytes) -> None:
        peer = KermitInit.decode(theirs)
        neg = negotiate_kermit(self.config, self._mine, peer)
        self._neg = neg
        self._parser.check = neg.check

    # -- role hooks -------------------------------------------------------------

    def _on_packet(self, packet: Packet, now: float) -> None:
        raise NotImplementedError

    def _on_damage(self, now: float) -> None:
        raise NotImplementedError

    def _on_timeout(self, now: float) -> None:
        raise NotImplementedError

    def _error_seq(self) -> int:
        raise NotImplementedError


class KermitSender(_Side):
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

    def _send(self, ptype: str, data: bytes, now: float, *, init: bool = False) -> None:
        seq = self._seq
        self._seq = (seq + 1) % SEQ_MODULUS
        self._transmissions += 1
        wire = self._emit(Packet(seq=seq, type=ptype, data=data), init=init)
        self._window.push(seq, wire, self._transmissions)
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
            elif packet.seq == self._seq:
                window.ack_all()  # NAK(n+1) = ACK(n)
                self._deadline = now + self._timeout()
                self._after_ack(None, now)
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
        name = self._neg.send_encoding.encode(self._file.name.encode("utf-8", "replace"))
        capacity = data_capacity(self._neg.send_max_length, self._neg.check)
        self._send(PacketType.FILE, name[:capacity], now)
        self._events.append(FileStarted(self._file.name))

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
            self._send(PacketType.DATA, field, now)
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


class KermitReceiver(_Side):
    """Receives a batch of files from a Kermit sender.

    Emits :class:`FileStarted`, :class:`FileData` (in order),
    :class:`FileCompleted` per file, then :class:`TransferComplete`; the
    caller stores the bytes.  File names arrive as the peer sent them: the
    caller must sanitise them before using them as paths.

    Args:
        config: local settings.
        now: the current time (starts the wait for S).
    """

    def __init__(self, config: KermitConfig, now: float) -> None:
        super().__init__(config, KermitState.RECEIVE_INIT)
        self._window = ReceiveWindow(1, 0)
        self._acks: dict[int, bytes] = {}  # last ACK sent per sequence number (bounded: 64)
        self._name = ""
        self._size: int | None = None
        self._deadline = now + self._timeout()

    def _error_seq(self) -> int:
        return self._window.low

    def _ack(self, seq: int, data: bytes = b"", *, init: bool = False) -> None:
        self._acks[seq] = self._emit(Packet(seq=seq, type=PacketType.ACK, data=data), init=init)

    def _nak(self, seq: int) -> None:
        self._naks_sent += 1
        self._emit(Packet(seq=seq, type=PacketType.NAK))

    def _on_packet(self, packet: Packet, now: float) -> None:
        window = self._window
        if self._state is KermitState.RECEIVE_INIT:
            if packet.type != PacketType.SEND_INIT:
                return  # noise before the transfer, or a peer in another mode
            self._negotiate(packet.data)
            assert self._neg is not None
            self._ack(packet.seq, self._mine.encode(), init=True)
            self._window = ReceiveWindow(self._neg.window, (packet.seq + 1) % SEQ_MODULUS)
            self._goto(KermitState.RECEIVE_FILE)
            self._progress(now)
            return
        if window.in_window(packet.seq):
            self._progress(now)
            window.hold(packet)
            ack_data = b""
            self._ack(packet.seq, ack_data)
            while not self.finished and (ready := window.pop_ready()) is not None:
                self._deliver(ready)
            if not self.finished and (gap := window.gap_to_nak()) is not None:
                window.naked(gap)
                self._nak(gap)
        elif window.in_previous(packet.seq):
            wire = self._acks.get(packet.seq)
            if wire is not None:
                self._resend(wire)  # our ACK was lost: say it again
            else:
                self._ack(packet.seq)
        # Outside both windows: a stray; ignored (C-Kermit chkwin()).

    def _progress(self, now: float) -> None:
        self._retries = 0
        self._deadline = now + self._timeout()

    def _deliver(self, packet: Packet) -> None:
        """Act on the next in-order packet."""
        ptype, state = packet.type, self._state
        if state is KermitState.RECEIVE_FILE and ptype == PacketType.FILE:
            self._name = self._decode(packet.data).decode("utf-8", "replace")
            self._size = None
            self._goto(KermitState.RECEIVE_DATA)
            self._events.append(FileStarted(self._name))
        elif state is KermitState.RECEIVE_FILE and ptype == PacketType.BREAK:
            self._goto(KermitState.DONE)
            self._deadline = None
            self._events.append(TransferComplete())
        elif state is KermitState.RECEIVE_DATA and ptype == PacketType.DATA:
            data = self._decode(packet.data)
            self._file_bytes += len(data)
            if data:
                self._events.append(FileData(data))
        elif state is KermitState.RECEIVE_DATA and ptype == PacketType.ATTRIBUTES:
            self._size = _attribute_size(self._decode(packet.data))
        elif state is KermitState.RECEIVE_DATA and ptype == PacketType.EOF:
            discarded = self._decode(packet.data)[:1] == b"D"
            self._files += 1
            self._goto(KermitState.RECEIVE_FILE)
            self._events.append(FileCompleted(self._name, discarded, self._size))
        elif ptype == PacketType.SEND_INIT:
            return  # a late S copy inside the window: its ACK was already sent
        else:
            raise RemoteProtocolError(
                f"unexpected {ptype!r} packet in state {state.value}",
                error_hint=f"Unexpected packet type {ptype}",
            )

    def _on_damage(self, now: float) -> None:
        if self._state is KermitState.RECEIVE_INIT:
            return  # nothing to NAK yet; the timer NAKs 0
        gap = self._window.gap_to_nak()
        if gap is None:
            gap = self._window.low
        else:
            self._window.naked(gap)
        self._nak(gap)

    def _on_timeout(self, now: float) -> None:
        self._deadline = now + self._timeout()
        if not self._count_retry():
            return
        self._window.forget_naks()
        self._nak(self._window.low)


def _prefix(c: int | None) -> str | None:
    return None if c is None else chr(c)


def _attribute_size(field: bytes) -> int | None:
    """The ``1`` (length in bytes) attribute of an A packet, if present and numeric."""
    i = 0
    while i + 1 < len(field):
        tag, n = field[i], field[i + 1] - 32
        value = field[i + 2 : i + 2 + max(n, 0)]
        if tag == ord("1") and value.isdigit():
            return int(value)
        i += 2 + max(n, 0)
    return None
