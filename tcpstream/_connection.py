"""Sans-I/O session core shared by both ends (:class:`ServerConnection`, :class:`ClientConnection`).

Like h11, a connection is a plain object: feed it bytes with
:meth:`~_Connection.receive_data` and the time with
:meth:`~_Connection.handle_timer`, take bytes with
:meth:`~_Connection.data_to_send` and events with :meth:`~_Connection.next_event`,
and ask :meth:`~_Connection.get_timer` when to call back.  No clock, socket,
task or global randomness inside; nonces come from an injected
``nonce_source``.

What a connection does on its own: framing by the fixed packet size,
resynchronisation after a bad magic, strict decoding, tag and counter checks,
the handshake, heartbeats, the dead-time (deadman) verdict, the handshake
timeout, the garbage limit, and a ``FAILED`` answer to every packet it has to
reject.  What it leaves to the application: whether to grant, and everything
about commands once they are received (queue, executor, exactly-once memory).
"""

from __future__ import annotations

import abc
import logging
import math
import struct
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from . import _auth
from ._commands import FailureReason
from ._events import (
    IDENTITY_SIZE,
    CloseReason,
    Event,
    PacketRejected,
    Role,
    SessionEnded,
    SessionParameters,
)
from ._packet import (
    MAGIC,
    PACKET_SIZE,
    SIGNED_SIZE,
    BadMagic,
    Packet,
    PacketError,
    PacketKind,
    decode_packet,
    encode_packet,
    pack_text,
    unpack_text,
)
from ._state import IllegalTransition, SessionState, Side, Trigger, transition

__all__ = ["MAX_BAD_IN_A_ROW", "ConnectionStatistics", "_Connection"]

trace = logging.getLogger("tcpstream.packets")
"""The packet trace: set this logger to DEBUG to log every packet, decoded."""

MAX_BAD_IN_A_ROW = 8
"""Consecutive rejected packets before the connection is given up.  A healthy
peer never sends even one (TCP and the serial socket both deliver intact,
in-order bytes), so eight is generous for a buggy-but-honest peer and keeps a
garbage source from holding a connection slot or costing more than eight
FAILED replies."""

_IDENTITY = struct.Struct(f"!{IDENTITY_SIZE}sQ{_auth.NONCE_SIZE}s")


@dataclass(frozen=True, slots=True, kw_only=True)
class ConnectionStatistics:
    """Counters an operator reads (one connection)."""

    state: SessionState
    role: Role | None
    packets_in: int
    packets_out: int
    bad_packets: int
    """Packets rejected for any reason (each answered with FAILED on the arm side)."""
    resyncs: int
    """Times framing was recovered after a bad magic."""
    tag_failures: int
    replays: int
    """Packets whose counter did not exceed the last one (replayed or reordered)."""
    heartbeats_in: int
    heartbeats_out: int
    last_counter_in: int
    last_counter_out: int
    expedited_in: int = 0
    """EMERGENCY_STOPs taken from the transport's expedited lane (PROTOCOL.md 15)."""
    expedited_out: int = 0
    """EMERGENCY_STOPs sent on the transport's expedited lane."""


def _identity_bytes(name: str) -> bytes:
    raw = name.encode("utf-8")
    if len(raw) > IDENTITY_SIZE or not raw or b"\0" in raw:
        raise ValueError(f"identity must be 1..{IDENTITY_SIZE} bytes of UTF-8 without NUL")
    return raw.ljust(IDENTITY_SIZE, b"\0")


class _Connection(abc.ABC):
    """What both ends share: framing, checks, counters, timers, events."""

    side: Side

    def __init__(
        self,
        *,
        key: bytes | None,
        handshake_timeout: float,
        now: float,
        nonce_source: Callable[[int], bytes],
    ) -> None:
        if key is not None and len(key) < _auth.MIN_KEY_SIZE:
            raise ValueError(f"a pre-shared key needs at least {_auth.MIN_KEY_SIZE} bytes")
        self._key = key
        self._nonce_source = nonce_source
        self._state = SessionState.IDLE if self.side is Side.CLIENT else SessionState.AWAITING_HELLO
        self._handshake_deadline = now + handshake_timeout
        self._session_key: bytes | None = None
        self._send_dir = _auth.TO_SERVER if self.side is Side.CLIENT else _auth.TO_CLIENT
        self._recv_dir = _auth.TO_CLIENT if self.side is Side.CLIENT else _auth.TO_SERVER
        self._inbuf = bytearray()
        self._hunting = False
        """Skipping to the next magic after a packet that did not verify."""
        self._out: list[bytes] = []
        self._out_bytes = 0
        # Bounded by construction: every received packet yields at most two events
        # and the application drains them after each receive_data/handle_timer.
        self._events: deque[Event] = deque()
        self._params: SessionParameters | None = None
        self.role: Role | None = None
        self.close_reason: CloseReason | None = None
        """Why the session ended (None while it has not)."""
        self._last_in = now
        self._last_out = now
        self._counter_in = 0
        self._counter_out = 0
        self._bad_in_a_row = 0
        self.expedited = False
        """The transport offers an expedited lane (set by the I/O layer before
        the session starts; PROTOCOL.md section 15): the controller sends its
        EMERGENCY_STOP there, the arm takes it from there."""
        self._xout: list[bytes] = []
        self._xcounter_in = 0
        self._xcounter_out = 0
        self._stats = dict.fromkeys(
            (
                "packets_in",
                "packets_out",
                "bad_packets",
                "resyncs",
                "tag_failures",
                "replays",
                "heartbeats_in",
                "heartbeats_out",
                "expedited_in",
                "expedited_out",
            ),
            0,
        )

    # --- public surface -------------------------------------------------------

    @property
    def state(self) -> SessionState:
        return self._state

    @property
    def closed(self) -> bool:
        return self._state is SessionState.CLOSED

    @property
    def parameters(self) -> SessionParameters | None:
        """The granted timing, once OPEN."""
        return self._params

    @property
    def last_heard(self) -> float:
        """When the last good packet from the peer arrived (the deadman's reference)."""
        return self._last_in

    def statistics(self) -> ConnectionStatistics:
        return ConnectionStatistics(
            state=self._state,
            role=self.role,
            last_counter_in=self._counter_in,
            last_counter_out=self._counter_out,
            **self._stats,
        )

    def receive_data(self, data: bytes, now: float) -> None:
        """Bytes from the stream; ``b""`` means the stream ended."""
        if self._state is SessionState.CLOSED:
            return
        if not data:
            self._end(CloseReason.PEER_EOF, "the stream ended without a BYE", by_peer=True)
            return
        self._inbuf += data
        while len(self._inbuf) >= PACKET_SIZE and not self.closed:
            if self._hunting:
                # Looking for the magic after bytes that did not verify: what
                # precedes it is the forgery's tail, nobody's packet to blame.
                if not self._inbuf.startswith(MAGIC):
                    self._skip_to_magic()
                    continue
                self._hunting = False
            raw = bytes(self._inbuf[:PACKET_SIZE])
            try:
                packet = decode_packet(raw)
            except BadMagic as exc:
                self._resync()
                self._reject(exc.reason, exc.message, exc.request_id, now)
                continue
            except PacketError as exc:
                if not self._tag_holds(raw):
                    # Keyed, and not from the peer: nothing may change (see
                    # _accept_packet), not even an answer or the garbage count.
                    self._stats["tag_failures"] += 1
                    self._drop_forgery(f"undecodable and unauthenticated: {exc.message}")
                    self._skip_unverified()
                    continue
                # The magic was right, so the framing holds: skip exactly one packet.
                del self._inbuf[:PACKET_SIZE]
                self._undecodable(exc, raw, exc.request_id, now)
                continue
            if self._forged(packet, raw):
                self._stats["tag_failures"] += 1
                self._drop_forgery(f"{packet.kind.name}: authentication tag mismatch")
                self._skip_unverified()
                continue
            del self._inbuf[:PACKET_SIZE]
            self._accept_packet(packet, raw, now)
        if self.closed:
            self._inbuf.clear()

    def data_to_send(self) -> bytes:
        """Everything queued for the stream since the last call."""
        out = b"".join(self._out)
        self._out.clear()
        self._out_bytes = 0
        return out

    @property
    def expedited_pending(self) -> int:
        """Expedited packets queued and not yet taken by :meth:`expedited_to_send`."""
        return len(self._xout)

    def expedited_to_send(self) -> list[bytes]:
        """Packets for the transport's expedited lane since the last call, each
        one message (PROTOCOL.md section 15)."""
        out, self._xout = self._xout, []
        return out

    def receive_expedited(self, message: bytes, now: float) -> None:
        """One message from the transport's expedited lane.

        It must be one whole packet, tagged for the lane (direction 0x03) when
        the session is keyed, with a lane counter above the last one, and an
        EMERGENCY_STOP: anything else is counted and dropped (a forgery or a
        broken peer; never answered, so the lane cannot be used to probe).
        Then it is handled as the same packet on the stream would be.
        """
        if self._state is SessionState.CLOSED:
            return
        why = self._expedited_problem(message)
        if why is not None:
            self._stats["bad_packets"] += 1
            if trace.isEnabledFor(logging.DEBUG):
                trace.debug("%s expedited dropped: %s", self.side.value, why)
            self._events.append(PacketRejected(FailureReason.NOT_AUTHORIZED, why))
            return
        packet = decode_packet(message)
        self._xcounter_in = packet.counter
        self._stats["expedited_in"] += 1
        self._last_in = now
        if trace.isEnabledFor(logging.DEBUG):
            trace.debug("%s expedited in: %s", self.side.value, packet.describe())
        self._dispatch(packet, now)

    def _expedited_problem(self, message: bytes) -> str | None:
        """Why an expedited message is not a genuine lane packet (None: it is)."""
        if self.side is not Side.SERVER:
            return "expedited message to the controller: only the controller sends on the lane"
        if len(message) != PACKET_SIZE:
            return f"expedited message of {len(message)} bytes, not one {PACKET_SIZE}-byte packet"
        if self._session_key is not None:
            expected = _auth.packet_tag(
                self._session_key, _auth.TO_SERVER_EXPEDITED, message[:SIGNED_SIZE]
            )
            if not _auth.verify(expected, message[SIGNED_SIZE:]):
                return "expedited message: authentication tag mismatch"
        if self._state is not SessionState.OPEN:
            return "expedited message outside an open session"
        try:
            packet = decode_packet(message)
        except PacketError as exc:
            return f"expedited message does not decode: {exc.message}"
        if packet.kind is not PacketKind.EMERGENCY_STOP:
            return f"{packet.kind.name} on the expedited lane (only EMERGENCY_STOP travels there)"
        if packet.counter <= self._xcounter_in:
            return f"expedited counter {packet.counter} is not above {self._xcounter_in}: replayed"
        return None

    def _send_expedited(self, packet: Packet, now: float) -> None:
        """Queue ``packet`` for the expedited lane, with the lane's own counter
        and direction (the arm checks both apart from the stream's)."""
        self._xcounter_out += 1
        stamped = _with(packet, counter=self._xcounter_out)
        unsigned = encode_packet(stamped)
        signed = unsigned[:SIGNED_SIZE]
        if self._session_key is not None:
            raw = signed + _auth.packet_tag(self._session_key, _auth.TO_SERVER_EXPEDITED, signed)
        else:
            raw = unsigned
        self._xout.append(raw)
        self._stats["expedited_out"] += 1
        self._last_out = now
        if trace.isEnabledFor(logging.DEBUG):
            trace.debug("%s expedited out: %s", self.side.value, stamped.describe())

    @property
    def buffered(self) -> int:
        """Bytes queued by the connection and not yet taken by :meth:`data_to_send`."""
        return self._out_bytes

    def abandon(self, reason: CloseReason, message: str) -> None:
        """Give the session up without a BYE (the stream cannot carry one); drops output."""
        if self._state is SessionState.CLOSED:
            return
        self._move(Trigger.FAULT)
        self.close_reason = reason
        self._out.clear()
        self._out_bytes = 0
        self._events.append(SessionEnded(reason, message, by_peer=False))

    def next_event(self) -> Event | None:
        return self._events.popleft() if self._events else None

    def get_timer(self) -> float | None:
        """When :meth:`handle_timer` next has work (None: never, until input arrives)."""
        if self._state is SessionState.CLOSED:
            return None
        if self._state is not SessionState.OPEN or self._params is None:
            return self._handshake_deadline
        p = self._params
        return min(
            self._last_out + p.heartbeat_interval,
            self._last_in + p.dead_time,
            self._idle_deadline(),
        )

    def handle_timer(self, now: float) -> None:
        """Send a due heartbeat; end the session on silence or handshake timeout."""
        if self._state is SessionState.CLOSED:
            return
        if self._state is not SessionState.OPEN or self._params is None:
            if now >= self._handshake_deadline:
                self._handshake_timed_out(now)
            return
        p = self._params
        # Compare with the very sums get_timer() returned: (a + b) - a < b can
        # happen in floating point, and would spin a timer loop at one instant.
        if now >= self._last_in + p.dead_time:
            self.close(CloseReason.SILENCE, now, f"nothing heard for {now - self._last_in:.3g} s")
            self._events.append(
                SessionEnded(CloseReason.SILENCE, "the peer fell silent", by_peer=False)
            )
            return
        if now >= self._idle_deadline():
            self.close(CloseReason.IDLE, now, "no commands for the idle timeout; control released")
            self._events.append(SessionEnded(CloseReason.IDLE, "idle timeout", by_peer=False))
            return
        if now >= self._last_out + p.heartbeat_interval:
            self._move(Trigger.HEARTBEAT)
            self._stats["heartbeats_out"] += 1
            self._send(Packet(PacketKind.HEARTBEAT), now)

    def close(self, reason: CloseReason, now: float, message: str = "") -> None:
        """Send BYE (with ``reason`` and text) and close; idempotent once CLOSED."""
        if self._state is SessionState.CLOSED:
            return
        if self._state is not SessionState.IDLE:
            self._send(Packet(PacketKind.BYE, status=reason, body=pack_text(message)), now)
        self._move(Trigger.BYE)
        self.close_reason = reason

    # --- shared machinery -----------------------------------------------------

    def _move(self, trigger: Trigger) -> None:
        self._state = transition(self.side, self._state, trigger)

    def _send(self, packet: Packet, now: float, *, tagged: bool = True) -> None:
        self._counter_out += 1
        stamped = _with(packet, counter=self._counter_out)
        unsigned = encode_packet(stamped)
        signed = unsigned[:SIGNED_SIZE]
        if tagged and self._session_key is not None:
            raw = signed + _auth.packet_tag(self._session_key, self._send_dir, signed)
        else:
            raw = unsigned
        self._out.append(raw)
        self._out_bytes += len(raw)
        if trace.isEnabledFor(logging.DEBUG):
            trace.debug("%s out: %s", self.side.value, stamped.describe())
        self._last_out = now
        self._stats["packets_out"] += 1

    def _end(self, reason: CloseReason, message: str, *, by_peer: bool) -> None:
        if not self.closed:
            try:
                self._move(Trigger.BYE_IN if by_peer else Trigger.FAULT)
            except IllegalTransition:  # a BYE before our HELLO: still over
                self._move(Trigger.FAULT)
            self.close_reason = reason
        self._events.append(SessionEnded(reason, message, by_peer))

    def _resync(self) -> None:
        # Framing is lost (the peer wrote a partial packet, or is not speaking
        # this protocol).  Skip to the next b"TL" after the current position;
        # a false match in the data just fails again and is counted again.
        self._stats["resyncs"] += 1
        self._skip_to_magic()

    def _skip_unverified(self) -> None:
        """Skip a keyed packet that did not verify.

        In an open session its bytes need not be a packet the peer framed: a
        fragment injected into the stream is completed by the start of the next
        genuine packet.  So look for the next magic after its first byte, as a
        resync does (not counted as one: it is no fault of the peer), rather
        than skip a whole packet and lose the genuine one.  A false match fails
        the tag again.  In the handshake, where an unauthenticated peer could
        make this cost a tag check per two bytes, one whole packet is skipped.
        """
        if self._state is SessionState.OPEN:
            self._skip_to_magic()
            # The byte kept when the buffer ends in b"T" may start the next
            # magic, or be the forgery's last byte: until a magic is in front,
            # skip without blame (a b"TT" bad magic was counted and answered).
            self._hunting = True
        else:
            del self._inbuf[:PACKET_SIZE]

    def _skip_to_magic(self) -> None:
        at = self._inbuf.find(MAGIC, 1)
        if at < 0:
            keep = 1 if self._inbuf.endswith(MAGIC[:1]) else 0
            del self._inbuf[: len(self._inbuf) - keep]
        else:
            del self._inbuf[:at]

    def _undecodable(self, exc: PacketError, raw: bytes, request_id: int, now: float) -> None:
        """A packet with the right magic that does not decode: counted, one packet
        skipped.  ``request_id`` is the packet's, if it may be believed, else 0."""
        self._reject(exc.reason, exc.message, request_id, now)

    def _tag_holds(self, raw: bytes) -> bool:
        """Whether a packet's tag verifies, or there is no key to check it with.
        The tag covers the raw bytes, so it can be checked even when the words
        cannot be decoded (and an undecodable packet's request id believed)."""
        if self._session_key is None:
            return True
        expected = _auth.packet_tag(self._session_key, self._recv_dir, raw[:SIGNED_SIZE])
        return _auth.verify(expected, raw[SIGNED_SIZE:PACKET_SIZE])

    def _reject(self, reason: FailureReason, message: str, request_id: int, now: float) -> None:
        self._stats["bad_packets"] += 1
        self._bad_in_a_row += 1
        if trace.isEnabledFor(logging.DEBUG):
            trace.debug("%s rejected: %s (%s)", self.side.value, message, reason.name)
        self._events.append(PacketRejected(reason, message))
        self._answer_rejected(reason, message, request_id, now)
        if self._bad_in_a_row >= MAX_BAD_IN_A_ROW and self._state is not SessionState.CLOSED:
            text = f"{self._bad_in_a_row} bad packets in a row; last: {message}"
            self.close(CloseReason.GARBAGE, now, text)
            self._events.append(SessionEnded(CloseReason.GARBAGE, text, by_peer=False))

    def _answer_rejected(  # noqa: B027 (a no-op by default, not abstract)
        self, reason: FailureReason, message: str, request_id: int, now: float
    ) -> None:
        """The arm answers a rejected packet with FAILED; the controller only counts it."""

    def _forged(self, packet: Packet, raw: bytes) -> bool:
        """Whether a decoded packet of a keyed session fails its tag.

        Checked before anything else: once the session is keyed, nothing about
        it -- the counter, the dead-time timer, the garbage count, an answer --
        changes for a packet that does not verify.  A kind that is never tagged
        (CHALLENGE, REFUSE) is accepted only where the handshake expects it,
        before the session key exists or, for REFUSE, while the arm may still
        turn a bad AUTH away.
        """
        return (
            self._session_key is not None
            and not self._may_be_untagged(packet.kind)
            and not self._tag_holds(raw)
        )

    def _accept_packet(self, packet: Packet, raw: bytes, now: float) -> None:
        # The tag was checked first (_forged), then the counter, then meaning.
        if packet.counter <= self._counter_in:
            self._stats["replays"] += 1
            why = f"counter {packet.counter} is not above {self._counter_in}: replayed or reordered"
            if self._session_key is not None:
                self._drop_forgery(why)  # a recorded genuine packet, re-injected
            else:
                self._reject(FailureReason.NOT_AUTHORIZED, why, 0, now)
            return
        if trace.isEnabledFor(logging.DEBUG):
            trace.debug("%s in: %s", self.side.value, packet.describe())
        self._counter_in = packet.counter
        self._bad_in_a_row = 0
        self._last_in = now
        self._stats["packets_in"] += 1
        if packet.kind is PacketKind.BYE:
            text = unpack_text(packet.body)
            try:
                reason = CloseReason(packet.status)
            except ValueError:
                reason = CloseReason.NORMAL
            self._end(reason, text or reason.name.lower(), by_peer=True)
            return
        if packet.kind is PacketKind.HEARTBEAT:
            try:
                self._move(Trigger.HEARTBEAT_IN)
            except IllegalTransition:
                self._reject_state(packet, now)
                return
            self._stats["heartbeats_in"] += 1
            return
        self._dispatch(packet, now)

    def _may_be_untagged(self, kind: PacketKind) -> bool:
        """Whether ``kind`` skips the shared tag check in this state of a keyed
        session (it may arrive untagged, or the role checks it itself)."""
        return False

    def _drop_forgery(self, message: str) -> None:
        """Count and drop a packet of a keyed session that did not verify.

        Unlike :meth:`_reject` it is not answered (no amplification: a forger
        gets nothing back) and does not count towards the garbage limit (a
        flood of forgeries must not end a session between genuine peers; the
        dead time still ends it if the genuine peer falls silent).
        """
        self._stats["bad_packets"] += 1
        if trace.isEnabledFor(logging.DEBUG):
            trace.debug("%s dropped: %s", self.side.value, message)
        self._events.append(PacketRejected(FailureReason.NOT_AUTHORIZED, message))

    def _reject_state(self, packet: Packet, now: float) -> None:
        self._reject(
            FailureReason.BAD_PACKET,
            f"{packet.kind.name} is not allowed in state {self._state.value}",
            packet.request_id,
            now,
        )

    @abc.abstractmethod
    def _dispatch(self, packet: Packet, now: float) -> None:
        """Role hook: each side implements it."""

    def _idle_deadline(self) -> float:
        """When an idle session ends (the arm's controller only; never by default)."""
        return math.inf

    @abc.abstractmethod
    def _handshake_timed_out(self, now: float) -> None:
        """Role hook: each side implements it."""


def _with(packet: Packet, *, counter: int) -> Packet:
    return Packet(
        kind=packet.kind,
        flags=packet.flags,
        code=packet.code,
        status=packet.status,
        request_id=packet.request_id,
        counter=counter,
        aux=packet.aux,
        body=packet.body,
    )
