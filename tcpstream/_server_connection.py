"""The arm's end of a session, sans-I/O: handshake, grant/refuse, replies (PROTOCOL.md 7-8)."""

from __future__ import annotations

import math
import secrets
import struct
from collections.abc import Callable

from . import _auth
from ._commands import (
    Command,
    CommandCode,
    CommandFailed,
    CommandFlags,
    CommandResult,
    FailureReason,
    Feedback,
    validate_arguments,
)
from ._connection import _IDENTITY, _Connection, _identity_bytes
from ._events import (
    CloseReason,
    CommandReceived,
    ControllerIdentity,
    ControlRequested,
    EmergencyStopRequested,
    RefuseReason,
    Role,
    SessionEnded,
    SessionParameters,
)
from ._packet import (
    BODY_SIZE,
    SIGNED_SIZE,
    Packet,
    PacketKind,
    pack_text,
    words_body,
)
from ._state import SessionState, Side, Trigger

__all__ = ["ServerConnection"]

_ZERO_AUX_4 = (0.0, 0.0, 0.0, 0.0)
_INSTANCE = struct.Struct("!QB")
"""GRANT body bytes 32..39: the arm's instance number (after the 32-byte proof);
byte 40: 1 if the arm remembers this controller, 0 if it has no memory of it."""


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
        idle_timeout: float | None = None,
        instance: int = 0,
        now: float = 0.0,
        nonce_source: Callable[[int], bytes] = secrets.token_bytes,
    ) -> None:
        super().__init__(
            key=key, handshake_timeout=handshake_timeout, now=now, nonce_source=nonce_source
        )
        self._granted_params = parameters
        self._idle_timeout = idle_timeout
        self._instance = instance
        self._last_activity = now
        # Request ids ACCEPTED and not yet answered: while any is outstanding the
        # controller is waiting, not idle.  Bounded by the arm's queue (+1 running).
        self._outstanding: set[int] = set()
        self.identity: ControllerIdentity | None = None
        self._identity_raw = b""
        self._incarnation = 0
        self._client_nonce = b""
        self._server_nonce = b""
        self._wanted = Role.CONTROLLER

    def grant(
        self, role: Role, last_request_id: int, now: float, *, remembered: bool = False
    ) -> None:
        """Grant ``role`` (GRANT carries the timing and, keyed, the arm's proof).

        ``remembered``: whether the arm's exactly-once memory knew this
        controller before this grant.  Say False whenever it cannot be proved:
        the controller then settles its unconfirmed commands as outcome-unknown
        instead of re-sending them.
        """
        self._move(Trigger.GRANT)
        self.role = role
        self._last_activity = now
        self._params = self._granted_params
        p = self._params
        proof = bytes(_auth.PROOF_SIZE)
        if self._key is not None:
            proof = _auth.server_proof(
                self._key,
                self._client_nonce,
                self._server_nonce,
                self._identity_raw,
                self._incarnation,
                self._wanted,
            )
        # The lane flag: this arm reads EMERGENCY_STOP from the transport's
        # expedited lane (PROTOCOL.md 15); a controller uses the lane only then.
        grant_tail = _INSTANCE.pack(self._instance, int(remembered)) + bytes((int(self.expedited),))
        body = (proof + grant_tail).ljust(BODY_SIZE, b"\0")
        aux = (p.heartbeat_interval, p.dead_time, p.telemetry_period, float(p.memory_size))
        self._send(
            Packet(PacketKind.GRANT, flags=role, request_id=last_request_id, aux=aux, body=body),
            now,
        )

    def refuse(self, reason: RefuseReason, message: str, now: float) -> None:
        """Refuse with ``reason`` and a text saying what to do; the connection is CLOSED."""
        self._move(Trigger.REFUSE)
        self.close_reason = CloseReason.REFUSED
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
        if packet.kind is PacketKind.ACCEPTED:
            self._outstanding.add(packet.request_id)
        elif packet.kind in (PacketKind.COMPLETED, PacketKind.FAILED):
            self._outstanding.discard(packet.request_id)
            self._last_activity = now

    def _idle_deadline(self) -> float:
        if self._idle_timeout is None or self.role is not Role.CONTROLLER or self._outstanding:
            return math.inf
        return self._last_activity + self._idle_timeout

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

    def _may_be_untagged(self, kind: PacketKind) -> bool:
        # The AUTH's tag is checked by _accept_packet: a bad one is a wrong key.
        return kind is PacketKind.AUTH and self._state is SessionState.CHALLENGED

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
        self._last_activity = now
        rid = packet.request_id
        if rid == 0:
            # 0 means "no request" in replies; a command named 0 could never be
            # told apart from an unattributable rejection.
            self._reject(
                FailureReason.BAD_PACKET, "request id 0 is reserved; number from 1", 0, now
            )
            return
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
        seen = packet.aux[0]
        if not (seen == int(seen) and 0 <= seen < 2**32):
            self._reject(
                FailureReason.BAD_PACKET, f"COMMAND aux[0] {seen!r} is no request id", rid, now
            )
            return
        command = Command(CommandCode(packet.code), packet.words(), CommandFlags(packet.flags))
        try:
            validate_arguments(command)
        except CommandFailed as exc:
            self.failed(rid, packet.code, exc.reason, exc.message, exc.aux, now)
            return
        self._events.append(CommandReceived(rid, command, int(seen)))
