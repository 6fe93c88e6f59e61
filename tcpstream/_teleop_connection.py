"""The teleoperation channel's sans-I/O ends (PROTOCOL.md section 14).

:class:`OperatorChannel` is the hand controller's end, :class:`ArmChannel` the
arm's.  Both take ``receive_data(data, now)`` and hand out
``data_to_send()`` and events; neither reads a clock or touches a stream.

Latest value, both ways: the operator end holds at most one unsent sample (a
newer one replaces it: *coalesced*), the arm end at most one unread sample and
one unsent reply.  Nothing waits in a queue that grows; what is not worth
sending any more is never sent.

Rate adaptation (:meth:`OperatorChannel.poll`): a sample leaves only when the
transport can put it on the wire at once -- its own figures say nothing of ours
is still waiting (:class:`Backlog`, e.g. a serial socket's ``bytes_queued`` and
``line_backlog``) -- and, when the transport has no figures (TCP), while the
bytes in flight stay within twice the delivery rate times the smallest round
trip the replies have shown (a bandwidth-delay product; 16 samples before the
first measurement).  A STOP bypasses both, and is repeated (:data:`STOP_REPEAT`)
until a REPLY says STOPPED: after a STOP the operator sends nothing else, so
without a copy behind it a lost STOP waits for the transport's retransmission
timer instead of being NAKed when the next packet shows the gap.

The transport's latest-value lane (:meth:`_End.use_lane`, PROTOCOL.md 14.8):
when the stream has one (a serial socket between telelink ends), SAMPLE and
REPLY packets go there instead of into the stream -- each behind the first
four bytes of the operator's HELLO nonce, which name the channel -- so a
lost sample never holds a newer one at the receiver; everything else stays on
the stream.  :meth:`_End.lane_to_send` hands out the packet for the lane and
:meth:`_End.receive_lane` takes one from it.
"""

from __future__ import annotations

import abc
import hmac
import struct
from collections import deque

from ._teleop_packet import (
    HEADER_SIZE,
    MAGIC,
    TAG_SIZE,
    UNTAGGED,
    Reply,
    ReplyStatus,
    Sample,
    TeleopKind,
    TeleopPacketError,
    channel_key,
    client_proof,
    decode_header,
    decode_reply,
    decode_sample,
    encode_reply,
    encode_sample,
    server_proof,
    sign,
    size_of,
    tag_for,
)
from ._teleop_state import (
    TRANSITIONS,
    Backlog,
    ChannelClosed,
    ChannelState,
    ChannelStatistics,
    Granted,
    IllegalTransition,
    OperatorArrived,
    RefuseCode,
    Refused,
    ReplyReceived,
    SampleArrived,
    StopArrived,
    TeleopEvent,
)

__all__ = ["ArmChannel", "OperatorChannel"]

TO_ARM = b"\x11"
"""Direction byte bound into operator -> arm tags (not the command session's 0x01)."""
TO_OPERATOR = b"\x12"
LANE_PREFIX = 4
"""Bytes of the operator's HELLO nonce ahead of each packet on the latest-value
lane: a value of an earlier channel on the same line (a resend still in flight
when a new channel opened) is told apart and dropped."""
GARBAGE_LIMIT = 8
"""Rejected packets in a row that end the channel: as the command session (section 10)."""
MAX_PACKET = max(size_of(k) for k in TeleopKind)
INITIAL_WINDOW = 16
"""Samples in flight before any reply measured the path: 0.15 s of a 104 Hz loop."""
MIN_WINDOW = 4
"""Never fewer samples in flight than this, whatever the measurement said."""
_RATE_SAMPLES = 16
"""Delivery-rate samples the window's rate is the maximum of: a few round trips of replies."""
_RTT_HISTORY = 64
"""Samples remembered for matching replies to send times: at least the window."""
STOP_REPEAT = 0.25
"""s: the least time between copies of a STOP (each also waits for an idle line, so
each is a packet of its own on the transport): a copy arrives about one STOP's line
time after the one before, and the first that arrives shows a lost one as a gap."""
MAX_STOP_COPIES = 8
"""Copies of a STOP sent after the first, at most (bounded whatever the arm says):
2 s of copies at :data:`STOP_REPEAT`, enough that a burst destroying a few of them
still leaves one to reveal the loss; 8 x 24 bytes, 0.8 s of a 2400 bit/s line."""


class _End(abc.ABC):
    """What both ends share: the reader, the tags, the counters, the statistics."""

    _tx_dir: bytes
    _rx_dir: bytes

    def __init__(self, key: bytes | None, state: ChannelState) -> None:
        self._psk = key
        self._key: bytes | None = None  # the channel key, once derived
        self._state = state
        self._buf = bytearray()
        self._out = bytearray()
        self._tx_counter = 0
        self._rx_counter = 0
        self._bad_in_row = 0
        self._lane = False
        self._lane_out: bytes | None = None
        self._stats: dict[str, int] = dict.fromkeys(
            (
                "packets_in packets_out bytes_in bytes_out bad_packets tag_failures replays "
                "resyncs samples_offered samples_sent samples_coalesced samples_received "
                "samples_superseded replies_sent replies_coalesced replies_received stops_sent "
                "stops_received stops_repeated held_by_backlog held_by_window samples_after_stop "
                "lane_packets_in lane_packets_out lane_stale lane_replaced"
            ).split(),
            0,
        )

    @property
    def state(self) -> ChannelState:
        return self._state

    def _go(self, new: ChannelState) -> None:
        if (self._state, new) not in TRANSITIONS:
            raise IllegalTransition(f"{self._state.value} -> {new.value}")
        self._state = new

    def _send(self, kind: TeleopKind, body: bytes) -> None:
        self._tx_counter += 1
        self._emit(sign(kind, self._tx_counter, body, self._key, self._tx_dir))

    def _emit(self, raw: bytes) -> None:
        self._out += raw
        self._stats["packets_out"] += 1
        self._stats["bytes_out"] += len(raw)

    def data_to_send(self) -> bytes:
        out = bytes(self._out)
        self._out.clear()
        return out

    # -- the transport's latest-value lane --------------------------------------------

    def use_lane(self) -> None:
        """The stream has a latest-value lane: send SAMPLE (REPLY) packets there."""
        self._lane = True

    @property
    def lane(self) -> bool:
        return self._lane

    @abc.abstractmethod
    def _lane_prefix(self) -> bytes | None:
        """The channel's name on the lane (None before the HELLO)."""

    def _emit_value(self, raw: bytes) -> None:
        """A SAMPLE or REPLY: on the lane when there is one, else on the stream."""
        prefix = self._lane_prefix()
        if not self._lane or prefix is None:
            self._emit(raw)
            return
        self._lane_out = prefix + raw  # the poll rule sends one only when the last has left
        self._stats["packets_out"] += 1
        self._stats["lane_packets_out"] += 1
        self._stats["bytes_out"] += len(raw)

    def lane_refused(self, message: bytes) -> None:
        """The transport would not take ``message`` (from :meth:`lane_to_send`)
        on its lane: send it, and every later one, on the stream."""
        self._lane = False
        self._stats["lane_packets_out"] -= 1
        self._out += message[LANE_PREFIX:]

    def lane_replaced(self) -> None:
        """The lane message last handed out replaced one the transport had not
        yet put on the line: that one was never sent after all."""
        self._stats["lane_replaced"] += 1
        self._stats[self._lane_sent] -= 1
        self._stats[self._lane_coalesced] += 1

    def lane_to_send(self) -> bytes | None:
        """The message for the transport's latest-value lane, or None."""
        out, self._lane_out = self._lane_out, None
        return out

    def receive_lane(self, message: bytes, now: float) -> list[TeleopEvent]:
        """One message from the transport's latest-value lane: a whole SAMPLE
        (at the arm) or REPLY (at the operator) behind this channel's prefix.

        Taken only while the channel is OPEN.  A message of another channel or
        one overtaken by a packet already taken (its counter is not above the
        last: the stream and the lane share one counter) is dropped and
        counted (``lane_stale``); a malformed one is a bad packet.
        """
        self._stats["bytes_in"] += len(message)
        prefix = self._lane_prefix()
        if self._state is not ChannelState.OPEN or prefix is None:
            self._stats["lane_stale"] += 1
            return []
        if message[:LANE_PREFIX] != prefix:
            self._stats["lane_stale"] += 1
            return []
        raw = message[LANE_PREFIX:]
        try:
            kind, counter, size = decode_header(raw)
        except TeleopPacketError:
            return self._bad("lane header")
        if size != len(raw) or kind is not self._lane_kind:
            return self._bad("lane packet")
        self._stats["packets_in"] += 1
        self._stats["lane_packets_in"] += 1
        if counter <= self._rx_counter:
            # Overtaken, not replayed: a packet with a higher counter came first
            # (a STOP on the stream after this sample); nothing to punish.
            self._stats["lane_stale"] += 1
            return []
        return self._packet(kind, counter, raw, now)

    _lane_kind: TeleopKind
    _lane_sent: str
    _lane_coalesced: str

    def close(self, reason: RefuseCode = RefuseCode.NORMAL) -> list[TeleopEvent]:
        """Send BYE and close (idempotent)."""
        if self._state is ChannelState.CLOSED:
            return []
        if self._key is not None or self._psk is None:
            self._send(TeleopKind.BYE, bytes([reason]) + bytes(7))
        self._go(ChannelState.CLOSED)
        return [ChannelClosed(reason, by_peer=False)]

    def _bad(self, what: str, *, counter: str = "bad_packets") -> list[TeleopEvent]:
        self._stats[counter] += 1
        self._bad_in_row += 1
        if self._bad_in_row >= GARBAGE_LIMIT and self._state is not ChannelState.CLOSED:
            return self.close(RefuseCode.GARBAGE)
        return []

    def receive_data(self, data: bytes, now: float) -> list[TeleopEvent]:
        """Feed bytes from the stream; returns what they meant.  Bad packets are counted."""
        events: list[TeleopEvent] = []
        self._stats["bytes_in"] += len(data)
        if self._closed():
            return events  # a closed channel reads nothing more, so it keeps nothing
        self._buf += data
        while not self._closed() and len(self._buf) >= HEADER_SIZE:
            try:
                kind, counter, size = decode_header(self._buf)
            except TeleopPacketError:
                # Framing lost: skip to the next possible magic, one bad packet per attempt.
                self._stats["resyncs"] += 1
                at = self._buf.find(MAGIC, 1)
                if at < 0:
                    keep = 1 if self._buf.endswith(MAGIC[:1]) else 0
                    del self._buf[: len(self._buf) - keep]
                else:
                    del self._buf[:at]
                events += self._bad("framing")
                continue
            if len(self._buf) < size:
                break
            raw = bytes(self._buf[:size])
            del self._buf[:size]
            self._stats["packets_in"] += 1
            events += self._packet(kind, counter, raw, now)
        if self._closed():
            self._buf.clear()  # bytes behind the packet that closed it are nobody's
        return events

    def _closed(self) -> bool:
        return self._state is ChannelState.CLOSED

    def _packet(self, kind: TeleopKind, counter: int, raw: bytes, now: float) -> list[TeleopEvent]:
        if kind not in UNTAGGED and self._key is not None:
            if not _verify(tag_for(self._key, self._rx_dir, raw[:-TAG_SIZE]), raw[-TAG_SIZE:]):
                return self._tag_failed()
        elif kind not in UNTAGGED and self._psk is not None:
            return self._tag_failed()  # a tagged packet before the key: a downgrade
        if counter <= self._rx_counter:
            return self._bad("replay", counter="replays")
        try:
            events = self._dispatch(kind, raw, now)
        except TeleopPacketError:
            return self._bad("field")
        self._rx_counter = counter
        self._bad_in_row = 0
        return events

    @abc.abstractmethod
    def _dispatch(self, kind: TeleopKind, raw: bytes, now: float) -> list[TeleopEvent]:
        """Decode and apply one authenticated packet of this end's kinds."""

    def _tag_failed(self) -> list[TeleopEvent]:
        if self._state is ChannelState.OPEN:
            return self._bad("tag", counter="tag_failures")
        # In the handshake a wrong tag is a wrong key: the same answer as a wrong proof.
        self._stats["tag_failures"] += 1
        return self._handshake_failed()

    def _handshake_failed(self) -> list[TeleopEvent]:
        return self.close(RefuseCode.NOT_AUTHORIZED)

    def _peer_bye(self, raw: bytes) -> list[TeleopEvent]:
        try:
            reason = RefuseCode(raw[HEADER_SIZE])
        except ValueError:
            reason = RefuseCode.NORMAL
        self._go(ChannelState.CLOSED)
        return [ChannelClosed(reason, by_peer=True)]

    def _common_statistics(self) -> dict[str, int]:
        return dict(self._stats)


def _verify(expected: bytes, received: bytes) -> bool:
    return hmac.compare_digest(expected, received)


_IDENTITY_SIZE = 32
_NONCE_SIZE = 16
_GRANT_TAIL = struct.Struct("!ff")


def _identity_bytes(identity: str) -> bytes:
    raw = identity.encode("utf-8")
    if not 1 <= len(raw) <= _IDENTITY_SIZE or b"\0" in raw:
        raise ValueError("identity must be 1..32 bytes of UTF-8 without NUL")
    return raw.ljust(_IDENTITY_SIZE, b"\0")


class OperatorChannel(_End):
    """The hand controller's end: HELLO, then samples out and replies in.

    Args:
        identity: who operates (1..32 bytes of UTF-8), the same label as the
            command session's.
        key: the pre-shared key (the command session's), or None.
        nonce: 16 fresh random bytes (``secrets.token_bytes(16)``; a seeded
            source in tests).
    """

    _tx_dir = TO_ARM
    _rx_dir = TO_OPERATOR
    _lane_kind = TeleopKind.REPLY
    _lane_sent = "samples_sent"
    _lane_coalesced = "samples_coalesced"

    def __init__(self, identity: str, key: bytes | None, nonce: bytes) -> None:
        super().__init__(key, ChannelState.IDLE)
        if len(nonce) != _NONCE_SIZE:
            raise ValueError("nonce must be 16 bytes")
        self._identity = _identity_bytes(identity)
        self._nonce = nonce
        self._server_nonce = b""
        self._pending: Sample | None = None
        self._stopped = False  # after STOP no sample is sent on this channel
        self._stop_last: float | None = None  # when the STOP or its last copy was queued
        self._stop_copies = 0
        self.stop_confirmed = False
        """A REPLY said STOPPED after our STOP: no more copies."""
        self.granted: Granted | None = None
        # Rate adaptation: (sample number, cumulative bytes sent, send time).
        self._sent: deque[tuple[int, int, float]] = deque(maxlen=_RTT_HISTORY)
        self._bytes_sent_samples = 0
        self._bytes_acked = 0
        self._acked_sample = 0
        self._last_ack: tuple[float, int] | None = None
        self._rate: float | None = None  # bytes/s delivered: the most of the recent samples
        self._rates: deque[float] = deque(maxlen=_RATE_SAMPLES)
        self._min_rtt: float | None = None
        self.last_reply: Reply | None = None

    def _lane_prefix(self) -> bytes | None:
        return self._nonce[:LANE_PREFIX]

    def connect(self) -> None:
        """Queue the HELLO."""
        self._go(ChannelState.HELLO_SENT)
        self._send(TeleopKind.HELLO, self._identity + self._nonce)

    # -- samples out ----------------------------------------------------------------

    def offer(self, sample: Sample) -> None:
        """The newest sample: it replaces one not yet sent (latest value)."""
        self._stats["samples_offered"] += 1
        if self._stopped:
            self._stats["samples_after_stop"] += 1
            return
        if self._pending is not None:
            self._stats["samples_coalesced"] += 1
        self._pending = sample

    @property
    def pending(self) -> Sample | None:
        return self._pending

    def emergency_stop(self) -> None:
        """Queue a STOP now, ahead of any sample not yet sent (and drop that sample)."""
        if self._state is not ChannelState.OPEN:
            raise IllegalTransition(f"STOP in state {self._state.value}")
        if self._pending is not None:
            self._stats["samples_coalesced"] += 1  # overtaken by the STOP
        self._pending = None
        self._stopped = True
        self._stats["stops_sent"] += 1
        self._send(TeleopKind.STOP, bytes(8))

    @property
    def repeating_stop(self) -> bool:
        """A STOP is out, not yet confirmed by a REPLY, and copies remain to be sent
        (the loop around this end keeps polling while so)."""
        return (
            self._stopped
            and not self.stop_confirmed
            and self._stop_copies < MAX_STOP_COPIES
            and self._state is ChannelState.OPEN
        )

    def _repeat_stop(self, now: float, backlog: Backlog | None) -> bool:
        """Queue the next copy of the STOP if it is due and the line is idle."""
        if self._stop_last is None:
            self._stop_last = now  # the first poll after the STOP: it has just been queued
            return False
        # With the transport's figures the first copy goes as soon as the STOP has left
        # (the line idle again): then it is a packet of its own, and the earliest
        # possible witness of a loss.  Without them (TCP) every copy waits the interval.
        first = self._stop_copies == 0 and backlog is not None
        if not first and now - self._stop_last < STOP_REPEAT:
            return False
        if backlog is not None and (backlog.queued_bytes > 0 or backlog.line_seconds > 0.0):
            return False  # behind other bytes it would share their packet: wait for the line
        self._stop_last = now
        self._stop_copies += 1
        self._stats["stops_repeated"] += 1
        self._send(TeleopKind.STOP, bytes(8))
        return True

    def window_bytes(self) -> float:
        """Bytes the path may hold in flight (without transport figures)."""
        size = size_of(TeleopKind.SAMPLE)
        if self._rate is None or self._min_rtt is None:
            return float(INITIAL_WINDOW * size)
        return max(float(MIN_WINDOW * size), 2.0 * self._rate * self._min_rtt)

    def in_flight_bytes(self) -> int:
        return self._bytes_sent_samples - self._bytes_acked

    def poll(self, now: float, backlog: Backlog | None = None) -> bool:
        """Send the pending sample (or a due copy of the STOP) if the line can take it
        now; True if something went."""
        if self.repeating_stop:
            return self._repeat_stop(now, backlog)
        if self._state is not ChannelState.OPEN or self._pending is None:
            return False
        if backlog is not None:
            if backlog.queued_bytes > 0 or backlog.line_seconds > 0.0:
                self._stats["held_by_backlog"] += 1
                return False
        elif self.in_flight_bytes() + size_of(TeleopKind.SAMPLE) > self.window_bytes():
            self._stats["held_by_window"] += 1
            return False
        sample, self._pending = self._pending, None
        self._tx_counter += 1
        raw = encode_sample(sample, self._tx_counter, self._key, TO_ARM)
        self._emit_value(raw)
        self._stats["samples_sent"] += 1
        self._bytes_sent_samples += len(raw)
        self._sent.append((sample.sample, self._bytes_sent_samples, now))
        return True

    def _acknowledge(self, reply: Reply, now: float) -> None:
        if reply.sample <= self._acked_sample:
            return
        self._acked_sample = reply.sample
        while self._sent and self._sent[0][0] <= reply.sample:
            number, cumulative, sent_at = self._sent.popleft()
            self._bytes_acked = cumulative
            if number == reply.sample:
                rtt = max(0.0, now - sent_at - reply.held)
                self._min_rtt = rtt if self._min_rtt is None else min(self._min_rtt, rtt)
        if self._last_ack is not None:
            then, acked_then = self._last_ack
            if now > then:
                rate = (self._bytes_acked - acked_then) / (now - then)
                # A windowed maximum (BBR's bottleneck filter): the path carried at
                # least this much lately; a smoothed mean would lag each doubling.
                self._rates.append(rate)
                self._rate = max(self._rates)
        self._last_ack = (now, self._bytes_acked)

    # -- packets in -----------------------------------------------------------------

    def _dispatch(self, kind: TeleopKind, raw: bytes, now: float) -> list[TeleopEvent]:
        st = self._state
        if kind is TeleopKind.CHALLENGE and st is ChannelState.HELLO_SENT and self._psk:
            self._server_nonce = raw[HEADER_SIZE : HEADER_SIZE + _NONCE_SIZE]
            self._key = channel_key(self._psk, self._nonce, self._server_nonce, self._identity)
            self._go(ChannelState.AUTH_SENT)
            proof = client_proof(self._psk, self._nonce, self._server_nonce, self._identity)
            self._send(TeleopKind.AUTH, proof)
            return []
        if kind is TeleopKind.GRANT and st in (ChannelState.HELLO_SENT, ChannelState.AUTH_SENT):
            if self._psk is not None:
                if st is not ChannelState.AUTH_SENT:
                    # A keyed operator never accepts an unauthenticated arm (no downgrade).
                    return self.close(RefuseCode.NOT_AUTHORIZED)
                want = server_proof(self._psk, self._nonce, self._server_nonce, self._identity)
                if not _verify(want, raw[HEADER_SIZE : HEADER_SIZE + 32]):
                    return self.close(RefuseCode.NOT_AUTHORIZED)
            deadman, rate = _GRANT_TAIL.unpack_from(raw, HEADER_SIZE + 32)
            if not (0 < deadman < 1e6 and 0 < rate < 1e6):
                raise TeleopPacketError("GRANT figures out of range")
            self._go(ChannelState.OPEN)
            self.granted = Granted(float(deadman), float(rate))
            return [self.granted]
        if kind is TeleopKind.REFUSE and st in (ChannelState.HELLO_SENT, ChannelState.AUTH_SENT):
            try:
                reason = RefuseCode(raw[HEADER_SIZE])
            except ValueError:
                reason = RefuseCode.NORMAL
            self._go(ChannelState.CLOSED)
            return [Refused(reason)]
        if kind is TeleopKind.REPLY and st is ChannelState.OPEN:
            reply = decode_reply(raw)
            self._stats["replies_received"] += 1
            self._acknowledge(reply, now)
            self.last_reply = reply
            if self._stopped and reply.status is ReplyStatus.STOPPED:
                self.stop_confirmed = True
            return [ReplyReceived(reply, now)]
        if kind is TeleopKind.BYE:
            return self._peer_bye(raw)
        raise TeleopPacketError(f"{kind.name} not expected in {st.value}")

    def statistics(self) -> ChannelStatistics:
        return ChannelStatistics(
            state=self._state.value,
            in_flight_bytes=self.in_flight_bytes(),
            window_bytes=self.window_bytes(),
            delivery_rate=self._rate,
            min_rtt=self._min_rtt,
            **self._common_statistics(),
        )


class ArmChannel(_End):
    """The arm's end: answers HELLO, then holds the newest sample and the newest reply.

    Args:
        key: the pre-shared key, or None (then any well-formed HELLO is an operator).
        nonce: 16 fresh random bytes.
        rate_deadman: seconds without a sample after which rate mode stops
            (sent in the GRANT so the operator knows).
        control_rate: the arm's control loop rate (Hz), also in the GRANT.
    """

    _tx_dir = TO_OPERATOR
    _rx_dir = TO_ARM
    _lane_kind = TeleopKind.SAMPLE
    _lane_sent = "replies_sent"
    _lane_coalesced = "replies_coalesced"

    def __init__(
        self, key: bytes | None, nonce: bytes, *, rate_deadman: float, control_rate: float
    ) -> None:
        super().__init__(key, ChannelState.AWAITING_HELLO)
        if len(nonce) != _NONCE_SIZE:
            raise ValueError("nonce must be 16 bytes")
        if not (0 < rate_deadman < 1e6 and 0 < control_rate < 1e6):
            raise ValueError("rate_deadman and control_rate must be positive")
        self._nonce = nonce
        self._client_nonce = b""
        self._identity = b""
        self.rate_deadman = rate_deadman
        self.control_rate = control_rate
        self._latest: tuple[Sample, float] | None = None
        self._reply: Reply | None = None
        self.stopped = False
        self.last_heard: float | None = None

    @property
    def identity(self) -> str:
        return self._identity.rstrip(b"\0").decode("utf-8", errors="replace")

    def _lane_prefix(self) -> bytes | None:
        return self._client_nonce[:LANE_PREFIX] if self._client_nonce else None

    def grant(self) -> None:
        self._go(ChannelState.OPEN)
        assert self._key is not None or self._psk is None
        proof = (
            server_proof(self._psk, self._client_nonce, self._nonce, self._identity)
            if self._psk
            else bytes(32)
        )
        self._send(TeleopKind.GRANT, proof + _GRANT_TAIL.pack(self.rate_deadman, self.control_rate))

    def refuse(self, reason: RefuseCode) -> None:
        self._tx_counter += 1
        self._emit(sign(TeleopKind.REFUSE, self._tx_counter, bytes([reason]) + bytes(7), None, b""))
        self._go(ChannelState.CLOSED)

    def _handshake_failed(self) -> list[TeleopEvent]:
        self.refuse(RefuseCode.NOT_AUTHORIZED)
        return [Refused(RefuseCode.NOT_AUTHORIZED)]

    def take_latest(self) -> tuple[Sample, float] | None:
        """The newest sample not yet taken and when it arrived, or None."""
        latest, self._latest = self._latest, None
        return latest

    @property
    def pending_reply(self) -> Reply | None:
        return self._reply

    def reply(self, reply: Reply) -> None:
        """The newest reply: it replaces one not yet sent."""
        if self._reply is not None:
            self._stats["replies_coalesced"] += 1
        self._reply = reply

    def poll(self, now: float, backlog: Backlog | None = None) -> bool:
        """Send the pending reply if the line can take it now."""
        if self._state is not ChannelState.OPEN or self._reply is None:
            return False
        if backlog is not None and (backlog.queued_bytes > 0 or backlog.line_seconds > 0.0):
            self._stats["held_by_backlog"] += 1
            return False
        reply, self._reply = self._reply, None
        self._tx_counter += 1
        self._emit_value(encode_reply(reply, self._tx_counter, self._key, TO_OPERATOR))
        self._stats["replies_sent"] += 1
        return True

    def _dispatch(self, kind: TeleopKind, raw: bytes, now: float) -> list[TeleopEvent]:
        st = self._state
        if kind is TeleopKind.HELLO and st is ChannelState.AWAITING_HELLO:
            identity = raw[HEADER_SIZE : HEADER_SIZE + _IDENTITY_SIZE]
            name = identity.rstrip(b"\0")
            if not name or b"\0" in name:
                self.refuse(RefuseCode.BAD_HELLO)
                return [Refused(RefuseCode.BAD_HELLO)]
            self._identity = identity
            self._client_nonce = raw[HEADER_SIZE + _IDENTITY_SIZE : HEADER_SIZE + 48]
            if self._psk:
                self._key = channel_key(self._psk, self._client_nonce, self._nonce, identity)
                self._go(ChannelState.CHALLENGED)
                self._tx_counter += 1
                self._emit(sign(TeleopKind.CHALLENGE, self._tx_counter, self._nonce, None, b""))
                return []
            self._go(ChannelState.AWAITING_DECISION)
            return [OperatorArrived(self.identity)]
        if kind is TeleopKind.AUTH and st is ChannelState.CHALLENGED:
            assert self._psk is not None
            want = client_proof(self._psk, self._client_nonce, self._nonce, self._identity)
            if not _verify(want, raw[HEADER_SIZE : HEADER_SIZE + 32]):
                self.refuse(RefuseCode.NOT_AUTHORIZED)
                return [Refused(RefuseCode.NOT_AUTHORIZED)]
            self._go(ChannelState.AWAITING_DECISION)
            return [OperatorArrived(self.identity)]
        if kind is TeleopKind.SAMPLE and st is ChannelState.OPEN:
            sample = decode_sample(raw)
            if self.stopped:  # the STOP is latched: nothing after it moves the arm
                self._stats["samples_after_stop"] += 1
                return []
            self._stats["samples_received"] += 1
            if self._latest is not None:
                self._stats["samples_superseded"] += 1
            self._latest = (sample, now)
            self.last_heard = now
            return [SampleArrived(sample, now)]
        if kind is TeleopKind.STOP and st is ChannelState.OPEN:
            self._stats["stops_received"] += 1
            if self.stopped:
                return []  # a copy (OperatorChannel repeats STOP): latched already
            self.stopped = True
            self._latest = None
            return [StopArrived(now)]
        if kind is TeleopKind.BYE and st is not ChannelState.AWAITING_HELLO:
            return self._peer_bye(raw)
        if st in (ChannelState.AWAITING_HELLO, ChannelState.CHALLENGED):
            # Before the grant the first bad packet is refused (as the command session).
            self.refuse(RefuseCode.BAD_HELLO)
            return [Refused(RefuseCode.BAD_HELLO)]
        raise TeleopPacketError(f"{kind.name} not expected in {st.value}")

    def statistics(self) -> ChannelStatistics:
        return ChannelStatistics(
            state=self._state.value,
            in_flight_bytes=0,
            window_bytes=0.0,
            delivery_rate=None,
            min_rtt=None,
            **self._common_statistics(),
        )
