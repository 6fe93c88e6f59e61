"""Kermit file transfer, sans-I/O: the receiver (see :mod:`serialsocket.kermit._core`).

The states, their transition table, the events and the shared machinery
are in :mod:`serialsocket.kermit._core`; this module is the receiving role.
"""

from __future__ import annotations

from collections.abc import Callable

from serialsocket._errors import RemoteProtocolError
from serialsocket._packet import Packet
from serialsocket._wire import SEQ_MODULUS, PacketType

from ._attributes import (
    AttributeReply,
    FileAttributes,
    TextDecoder,
    encode_reply,
    local_form,
    parse_attributes,
)
from ._core import (
    _PLAIN,
    FileCompleted,
    FileData,
    FileStarted,
    KermitSide,
    KermitState,
    RemoteReply,
    TransferComplete,
)
from ._params import INIT_TIMEOUT, KermitConfig, line_timeout
from ._window import ReceiveWindow

AttributePolicy = Callable[[str, FileAttributes], AttributeReply]
"""Decides on an incoming file from its (stored) name and attributes: accept,
refuse, or -- for a RESEND -- say how many bytes are already held.  The
caller's code (it may look at the disk); the core only calls it."""


def accept_all(name: str, attributes: FileAttributes) -> AttributeReply:
    """The default policy: every file accepted, nothing held for a RESEND."""
    return AttributeReply(resume_from=0 if attributes.disposition == "R" else None)


__all__ = ["KermitReceiver"]


class KermitReceiver(KermitSide):
    """Receives a batch of files from a Kermit sender.

    Emits :class:`FileStarted`, :class:`FileData` (in order),
    :class:`FileCompleted` per file, then :class:`TransferComplete`; the
    caller stores the bytes.  File names arrive as the peer sent them,
    lower-cased when they came in upper case (unless ``literal_names``):
    the caller must sanitise them before using them as paths.  A file the A
    packet calls text has its CR LF record ends turned into LF.

    Args:
        config: local settings.
        now: the current time (starts the wait for S).
        policy: decides on each file from its A packet (see
            :data:`AttributePolicy`); default :func:`accept_all`.
        request: a client's request to a server, sent first (seq 0, type-1
            check) and again on each timeout until the answer comes: ``("R",
            filespec)`` for GET, ``("G", subcommand + arguments)`` for REMOTE
            commands.  The server answers with S (files, or screen text under
            an X header, received as usual) or with an ACK whose text ends the
            transaction (:class:`RemoteReply`, then :class:`TransferComplete`).
    """

    def __init__(
        self,
        config: KermitConfig,
        now: float,
        *,
        policy: AttributePolicy | None = None,
        request: tuple[str, bytes] | None = None,
    ) -> None:
        super().__init__(config, KermitState.RECEIVE_INIT)
        self._window = ReceiveWindow(1, 0)
        self._acks: dict[int, bytes] = {}  # last ACK sent per sequence number (bounded: 64)
        self._name = ""
        self._size: int | None = None
        self._policy = policy or accept_all
        self._text: TextDecoder | None = None
        self._attributes = FileAttributes()
        self._started = now
        self._request: bytes | None = None
        if request is not None:
            ptype, data = request
            field, _ = _PLAIN.encode_prefix(data, 90)
            self._request = self._emit(Packet(seq=0, type=ptype, data=field), init=True)
        self._deadline = now + self._timeout()

    @property
    def attributes(self) -> FileAttributes:
        """The current (or last) file's attributes, as its A packet gave them."""
        return self._attributes

    def _timeout(self) -> float:
        """Wait for the sender's packets: the line's time for a window of our
        longest packets, at least the peer's TIME (what it asked us to wait)."""
        config, neg = self.config, self._neg
        if config.timeout is not None:
            return config.timeout
        if neg is None:
            return max(INIT_TIMEOUT, self._mine.timeout)
        line = line_timeout(config.delay, config.rate, neg.window, config.max_packet_length)
        return max(line, neg.peer_time)

    def _error_seq(self) -> int:
        return self._window.low

    def _acknowledged_bytes(self) -> int:
        return self._file_bytes  # delivered in order = acknowledged (D is ACKed on arrival)

    def _ack(self, seq: int, data: bytes = b"", *, init: bool = False) -> None:
        self._acks[seq] = self._emit(Packet(seq=seq, type=PacketType.ACK, data=data), init=init)

    def _nak(self, seq: int) -> None:
        self._naks_sent += 1
        self._emit(Packet(seq=seq, type=PacketType.NAK))

    def _on_packet(self, packet: Packet, now: float) -> None:
        window = self._window
        if self._state is KermitState.RECEIVE_INIT:
            if self._request is not None and packet.type == PacketType.ACK and packet.seq == 0:
                # The server's short answer to our request (REMOTE CD, ...).
                self._events.append(RemoteReply(self._decode_text(packet.data)))
                self._goto(KermitState.DONE)
                self._deadline = None
                self._events.append(TransferComplete())
                return
            if packet.type != PacketType.SEND_INIT:
                return  # noise before the transfer, or a peer in another mode
            self._negotiate(packet.data)
            assert self._neg is not None
            self._ack(packet.seq, self._mine.encode(), init=True)
            self._window = ReceiveWindow(self._neg.window, (packet.seq + 1) % SEQ_MODULUS)
            self._goto(KermitState.RECEIVE_FILE)
            self._progress(now)
            return
        streaming = self._neg is not None and self._neg.streaming
        if streaming and packet.type == PacketType.DATA and packet.seq != window.low:
            # A reliable transport never loses or reorders: this is fatal (ckcfn2.c).
            self.abort(
                "Transmission error on reliable link",
                message=f"streaming: D {packet.seq} arrived, {window.low} expected",
            )
            return
        if window.in_window(packet.seq):
            self._progress(now)
            window.hold(packet)
            if packet.type == PacketType.DATA and not streaming:
                # "I have it": a D is ACKed on arrival, in or out of order.
                self._ack(packet.seq)
            # Anything else is ACKed in _deliver, once every packet before it
            # has arrived: the ACK of Z means "the whole file is here", of B
            # "the batch is done" (the sender then exits).  A Z that overtook
            # a missing D waits, unacknowledged, for the D's retransmission.
            while not self.finished and (ready := window.pop_ready()) is not None:
                reply = self._deliver(ready)
                if ready.type != PacketType.DATA and self._state is not KermitState.FAILED:
                    self._ack(ready.seq, reply)
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

    def _deliver(self, packet: Packet) -> bytes:
        """Act on the next in-order packet; returns the data for its ACK."""
        ptype, state = packet.type, self._state
        if state is KermitState.RECEIVE_FILE and ptype in (PacketType.FILE, PacketType.TEXT):
            name = self._decode(packet.data).decode("utf-8", "replace")
            screen = ptype == PacketType.TEXT
            self._name = name if self.config.literal_names or screen else local_form(name)
            self._size = None
            self._text = None
            self._attributes = FileAttributes()
            self._goto(KermitState.RECEIVE_DATA)
            self._events.append(FileStarted(self._name, screen=screen))
        elif state is KermitState.RECEIVE_FILE and ptype == PacketType.BREAK:
            self._goto(KermitState.DONE)
            self._deadline = None
            self._events.append(TransferComplete())
        elif state is KermitState.RECEIVE_DATA and ptype == PacketType.DATA:
            data = self._decode(packet.data)
            self._file_bytes += len(data)
            if self._text is not None:
                data = self._text.feed(data)
            if data:
                self._events.append(FileData(data))
        elif state is KermitState.RECEIVE_DATA and ptype == PacketType.ATTRIBUTES:
            # Literal, not prefix-decoded: C-Kermit's sattr() sends the field
            # as built and gattr() reads it so (a length of 3 is tochar(3) = '#').
            return self._on_attributes(parse_attributes(packet.data))
        elif state is KermitState.RECEIVE_DATA and ptype == PacketType.EOF:
            discarded = self._decode(packet.data)[:1] == b"D"
            if self._text is not None and (tail := self._text.flush()):
                self._events.append(FileData(tail))
            self._files += 1
            self._goto(KermitState.RECEIVE_FILE)
            self._events.append(FileCompleted(self._name, discarded, self._size))
        elif ptype == PacketType.SEND_INIT:
            pass  # a late S copy inside the window: its ACK was already sent
        else:
            raise RemoteProtocolError(
                f"unexpected {ptype!r} packet in state {state.value}",
                error_hint=f"Unexpected packet type {ptype}",
            )
        return b""

    def _on_attributes(self, attributes: FileAttributes) -> bytes:
        """The A packet: ask the policy, and answer as C-Kermit's gattr() does."""
        assert self._neg is not None
        self._attributes = attributes
        self._size = attributes.size
        if attributes.disposition not in (None, "R"):
            return encode_reply(AttributeReply(refuse="+"))  # mail, print: not here
        if attributes.disposition == "R" and (attributes.text or not self._neg.recovery):
            return encode_reply(AttributeReply(refuse="+"))  # RESEND is binary only
        reply = self._policy(self._name, attributes)
        if not reply.refuse:
            if attributes.text:
                self._text = TextDecoder()
            if attributes.disposition == "R":
                held = reply.resume_from or 0
                self._resumed += held
                reply = AttributeReply(resume_from=held)
            else:
                reply = AttributeReply()
        return encode_reply(reply)

    def _on_damage(self, now: float) -> None:
        if self._state is KermitState.RECEIVE_INIT:
            return  # nothing to NAK yet; the timer NAKs 0
        if self._neg is not None and self._neg.streaming:
            self.abort("Transmission error on reliable link")
            return
        gap = self._window.gap_to_nak()
        if gap is None:
            gap = self._window.low
        else:
            self._window.naked(gap)
        self._nak(gap)

    def _on_timeout(self, now: float) -> None:
        self._deadline = now + self._timeout()
        self._retries += 1
        limit = self._retry_limit()
        if limit and self._retries > limit:
            what = (
                "S never arrived"
                if self._state is KermitState.RECEIVE_INIT
                else f"packet {self._window.low} never arrived"
            )
            self._give_up(what, self._retries, now)
            return
        if self._request is not None and self._state is KermitState.RECEIVE_INIT:
            self._resend(self._request)  # the request or its answer was lost
            return
        if self._neg is not None and self._neg.streaming:
            return  # no NAKs while streaming: the sender takes one as fatal
        self._window.forget_naks()
        self._nak(self._window.low)
