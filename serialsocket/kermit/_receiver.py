"""Kermit file transfer, sans-I/O: the receiver (see :mod:`serialsocket.kermit._core`).

The states, their transition table, the events and the shared machinery
are in :mod:`serialsocket.kermit._core`; this module is the receiving role.
"""

from __future__ import annotations

from serialsocket._errors import RemoteProtocolError
from serialsocket._packet import Packet
from serialsocket._wire import SEQ_MODULUS, PacketType

from ._core import (
    FileCompleted,
    FileData,
    FileStarted,
    KermitSide,
    KermitState,
    TransferComplete,
)
from ._params import KermitConfig
from ._window import ReceiveWindow

__all__ = ["KermitReceiver"]


class KermitReceiver(KermitSide):
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
            if packet.type == PacketType.DATA:
                # "I have it": a D is ACKed on arrival, in or out of order.
                self._ack(packet.seq)
            # Anything else is ACKed in _deliver, once every packet before it
            # has arrived: the ACK of Z means "the whole file is here", of B
            # "the batch is done" (the sender then exits).  A Z that overtook
            # a missing D waits, unacknowledged, for the D's retransmission.
            while not self.finished and (ready := window.pop_ready()) is not None:
                if ready.type != PacketType.DATA:
                    self._ack(ready.seq)
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
