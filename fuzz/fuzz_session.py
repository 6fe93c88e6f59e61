"""atheris harness: the tcpstream session handshake and command path (sans-I/O cores).

The first byte picks a target; the rest is a script of operations on it:
well-formed packets of any kind and field values (tag zero or arbitrary; the
fuzzer never holds the key), raw bytes, time steps that fire timers, and an
honest exchange with a client that holds the *wrong* key.

* keyed arm (ServerConnection with a key): no input may ever produce
  ``ControlRequested`` or ``CommandReceived`` -- authentication cannot be
  bypassed by any byte sequence without the key;
* keyed controller (ClientConnection with a key, after its HELLO): no input may
  produce ``Granted`` -- an arm without the key cannot impersonate the arm;
* unkeyed arm, granting every request: commands that reach the application
  (``CommandReceived``) have finite arguments that pass ``validate_arguments``,
  and request ids are never 0;
* for all targets: ``receive_data`` and ``handle_timer`` never raise, the
  state never leaves CLOSED once there, and the input buffer stays below one
  packet after a call.
"""

from __future__ import annotations

import struct
import sys

from fuzz._instrument import instrumented
from fuzz._reader import Reader

with instrumented(__name__ == "__main__"):
    from tcpstream.commands import (
        PACKET_SIZE,
        Packet,
        PacketKind,
        encode_packet,
        validate_arguments,
    )
    from tcpstream.connection import (
        ClientConnection,
        CommandReceived,
        ControllerIdentity,
        ControlRequested,
        Granted,
        ServerConnection,
        SessionParameters,
        SessionState,
    )

KEY = b"fuzz-harness-right-key-0123456789"
WRONG_KEY = b"fuzz-harness-wrong-key-0123456789"
PARAMS = SessionParameters(
    heartbeat_interval=2.0, dead_time=10.0, telemetry_period=0.0, memory_size=64
)
_KINDS = tuple(PacketKind)
_D = struct.Struct("!d")


def _nonces(n: int) -> bytes:
    return bytes(n)  # deterministic: the fuzzer must be able to replay its inputs


def _packet(r: Reader) -> bytes:
    kind = _KINDS[r.byte() % len(_KINDS)]
    aux = tuple(
        _D.unpack(r.take(8).ljust(8, b"\0"))[0] if r.byte() % 4 == 0 else 0.0 for _ in "abcd"
    )
    packet = Packet(
        kind,
        flags=r.u16(),
        code=r.u16() % 32,
        status=r.u16() % 16,
        request_id=r.byte(),
        counter=r.byte() % 8,
        aux=aux,
        body=r.take(r.byte()).ljust(144, b"\0")[:144],
        tag=r.take(16).ljust(16, b"\0") if r.byte() % 2 else bytes(16),
    )
    try:
        return encode_packet(packet)
    except (ValueError, struct.error):
        return bytes(PACKET_SIZE)


def one_input(data: bytes) -> None:
    r = Reader(data)
    target = r.byte() % 3
    now = 0.0
    conn: ServerConnection | ClientConnection
    honest: ClientConnection | None = None
    if target == 2:
        conn = ClientConnection(
            ControllerIdentity("fuzz", 1), key=KEY, now=now, nonce_source=_nonces
        )
        conn.connect(now)
        conn.data_to_send()
    else:
        conn = ServerConnection(
            PARAMS, key=KEY if target == 0 else None, now=now, nonce_source=_nonces
        )
        honest = ClientConnection(
            ControllerIdentity("liar", 2), key=WRONG_KEY if target == 0 else None, now=now
        )
    was_closed = False
    while r.remaining:
        op = r.byte() % 5
        if op in (0, 1):
            conn.receive_data(_packet(r), now)
        elif op == 2:
            conn.receive_data(r.take(r.byte()), now)
        elif op == 3:
            now += r.byte() * 0.1
            if (timer := conn.get_timer()) is not None and timer <= now:
                conn.handle_timer(now)
        elif honest is not None:
            if honest.state is SessionState.IDLE:
                honest.connect(now)
            conn.receive_data(honest.data_to_send(), now)
            honest.receive_data(conn.data_to_send(), now)
            while honest.next_event() is not None:
                pass
        while (event := conn.next_event()) is not None:
            if isinstance(event, ControlRequested):
                if target == 0:
                    raise AssertionError(f"keyed arm let {event!r} through without the key")
                assert isinstance(conn, ServerConnection)
                conn.grant(event.role, 0, now)
            elif isinstance(event, CommandReceived):
                if target == 0:
                    raise AssertionError(f"keyed arm accepted {event!r} without the key")
                if event.request_id == 0:
                    raise AssertionError("command with request id 0 delivered")
                validate_arguments(event.command)
            elif isinstance(event, Granted):
                raise AssertionError(f"keyed controller granted by an arm without the key: {event}")
        conn.data_to_send()
        if was_closed and conn.state is not SessionState.CLOSED:
            raise AssertionError(f"left CLOSED for {conn.state}")
        was_closed = conn.state is SessionState.CLOSED
        if len(conn._inbuf) >= PACKET_SIZE:
            raise AssertionError(f"{len(conn._inbuf)} bytes left unparsed")


if __name__ == "__main__":
    from fuzz._atheris import run

    run(one_input)
    sys.exit(0)
