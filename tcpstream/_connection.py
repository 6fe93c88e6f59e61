"""Sans-I/O session cores: :class:`ServerConnection` (the arm) and :class:`ClientConnection`.

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

import secrets
import struct
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from . import _auth
from ._commands import (
    AUX_WORDS,
    Command,
    CommandCode,
    CommandFailed,
    CommandFlags,
    CommandResult,
    FailureReason,
    Feedback,
    validate_arguments,
)
from ._errors import LocalProtocolError
from ._events import (
    IDENTITY_SIZE,
    Accepted,
    CloseReason,
    CommandReceived,
    Completed,
    ControllerIdentity,
    ControlRequested,
    EmergencyStopRequested,
    Event,
    Failed,
    Granted,
    PacketRejected,
    RefusalReceived,
    RefuseReason,
    Role,
    SessionEnded,
    SessionParameters,
    TelemetryReceived,
)
from ._packet import (
    BODY_SIZE,
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
    words_body,
)
from ._state import IllegalTransition, SessionState, Side, Trigger, transition

__all__ = ["ClientConnection", "ConnectionStatistics", "ServerConnection"]

MAX_BAD_IN_A_ROW = 8
"""Consecutive rejected packets before the connection is given up.  A healthy
peer never sends even one (TCP and the serial socket both deliver intact,
in-order bytes), so eight is generous for a buggy-but-honest peer and keeps a
garbage source from holding a connection slot or costing more than eight
FAILED replies."""

_IDENTITY = struct.Struct(f"!{IDENTITY_SIZE}sQ{_auth.NONCE_SIZE}s")
_ZERO_AUX = (0.0,) * AUX_WORDS


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


def _identity_bytes(name: str) -> bytes:
    raw = name.encode("utf-8")
    if len(raw) > IDENTITY_SIZE or not raw or b"\0" in raw:
        raise ValueError(f"identity must be 1..{IDENTITY_SIZE} bytes of UTF-8 without NUL")
    return raw.ljust(IDENTITY_SIZE, b"\0")


class _Connection:
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
        self._out: list[bytes] = []
        # Bounded by construction: every received packet yields at most two events
        # and the application drains them after each receive_data/handle_timer.
        self._events: deque[Event] = deque()
        self._params: SessionParameters | None = None
        self.role: Role | None = None
        self._last_in = now
        self._last_out = now
        self._counter_in = 0
        self._counter_out = 0
        self._bad_in_a_row = 0
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
            raw = bytes(self._inbuf[:PACKET_SIZE])
            try:
                packet = decode_packet(raw)
            except BadMagic as exc:
                self._resync()
                self._reject(exc.reason, exc.message, exc.request_id, now)
                continue
            except PacketError as exc:
                # The magic was right, so the framing holds: skip exactly one packet.
                del self._inbuf[:PACKET_SIZE]
                self._reject(exc.reason, exc.message, exc.request_id, now)
                continue
            del self._inbuf[:PACKET_SIZE]
            self._accept_packet(packet, raw, now)
        if self.closed:
            self._inbuf.clear()

    def data_to_send(self) -> bytes:
        """Everything queued for the stream since the last call."""
        out = b"".join(self._out)
        self._out.clear()
        return out

    def next_event(self) -> Event | None:
        return self._events.popleft() if self._events else None

    def get_timer(self) -> float | None:
        """When :meth:`handle_timer` next has work (None: never, until input arrives)."""
        if self._state is SessionState.CLOSED:
            return None
        if self._state is not SessionState.OPEN or self._params is None:
            return self._handshake_deadline
        p = self._params
        return min(self._last_out + p.heartbeat_interval, self._last_in + p.dead_time)

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

    # --- shared machinery -----------------------------------------------------

    def _move(self, trigger: Trigger) -> None:
        self._state = transition(self.side, self._state, trigger)

    def _send(self, packet: Packet, now: float, *, tagged: bool = True) -> None:
        self._counter_out += 1
        unsigned = encode_packet(_with(packet, counter=self._counter_out))
        signed = unsigned[:SIGNED_SIZE]
        if tagged and self._session_key is not None:
            raw = signed + _auth.packet_tag(self._session_key, self._send_dir, signed)
        else:
            raw = unsigned
        self._out.append(raw)
        self._last_out = now
        self._stats["packets_out"] += 1

    def _end(self, reason: CloseReason, message: str, *, by_peer: bool) -> None:
        if not self.closed:
            try:
                self._move(Trigger.BYE_IN if by_peer else Trigger.FAULT)
            except IllegalTransition:  # a BYE before our HELLO: still over
                self._move(Trigger.FAULT)
        self._events.append(SessionEnded(reason, message, by_peer))

    def _resync(self) -> None:
        # Framing is lost (the peer wrote a partial packet, or is not speaking
        # this protocol).  Skip to the next b"TL" after the current position;
        # a false match in the data just fails again and is counted again.
        self._stats["resyncs"] += 1
        at = self._inbuf.find(MAGIC, 1)
        if at < 0:
            keep = 1 if self._inbuf.endswith(MAGIC[:1]) else 0
            del self._inbuf[: len(self._inbuf) - keep]
        else:
            del self._inbuf[:at]

    def _reject(self, reason: FailureReason, message: str, request_id: int, now: float) -> None:
        self._stats["bad_packets"] += 1
        self._bad_in_a_row += 1
        self._events.append(PacketRejected(reason, message))
        self._answer_rejected(reason, message, request_id, now)
        if self._bad_in_a_row >= MAX_BAD_IN_A_ROW and self._state is not SessionState.CLOSED:
            text = f"{self._bad_in_a_row} bad packets in a row; last: {message}"
            self.close(CloseReason.GARBAGE, now, text)
            self._events.append(SessionEnded(CloseReason.GARBAGE, text, by_peer=False))

    def _answer_rejected(
        self, reason: FailureReason, message: str, request_id: int, now: float
    ) -> None:
        """The arm answers a rejected packet with FAILED; the controller only counts it."""

    def _accept_packet(self, packet: Packet, raw: bytes, now: float) -> None:
        # Tag first (an unauthenticated packet must not move the counter), then
        # the counter, then meaning.  REFUSE and CHALLENGE are never tagged:
        # the arm cannot assume the controller holds the key.
        if self._session_key is not None and packet.kind not in (
            PacketKind.REFUSE,
            PacketKind.CHALLENGE,
        ):
            expected = _auth.packet_tag(self._session_key, self._recv_dir, raw[:SIGNED_SIZE])
            if not _auth.verify(expected, packet.tag):
                self._stats["tag_failures"] += 1
                self._reject(FailureReason.NOT_AUTHORIZED, "authentication tag mismatch", 0, now)
                return
        if packet.counter <= self._counter_in:
            self._stats["replays"] += 1
            self._reject(
                FailureReason.NOT_AUTHORIZED,
                f"counter {packet.counter} is not above {self._counter_in}: replayed or reordered",
                0,
                now,
            )
            return
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

    def _reject_state(self, packet: Packet, now: float) -> None:
        self._reject(
            FailureReason.BAD_PACKET,
            f"{packet.kind.name} is not allowed in state {self._state.value}",
            packet.request_id,
            now,
        )

    def _dispatch(self, packet: Packet, now: float) -> None:
        raise NotImplementedError

    def _handshake_timed_out(self, now: float) -> None:
        raise NotImplementedError


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


class ServerConnection(_Connection):
    """The arm's end of one connection.

    Events: :class:`ControlRequested` (answer with :meth:`grant` or
    :meth:`refuse`), :class:`CommandReceived`, :class:`EmergencyStopRequested`,
    :class:`PacketRejected`, :class:`SessionEnded`.
    """

    side = Side.SERVER

    def __init__(
        self,
        parameters: SessionParameters,
        *,
        key: bytes | None = None,
        handshake_timeout: float = 10.0,
        now: float = 0.0,
        nonce_source: Callable[[int], bytes] = secrets.token_bytes,
    ) -> None:
        super().__init__(
            key=key, handshake_timeout=handshake_timeout, now=now, nonce_source=nonce_source
        )
        self._granted_params = parameters
        self.identity: ControllerIdentity | None = None
        self._identity_raw = b""
        self._incarnation = 0
        self._client_nonce = b""
        self._server_nonce = b""
        self._wanted = Role.CONTROLLER

    def grant(self, role: Role, last_request_id: int, now: float) -> None:
        """Grant ``role`` (GRANT carries the timing and, keyed, the arm's proof)."""
        self._move(Trigger.GRANT)
        self.role = role
        self._params = self._granted_params
        p = self._params
        body = bytes(BODY_SIZE)
        if self._key is not None:
            proof = _auth.server_proof(
                self._key,
                self._client_nonce,
                self._server_nonce,
                self._identity_raw,
                self._incarnation,
                self._wanted,
            )
            body = proof.ljust(BODY_SIZE, b"\0")
        aux = (p.heartbeat_interval, p.dead_time, p.telemetry_period, float(p.memory_size))
        self._send(
            Packet(PacketKind.GRANT, flags=role, request_id=last_request_id, aux=aux, body=body),
            now,
        )

    def refuse(self, reason: RefuseReason, message: str, now: float) -> None:
        """Refuse with ``reason`` and a text saying what to do; the connection is CLOSED."""
        self._move(Trigger.REFUSE)
        self._send(
            Packet(PacketKind.REFUSE, status=reason, body=pack_text(message)), now, tagged=False
        )

    def accepted(self, request_id: int, code: CommandCode, position: int, now: float) -> None:
        """Confirm a command is queued (``position`` 0: it runs next)."""
        self._reply(
            Packet(
                PacketKind.ACCEPTED,
                code=code,
                request_id=request_id,
                aux=(float(position), 0.0, 0.0, 0.0),
            ),
            now,
        )

    def completed(
        self, request_id: int, code: CommandCode, result: CommandResult, now: float
    ) -> None:
        """Report a command done, with the feedback array and result words."""
        self._reply(
            Packet(
                PacketKind.COMPLETED,
                code=code,
                request_id=request_id,
                aux=tuple(result.aux),
                body=words_body(result.feedback.to_words()),
            ),
            now,
        )

    def failed(
        self,
        request_id: int,
        code: int,
        reason: FailureReason,
        message: str,
        aux: tuple[float, float, float, float],
        now: float,
    ) -> None:
        """Report a command failed (reason code, detail words, text of up to 144 bytes)."""
        self._reply(
            Packet(
                PacketKind.FAILED,
                code=code,
                status=reason,
                request_id=request_id,
                aux=aux,
                body=pack_text(message),
            ),
            now,
        )

    def telemetry(self, sample: int, feedback: Feedback, now: float) -> None:
        """Send the arm's state at control sample ``sample``."""
        self._reply(
            Packet(
                PacketKind.TELEMETRY,
                aux=(float(sample), 0.0, 0.0, 0.0),
                body=words_body(feedback.to_words()),
            ),
            now,
        )

    def _reply(self, packet: Packet, now: float) -> None:
        self._move(Trigger.REPLY)
        self._send(packet, now)

    def _answer_rejected(
        self, reason: FailureReason, message: str, request_id: int, now: float
    ) -> None:
        if self._state is SessionState.OPEN:
            self.failed(request_id, 0, reason, message, (0.0, 0.0, 0.0, 0.0), now)
        elif self._state is not SessionState.CLOSED:
            self.refuse(RefuseReason.BAD_HELLO, f"expected a HELLO: {message}", now)
            self._events.append(SessionEnded(CloseReason.REFUSED, message, by_peer=False))

    def _handshake_timed_out(self, now: float) -> None:
        self.refuse(RefuseReason.HANDSHAKE_TIMEOUT, "the handshake took too long", now)
        self._events.append(
            SessionEnded(CloseReason.HANDSHAKE_TIMEOUT, "handshake timed out", by_peer=False)
        )

    def _dispatch(self, packet: Packet, now: float) -> None:
        kind = packet.kind
        if kind is PacketKind.HELLO and self._state is SessionState.AWAITING_HELLO:
            self._on_hello(packet, now)
        elif kind is PacketKind.AUTH and self._state is SessionState.CHALLENGED:
            self._on_auth(packet, now)
        elif kind in (PacketKind.COMMAND, PacketKind.EMERGENCY_STOP) and (
            self._state is SessionState.OPEN
        ):
            self._on_command(packet, now)
        else:
            self._reject_state(packet, now)

    def _on_hello(self, packet: Packet, now: float) -> None:
        raw_id, incarnation, nonce = _IDENTITY.unpack_from(packet.body)
        try:
            name = raw_id.rstrip(b"\0").decode("utf-8")
            _identity_bytes(name)
            role = Role(packet.flags)
        except ValueError:
            self._move(Trigger.HELLO_IN)
            self.refuse(RefuseReason.BAD_HELLO, "malformed HELLO (identity or role)", now)
            self._events.append(SessionEnded(CloseReason.REFUSED, "bad hello", by_peer=False))
            return
        self._move(Trigger.HELLO_IN)
        self._identity_raw, self._incarnation, self._client_nonce = raw_id, incarnation, nonce
        self._wanted = role
        self.identity = ControllerIdentity(name, incarnation)
        if self._key is None:
            self._events.append(ControlRequested(self.identity, role))
            return
        self._server_nonce = self._nonce_source(_auth.NONCE_SIZE)
        self._move(Trigger.CHALLENGE)
        self._send(
            Packet(PacketKind.CHALLENGE, body=self._server_nonce.ljust(BODY_SIZE, b"\0")),
            now,
            tagged=False,
        )
        self._session_key = _auth.derive_session_key(
            self._key, nonce, self._server_nonce, raw_id, incarnation
        )

    def _on_auth(self, packet: Packet, now: float) -> None:
        assert self._key is not None
        assert self.identity is not None
        expected = _auth.client_proof(
            self._key,
            self._client_nonce,
            self._server_nonce,
            self._identity_raw,
            self._incarnation,
            self._wanted,
        )
        if not _auth.verify(expected, packet.body[: _auth.PROOF_SIZE]):
            self.refuse(RefuseReason.NOT_AUTHORIZED, "authentication failed", now)
            self._events.append(
                SessionEnded(CloseReason.AUTHENTICATION, "authentication failed", by_peer=False)
            )
            return
        self._move(Trigger.AUTH_IN)
        self._events.append(ControlRequested(self.identity, self._wanted))

    def _accept_packet(self, packet: Packet, raw: bytes, now: float) -> None:
        # A wrong key shows first as a bad AUTH tag: answer it exactly like a wrong
        # proof (one refusal text for every key failure), not as a counted bad packet.
        if (
            self._state is SessionState.CHALLENGED
            and packet.kind is PacketKind.AUTH
            and self._session_key is not None
        ):
            expected = _auth.packet_tag(self._session_key, self._recv_dir, raw[:SIGNED_SIZE])
            if not _auth.verify(expected, packet.tag):
                self._stats["tag_failures"] += 1
                self.refuse(RefuseReason.NOT_AUTHORIZED, "authentication failed", now)
                self._events.append(
                    SessionEnded(CloseReason.AUTHENTICATION, "authentication failed", by_peer=False)
                )
                return
        super()._accept_packet(packet, raw, now)

    def _on_command(self, packet: Packet, now: float) -> None:
        self._move(Trigger.COMMAND_IN)
        rid = packet.request_id
        if self.role is not Role.CONTROLLER:
            self.failed(
                rid,
                packet.code,
                FailureReason.NOT_AUTHORIZED,
                "this connection is an observer; connect as controller to command",
                _ZERO_AUX_4,
                now,
            )
            return
        if packet.kind is PacketKind.EMERGENCY_STOP or packet.code == CommandCode.EMERGENCY_STOP:
            self._events.append(EmergencyStopRequested(rid))
            return
        command = Command(CommandCode(packet.code), packet.words(), CommandFlags(packet.flags))
        try:
            validate_arguments(command)
        except CommandFailed as exc:
            self.failed(rid, packet.code, exc.reason, exc.message, exc.aux, now)
            return
        self._events.append(CommandReceived(rid, command))


_ZERO_AUX_4 = (0.0, 0.0, 0.0, 0.0)


class ClientConnection(_Connection):
    """The controller's end of one connection.

    Events: :class:`Granted`, :class:`RefusalReceived`, :class:`Accepted`,
    :class:`Completed`, :class:`Failed`, :class:`TelemetryReceived`,
    :class:`PacketRejected`, :class:`SessionEnded`.
    """

    side = Side.CLIENT

    def __init__(
        self,
        identity: ControllerIdentity,
        *,
        role: Role = Role.CONTROLLER,
        key: bytes | None = None,
        handshake_timeout: float = 10.0,
        now: float = 0.0,
        nonce_source: Callable[[int], bytes] = secrets.token_bytes,
    ) -> None:
        super().__init__(
            key=key, handshake_timeout=handshake_timeout, now=now, nonce_source=nonce_source
        )
        self.identity = identity
        self._identity_raw = _identity_bytes(identity.name)
        if not 0 <= identity.incarnation < 2**64:
            raise ValueError("incarnation must fit in 64 bits")
        self._wanted = role
        self._client_nonce = b""

    def connect(self, now: float) -> None:
        """Send the HELLO."""
        self._move(Trigger.CONNECT)
        self._client_nonce = self._nonce_source(_auth.NONCE_SIZE)
        body = _IDENTITY.pack(self._identity_raw, self.identity.incarnation, self._client_nonce)
        self._send(
            Packet(PacketKind.HELLO, flags=self._wanted, body=body.ljust(BODY_SIZE, b"\0")), now
        )

    def send_command(self, request_id: int, command: Command, now: float) -> None:
        """Send a command (EMERGENCY_STOP goes as its own packet kind)."""
        if not 0 < request_id < 2**32:
            raise LocalProtocolError(f"request id {request_id} outside 1..2**32-1")
        self._move(Trigger.COMMAND)
        if command.code is CommandCode.EMERGENCY_STOP:
            self._send(
                Packet(PacketKind.EMERGENCY_STOP, code=command.code, request_id=request_id), now
            )
            return
        self._send(
            Packet(
                PacketKind.COMMAND,
                flags=command.flags,
                code=command.code,
                request_id=request_id,
                body=words_body(command.args),
            ),
            now,
        )

    def _handshake_timed_out(self, now: float) -> None:
        self.close(CloseReason.HANDSHAKE_TIMEOUT, now, "no answer to HELLO")
        self._events.append(
            SessionEnded(CloseReason.HANDSHAKE_TIMEOUT, "the arm did not answer", by_peer=False)
        )

    def _auth_failed(self, message: str, now: float) -> None:
        self.close(CloseReason.AUTHENTICATION, now, "authentication failed")
        self._events.append(SessionEnded(CloseReason.AUTHENTICATION, message, by_peer=False))

    def _dispatch(self, packet: Packet, now: float) -> None:
        kind, state = packet.kind, self._state
        if kind is PacketKind.REFUSE and state in (SessionState.HELLO_SENT, SessionState.AUTH_SENT):
            self._move(Trigger.REFUSE_IN)
            try:
                reason = RefuseReason(packet.status)
            except ValueError:
                reason = RefuseReason.BAD_HELLO
            text = unpack_text(packet.body)
            self._events.append(RefusalReceived(reason, text))
            self._events.append(SessionEnded(CloseReason.REFUSED, text, by_peer=True))
        elif kind is PacketKind.CHALLENGE and state is SessionState.HELLO_SENT:
            self._on_challenge(packet, now)
        elif kind is PacketKind.GRANT and state in (
            SessionState.HELLO_SENT,
            SessionState.AUTH_SENT,
        ):
            self._on_grant(packet, now)
        elif state is SessionState.OPEN and kind in (
            PacketKind.ACCEPTED,
            PacketKind.COMPLETED,
            PacketKind.FAILED,
            PacketKind.TELEMETRY,
        ):
            self._on_reply(packet, now)
        else:
            self._reject_state(packet, now)

    def _on_challenge(self, packet: Packet, now: float) -> None:
        if self._key is None:
            self._move(Trigger.CHALLENGE_IN)
            self._auth_failed("the arm requires a pre-shared key and none was given", now)
            return
        server_nonce = packet.body[: _auth.NONCE_SIZE]
        self._move(Trigger.CHALLENGE_IN)
        self._session_key = _auth.derive_session_key(
            self._key,
            self._client_nonce,
            server_nonce,
            self._identity_raw,
            self.identity.incarnation,
        )
        self._server_nonce = server_nonce
        proof = _auth.client_proof(
            self._key,
            self._client_nonce,
            server_nonce,
            self._identity_raw,
            self.identity.incarnation,
            self._wanted,
        )
        self._send(Packet(PacketKind.AUTH, body=proof.ljust(BODY_SIZE, b"\0")), now)

    def _on_grant(self, packet: Packet, now: float) -> None:
        if self._key is not None:
            if self._state is SessionState.HELLO_SENT:
                # A keyed controller never accepts an unauthenticated arm (no downgrade).
                self._move(Trigger.GRANT_IN)
                self._auth_failed("the arm granted without authenticating; refusing it", now)
                return
            expected = _auth.server_proof(
                self._key,
                self._client_nonce,
                self._server_nonce,
                self._identity_raw,
                self.identity.incarnation,
                self._wanted,
            )
            if not _auth.verify(expected, packet.body[: _auth.PROOF_SIZE]):
                self._move(Trigger.GRANT_IN)
                self._auth_failed("the arm could not prove it holds the key", now)
                return
        try:
            role = Role(packet.flags)
            hb, dead, tele, memory = packet.aux
            params = SessionParameters(hb, dead, tele, int(memory))
            if not (hb > 0 and dead > hb and tele >= 0 and memory >= 0):
                raise ValueError("timing out of range")
        except ValueError as exc:
            self._move(Trigger.GRANT_IN)
            self.close(CloseReason.GARBAGE, now, f"malformed GRANT: {exc}")
            self._events.append(SessionEnded(CloseReason.GARBAGE, f"malformed GRANT: {exc}", False))
            return
        self._move(Trigger.GRANT_IN)
        self.role = role
        self._params = params
        self._events.append(Granted(role, params, packet.request_id))

    def _on_reply(self, packet: Packet, now: float) -> None:
        self._move(Trigger.REPLY_IN)
        kind, rid = packet.kind, packet.request_id
        aux = (packet.aux[0], packet.aux[1], packet.aux[2], packet.aux[3])
        if kind is PacketKind.FAILED:
            try:
                reason = FailureReason(packet.status)
            except ValueError:
                reason = FailureReason.ARM_FAULT
            self._events.append(Failed(rid, packet.code, reason, unpack_text(packet.body), aux))
            return
        if kind is PacketKind.TELEMETRY:
            try:
                feedback = Feedback.from_words(packet.words())
            except ValueError as exc:
                self._reject(FailureReason.BAD_PACKET, f"bad telemetry: {exc}", 0, now)
                return
            self._events.append(TelemetryReceived(int(aux[0]), feedback))
            return
        try:
            code = CommandCode(packet.code)
        except ValueError:
            self._reject(
                FailureReason.BAD_PACKET, f"reply for unknown command {packet.code}", rid, now
            )
            return
        if kind is PacketKind.ACCEPTED:
            self._events.append(Accepted(rid, code, int(aux[0])))
            return
        try:
            feedback = Feedback.from_words(packet.words())
        except ValueError as exc:
            self._reject(FailureReason.BAD_PACKET, f"bad feedback array: {exc}", rid, now)
            return
        self._events.append(Completed(rid, code, CommandResult(feedback, aux)))
