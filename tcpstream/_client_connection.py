"""The controller's end of a session, sans-I/O: HELLO, AUTH, commands, replies (PROTOCOL.md 7-8)."""

from __future__ import annotations

import secrets
import struct
from collections.abc import Callable

from . import _auth
from ._commands import (
    Command,
    CommandCode,
    CommandResult,
    FailureReason,
    Feedback,
)
from ._connection import _IDENTITY, _Connection, _identity_bytes
from ._errors import LocalProtocolError
from ._events import (
    Accepted,
    CloseReason,
    Completed,
    ControllerIdentity,
    Failed,
    Granted,
    RefusalReceived,
    RefuseReason,
    Role,
    SessionEnded,
    SessionParameters,
    TelemetryReceived,
)
from ._packet import (
    BODY_SIZE,
    Packet,
    PacketError,
    PacketKind,
    unpack_text,
    words_body,
)
from ._state import SessionState, Side, Trigger

__all__ = ["ClientConnection"]


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
        self.arm_reads_lane = False
        """The arm's GRANT said it reads EMERGENCY_STOP from the transport's
        expedited lane (PROTOCOL.md 15): only then does a stop go there, so an
        arm whose session layer does not read the lane still gets it."""
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

    def send_command(
        self, request_id: int, command: Command, now: float, *, failures_seen: int = 0
    ) -> None:
        """Send a command (EMERGENCY_STOP goes as its own packet kind, on the
        transport's expedited lane when there is one (:attr:`expedited`) and
        the arm said it reads it (:attr:`arm_reads_lane`)).

        ``failures_seen``: the highest request id of a FAILED reply received so
        far (PROTOCOL.md section 9, the failure barrier).
        """
        if not 0 < request_id < 2**32:
            raise LocalProtocolError(f"request id {request_id} outside 1..2**32-1")
        if not 0 <= failures_seen < 2**32:
            raise LocalProtocolError(f"failures_seen {failures_seen} outside 0..2**32-1")
        self._move(Trigger.COMMAND)
        if command.code is CommandCode.EMERGENCY_STOP:
            stop = Packet(PacketKind.EMERGENCY_STOP, code=command.code, request_id=request_id)
            if self.expedited and self.arm_reads_lane:
                # Ahead of everything queued on the stream (PROTOCOL.md 15).
                self._send_expedited(stop, now)
            else:
                self._send(stop, now)
            return
        self._send(
            Packet(
                PacketKind.COMMAND,
                flags=command.flags,
                code=command.code,
                request_id=request_id,
                aux=(float(failures_seen), 0.0, 0.0, 0.0),
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
        instance, remembered, lane = struct.unpack_from("!QBB", packet.body, _auth.PROOF_SIZE)
        self.arm_reads_lane = lane == 1
        self._events.append(
            Granted(role, params, packet.request_id, instance, remembered=remembered == 1)
        )

    def _may_be_untagged(self, kind: PacketKind) -> bool:
        # The arm refuses a bad AUTH with an untagged REFUSE (it cannot assume
        # we hold the key); after the GRANT nothing untagged is believed.
        return kind is PacketKind.REFUSE and self._state is SessionState.AUTH_SENT

    def _undecodable(self, exc: PacketError, raw: bytes, request_id: int, now: float) -> None:
        # A COMPLETED or FAILED the codec rejects (a non-finite word, say) still
        # answers its command: settle it now as failed, as for a COMPLETED whose
        # feedback does not decode, rather than leave the caller to time out --
        # and record it as a failure seen, so the arm's failure barrier and what
        # this client was told stay in step.
        super()._undecodable(exc, raw, request_id, now)
        kind, code = raw[3], int.from_bytes(raw[6:8], "big")
        if request_id and self._state is SessionState.OPEN and kind in _ANSWERS:
            why = (
                f"the arm's {PacketKind(kind).name} could not be decoded ({exc.message}); "
                "outcome unknown: check the arm with STATUS"
            )
            self._events.append(
                Failed(request_id, code, FailureReason.BAD_PACKET, why, (0.0, 0.0, 0.0, 0.0))
            )

    def _on_reply(self, packet: Packet, now: float) -> None:
        self._move(Trigger.REPLY_IN)
        kind, rid = packet.kind, packet.request_id
        aux = (packet.aux[0], packet.aux[1], packet.aux[2], packet.aux[3])
        if kind is PacketKind.FAILED:
            text = unpack_text(packet.body)
            try:
                reason = FailureReason(packet.status)
            except ValueError:  # a newer arm's reason: keep its number in the text
                reason = FailureReason.ARM_FAULT
                text = f"(reason code {packet.status}) {text}"
            self._events.append(Failed(rid, packet.code, reason, text, aux))
            return
        if kind is PacketKind.TELEMETRY:
            try:
                feedback = Feedback.from_words(packet.words())
            except ValueError as exc:
                self._reject(FailureReason.BAD_PACKET, f"bad telemetry: {exc}", 0, now)
                return
            self._events.append(TelemetryReceived(int(aux[0]), feedback))
            return
        if kind is PacketKind.ACCEPTED:
            try:
                self._events.append(Accepted(rid, CommandCode(packet.code), int(aux[0])))
            except ValueError:  # counted; the COMPLETED or FAILED still settles it
                self._reject(
                    FailureReason.BAD_PACKET, f"ACCEPTED names code {packet.code}", rid, now
                )
            return
        try:
            code = CommandCode(packet.code)
            feedback = Feedback.from_words(packet.words())
        except ValueError as exc:
            # Count it like any bad packet, and settle the command it answers:
            # left pending, its caller would hang until the session ended.
            why = f"the arm's COMPLETED could not be decoded ({exc}); check the arm with STATUS"
            self._reject(FailureReason.BAD_PACKET, why, rid, now)
            if rid:
                self._events.append(Failed(rid, packet.code, FailureReason.BAD_PACKET, why, aux))
            return
        self._events.append(Completed(rid, code, CommandResult(feedback, aux)))


_ANSWERS = frozenset({PacketKind.COMPLETED.value, PacketKind.FAILED.value})
"""The kinds that settle a command."""
