"""Kermit file transfer, sans-I/O: states, transition table, events, shared core.

The two roles are :class:`~serialsocket.kermit.KermitSender` (``_sender.py``)
and :class:`~serialsocket.kermit.KermitReceiver` (``_receiver.py``); both
subclass :class:`KermitSide` below, and every state change of either goes
through :data:`TRANSITIONS`.

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
  timeout.  With window 1 a NAK for the packet after the last one sent means
  that one was received (NAK(n+1) = ACK(n)), except while waiting for the ACK
  of S.  With windows a NAK acknowledges nothing: C-Kermit NAKs sequence
  numbers beyond a packet it still misses, so a NAK of a packet not sent yet
  resends window-low.  Z goes out only once every D is acknowledged, and B
  once Z is; success means every Z was acknowledged.  When
  an ACK arrives for a packet whose every copy was sent after window-low's
  last copy, window-low is resent at once: the line keeps order, so that copy
  or its ACK was lost, and waiting for a timeout would stall the window for
  seconds on a delayed link.  (This generalises the 1985 windowing draft's
  heuristic, which did it once, for a packet never resent.)
* The receiver ACKs every in-window D packet on arrival, buffers out-of-order
  ones, NAKs the oldest gap not NAKed yet, re-ACKs duplicates from the
  previous window, and on a timeout or a damaged packet NAKs window-low.
  Every other packet (F, A, Z, B) is ACKed only when it is acted on, in
  order: the ACK of Z says the whole file arrived, so it never goes out
  while a D before it is missing.
* Each packet may be retried ``retry_limit`` times (0 = forever); then the
  side sends ``E`` "Too many retries" and fails.
"""

from __future__ import annotations

import abc
import enum
import logging
from collections import deque
from dataclasses import dataclass
from typing import Protocol

from serialsocket._checks import BlockCheck
from serialsocket._encoding import Encoding
from serialsocket._errors import LocalProtocolError, MalformedDataError, RemoteProtocolError
from serialsocket._packet import Packet, build_packet
from serialsocket._parser import PacketParser, PacketReceived, PacketRejected, RejectReason
from serialsocket._wire import CR, MAX_PACKET_LENGTH, PacketType

from ._params import (
    INIT_TIMEOUT,
    KermitConfig,
    KermitInit,
    KermitNegotiated,
    negotiate_kermit,
)

__all__ = [
    "FileCompleted",
    "FileData",
    "FileStarted",
    "KermitEvent",
    "KermitSide",
    "KermitState",
    "KermitStatistics",
    "OutgoingFile",
    "RemoteReply",
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
    """Receiver: waiting for S (a client: its R or G request sent, waiting for S or the ACK)."""
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
    _S.RECEIVE_INIT: frozenset({_S.RECEIVE_FILE, _S.DONE, _S.FAILED}),
    _S.RECEIVE_FILE: frozenset({_S.RECEIVE_DATA, _S.DONE, _S.FAILED}),
    _S.RECEIVE_DATA: frozenset({_S.RECEIVE_FILE, _S.FAILED}),
    _S.DONE: frozenset(),
    _S.FAILED: frozenset(),
}
"""Every legal state change, in one table; anything else raises LocalProtocolError."""


class Readable(Protocol):
    """What the sender reads file contents from (a binary file, ``io.BytesIO``).

    ``seek`` is used only when a RESEND starts part-way into the file.
    """

    def read(self, size: int, /) -> bytes: ...

    def seek(self, offset: int, /) -> int: ...


@dataclass(frozen=True, slots=True)
class OutgoingFile:
    """A file to send: its name, its size if known, its bytes, and its date.

    ``date`` is the modification time as the A packet carries it,
    ``yyyymmdd hh:mm:ss`` (the caller formats it: the core reads no clock).
    ``screen``: text for the other side's screen (a server's reply to REMOTE
    DIR): sent with an X header instead of F, without attributes.
    """

    name: str
    size: int | None
    source: Readable
    date: str | None = None
    screen: bool = False


@dataclass(frozen=True, slots=True)
class FileStarted:
    """A file began (F packet); ``size`` comes from the A packet, when one is sent later.

    ``screen``: an X header -- text for the screen (a server's reply), not a file.
    """

    name: str
    screen: bool = False


@dataclass(frozen=True, slots=True)
class RemoteReply:
    """A server answered a client's request with a short text in its ACK (client only)."""

    text: str


@dataclass(frozen=True, slots=True)
class FileData:
    """Received file bytes, in order (receiver only)."""

    data: bytes


@dataclass(frozen=True, slots=True)
class FileCompleted:
    """A file ended (Z acknowledged); ``discarded`` when the sender cancelled it (Z ``D``).

    ``size`` is the length the A packet announced, if any (receiver only);
    ``reason`` says why the receiver refused the file (sender only: the
    refused attributes in words, e.g. ``size: it does not fit``).
    """

    name: str
    discarded: bool
    size: int | None = None
    reason: str | None = None


@dataclass(frozen=True, slots=True)
class TransferComplete:
    """The batch ended normally: every file's Z was acknowledged and B was sent.

    A receiver ACKs Z only once it holds every byte of the file (C-Kermit
    after closing it), so every file is confirmed, whole, by then.

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


KermitEvent = (
    FileStarted | FileData | FileCompleted | RemoteReply | TransferComplete | TransferFailed
)


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
        acknowledged_bytes: file bytes the receiver has acknowledged in
            order, every file counted (sender); file bytes delivered in
            order and acknowledged (receiver: the same as ``file_bytes``).
        packets_sent, packets_received: packets, retransmissions included.
        retransmissions: packets sent again.
        naks_sent, naks_received: NAK packets.
        timeouts: timer expiries.
        damaged: packets the parser rejected (a MARK followed by a bad
            length, header or check, or cut short).
        noise_bytes: bytes outside any packet (line noise, a stray byte
            before the first packet, a packet whose MARK was hit): ignored,
            as C-Kermit's rpack() skips to the next MARK; not a damaged
            packet and never answered with a NAK.
        bytes_sent, bytes_received: line bytes.
        eighth_bit_prefix: the agreed 8th-bit prefix (``&``), or None when
            8-bit bytes travel raw (or before the exchange).
        repeat_prefix: the agreed repeat prefix (``~``), or None.
        timeout: the timeout in force, s.
        data_packet_length: the length of the D packets being sent now
            (sender; it follows the measured error rate), else
            ``packet_length``.
        resumed_bytes: bytes the receiver already held when files were
            resent (recovery), all files counted: acknowledged, never sent.
    """

    state: KermitState
    window: int
    packet_length: int
    check: BlockCheck
    files: int
    file_bytes: int
    acknowledged_bytes: int
    packets_sent: int
    packets_received: int
    retransmissions: int
    naks_sent: int
    naks_received: int
    timeouts: int
    damaged: int
    noise_bytes: int
    bytes_sent: int
    bytes_received: int
    eighth_bit_prefix: str | None
    repeat_prefix: str | None
    timeout: float
    data_packet_length: int
    resumed_bytes: int


class KermitSide(abc.ABC):
    """What both roles share: parser, output buffer, events, E packets, counters.

    Not used directly: :class:`~serialsocket.kermit.KermitSender` (``_sender``)
    and :class:`~serialsocket.kermit.KermitReceiver` (``_receiver``) subclass it.
    """

    def __init__(self, config: KermitConfig, state: KermitState) -> None:
        self.config = config
        self._state = state
        self._mine = KermitInit.mine(config)
        self._neg: KermitNegotiated | None = None
        self._init_check = BlockCheck.CRC16 if config.force3 else BlockCheck.SUM6
        """Check on S and its ACK: type 1, or CRC-16 under FORCE-3."""
        self._parser = PacketParser(
            max_length=min(max(config.max_packet_length, 96) + _PARSER_SLACK, MAX_PACKET_LENGTH),
            check=self._init_check,
            init_check=self._init_check,
        )
        self._out = bytearray()
        self._events: deque[KermitEvent] = deque()
        self._deadline: float | None = None
        self._retries = 0
        self._files = 0
        self._file_bytes = 0
        self._sent = self._received = self._retransmissions = 0
        self._naks_sent = self._naks_received = self._timeouts = self._damaged = 0
        self._noise = 0
        self._bytes_sent = self._bytes_received = 0
        self._heard = False  # a good packet has arrived from the peer
        self._started = 0.0  # when the machine was made (for "no answer at all")
        self._resumed = 0  # bytes held by the receiver before a RESEND, all files

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
                event = self._force3_init(event) or event
            if not isinstance(event, PacketReceived):
                if event.reason is RejectReason.GARBAGE:
                    # Bytes outside any packet: a stray byte before the first
                    # packet, line noise, a packet whose MARK was hit.  C-Kermit
                    # skips them looking for the next MARK; so do we (a lost
                    # packet shows up as a gap or a timeout).
                    self._noise += event.length
                    continue
                self._damaged += 1
                if log.isEnabledFor(logging.DEBUG):
                    log.debug("%.3f <- damaged: %s %r", now, event.reason.value, event.raw[:12])
                self._on_damage(now)
                continue
            self._received += 1
            self._heard = True
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

    def _force3_init(self, event: PacketRejected) -> PacketReceived | None:
        """An S or I whose type-1 check failed may carry a CRC-16 (FORCE-3).

        C-Kermit reads CHKT before checking an init packet (ckcfn2.c rpack);
        here the rejected bytes are read again with CRC-16 on init packets.
        If that verifies, the peer is in FORCE-3 and so are we from now on:
        our ACK of it carries a CRC-16 too.
        """
        if (
            self._neg is not None
            or self._init_check is BlockCheck.CRC16
            or event.reason is not RejectReason.BAD_CHECK
            or event.type not in (PacketType.SEND_INIT, PacketType.INIT)
        ):
            return None
        parser = PacketParser(
            max_length=self._parser.max_length,
            check=BlockCheck.CRC16,
            init_check=BlockCheck.CRC16,
        )
        parser.receive_data(event.raw)
        got = parser.next_event()
        if not isinstance(got, PacketReceived):
            return None
        self._init_check = BlockCheck.CRC16
        self._parser.init_check = self._parser.check = BlockCheck.CRC16
        return got

    def handle_timer(self, now: float) -> None:
        """Call at :meth:`get_timer`'s time: resend or NAK, or give up."""
        if self.finished or self._deadline is None or now < self._deadline:
            return
        self._timeouts += 1
        self._on_timeout(now)

    def abort(self, reason: str, *, message: str | None = None) -> None:
        """Stop the transfer now: send E with ``reason`` and fail (local cancel, bad data).

        Bytes not yet taken by :meth:`data_to_send` are dropped first: an ACK
        still waiting there must not confirm what the caller failed to store
        (the ACK of Z for a file that could not be written).
        """
        if self.finished:
            return
        self._out.clear()
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
            acknowledged_bytes=self._acknowledged_bytes(),
            packets_sent=self._sent,
            packets_received=self._received,
            retransmissions=self._retransmissions,
            naks_sent=self._naks_sent,
            naks_received=self._naks_received,
            timeouts=self._timeouts,
            damaged=self._damaged,
            noise_bytes=self._noise,
            bytes_sent=self._bytes_sent,
            bytes_received=self._bytes_received,
            eighth_bit_prefix=_prefix(neg.send_encoding.qbin if neg else None),
            repeat_prefix=_prefix(neg.send_encoding.rept if neg else None),
            timeout=self._timeout(),
            data_packet_length=self._data_packet_length(),
            resumed_bytes=self._resumed,
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
        """The timeout in force (roles refine it: the sender measures round trips)."""
        if self._neg is not None:
            return self._neg.timeout
        if self.config.timeout is not None:
            return self.config.timeout
        return max(INIT_TIMEOUT, self._mine.timeout)

    def _data_packet_length(self) -> int:
        return self._neg.send_max_length if self._neg else 96

    def _retry_limit(self) -> int:
        return self._neg.retry_limit if self._neg else self.config.retry_limit

    def _emit(self, packet: Packet, *, init: bool = False) -> bytes:
        """Append a packet to the output; returns its wire bytes."""
        neg = self._neg
        if neg is None or init:
            wire = build_packet(packet, self._init_check, eol=CR)
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

    def _give_up(self, what: str, tries: int, now: float) -> None:
        """Send E "Too many retries" and fail, saying what failed and how."""
        if not self._heard:
            message = (
                f"no answer at all: nothing came back from the peer in {now - self._started:.0f} s "
                f"({what}, {tries} tries); is the other side running, on this line and rate?"
            )
        else:
            message = f"too many retries: {what}, after {tries} tries"
        self.abort("Too many retries", message=message)

    def _negotiate(self, theirs: bytes) -> None:
        peer = KermitInit.decode(theirs)
        neg = negotiate_kermit(self.config, self._mine, peer)
        self._neg = neg
        self._parser.check = neg.check

    # -- role hooks -------------------------------------------------------------

    @abc.abstractmethod
    def _on_packet(self, packet: Packet, now: float) -> None:
        """Role hook: each side implements it."""

    @abc.abstractmethod
    def _on_damage(self, now: float) -> None:
        """Role hook: each side implements it."""

    @abc.abstractmethod
    def _on_timeout(self, now: float) -> None:
        """Role hook: each side implements it."""

    @abc.abstractmethod
    def _error_seq(self) -> int:
        """Role hook: each side implements it."""

    @abc.abstractmethod
    def _acknowledged_bytes(self) -> int:
        """Role hook: file bytes acknowledged in order (see :class:`KermitStatistics`)."""


def _prefix(c: int | None) -> str | None:
    return None if c is None else chr(c)
