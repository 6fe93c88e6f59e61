"""Pre-shared-key authentication: challenge-response, session keys, packet tags.

PROTOCOL.md section 8.  The design answers the MAVLink signing pitfalls of
``shared/reference/peers.md``:

* No clock in the replay defence: each direction of each session carries a
  counter that starts at 1 and only ever grows.  An idle controller cannot fall
  behind a clock, and nothing is cached already-signed: a command re-sent after a
  reconnect is re-encoded with the new session's key and counter.
* Both sides contribute a fresh nonce, and the session key is derived from
  both, so a packet recorded in one session verifies in no other.
* The direction is bound into every tag, so a packet cannot be reflected back
  to its sender.
* The controller proves it knows the key before it is granted anything, and
  the arm proves it back in the GRANT, so a controller cannot be fooled by a
  look-alike arm.
* Every comparison is constant time (:func:`hmac.compare_digest`) and a
  failure is reported with the same words whatever was wrong.

Pure functions; nonces come from the caller (the session takes a
``nonce_source``, :func:`secrets.token_bytes` by default).
"""

from __future__ import annotations

import hashlib
import hmac
import struct

from ._packet import SIGNED_SIZE, TAG_SIZE

__all__ = [
    "MIN_KEY_SIZE",
    "NONCE_SIZE",
    "PROOF_SIZE",
    "client_proof",
    "derive_session_key",
    "packet_tag",
    "server_proof",
    "verify",
]

NONCE_SIZE = 16
"""128-bit nonces: a repeat needs ~2^64 sessions (birthday bound)."""
PROOF_SIZE = 32
"""Full HMAC-SHA256 in the handshake: it is sent once, so there is no reason to cut it."""
MIN_KEY_SIZE = 16
"""Refuse shorter keys: a pre-shared key is the only secret the arm has."""

_CLIENT_LABEL = b"telelink-v1 client proof"
_SERVER_LABEL = b"telelink-v1 server proof"
_SESSION_LABEL = b"telelink-v1 session key"

TO_SERVER = b"\x01"
"""Direction byte for packets the controller sends."""
TO_CLIENT = b"\x02"
"""Direction byte for packets the arm sends."""
TO_SERVER_EXPEDITED = b"\x03"
"""Direction byte for the controller's packets on a transport's expedited lane
(PROTOCOL.md section 15): their own counter, so the lane may overtake the
stream without either looking replayed, and a tag that verifies on no other
path."""


def _transcript(
    client_nonce: bytes, server_nonce: bytes, identity: bytes, incarnation: int, role: int
) -> bytes:
    # Fixed-width fields (the identity is already padded to 32 bytes), so no
    # two different transcripts concatenate to the same bytes.
    return client_nonce + server_nonce + identity + struct.pack("!QB", incarnation, role)


def client_proof(
    key: bytes,
    client_nonce: bytes,
    server_nonce: bytes,
    identity: bytes,
    incarnation: int,
    role: int,
) -> bytes:
    """The AUTH body: proves the controller holds ``key`` for this exact handshake."""
    msg = _CLIENT_LABEL + _transcript(client_nonce, server_nonce, identity, incarnation, role)
    return hmac.new(key, msg, hashlib.sha256).digest()


def server_proof(
    key: bytes,
    client_nonce: bytes,
    server_nonce: bytes,
    identity: bytes,
    incarnation: int,
    role: int,
) -> bytes:
    """The GRANT body: proves the arm holds ``key`` too (mutual authentication)."""
    msg = _SERVER_LABEL + _transcript(client_nonce, server_nonce, identity, incarnation, role)
    return hmac.new(key, msg, hashlib.sha256).digest()


def derive_session_key(
    key: bytes, client_nonce: bytes, server_nonce: bytes, identity: bytes, incarnation: int
) -> bytes:
    """The per-session MAC key: fresh for every session because both nonces are."""
    msg = _SESSION_LABEL + _transcript(client_nonce, server_nonce, identity, incarnation, 0)
    return hmac.new(key, msg, hashlib.sha256).digest()


def packet_tag(session_key: bytes, direction: bytes, signed: bytes) -> bytes:
    """The 16-byte tag over a packet's first :data:`SIGNED_SIZE` bytes and its direction."""
    if len(signed) != SIGNED_SIZE:
        raise ValueError(f"tag covers exactly {SIGNED_SIZE} bytes")
    return hmac.new(session_key, direction + signed, hashlib.sha256).digest()[:TAG_SIZE]


def verify(expected: bytes, received: bytes) -> bool:
    """Constant-time comparison (never ``==`` on secrets)."""
    return hmac.compare_digest(expected, received)
