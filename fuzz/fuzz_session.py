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

A first byte of 0xF0 or more picks the **teleoperation channel** instead
(tcpstream PROTOCOL.md section 14; its sans-I/O ends), the same way: packets
of any kind with any counter and body and a guessed tag, raw bytes, and an
honest exchange with an operator that holds the wrong key:

* keyed arm (``ArmChannel``, even byte): no input ever produces
  ``OperatorArrived``, ``SampleArrived`` or ``StopArrived``;
* keyed operator (``OperatorChannel`` after its HELLO, odd byte): no input
  ever produces ``Granted`` or ``ReplyReceived``;
* both: ``receive_data`` never raises, CLOSED is never left, and less than
  one packet stays buffered.
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
    from tcpstream.teleop import (
        MAGIC as TELEOP_MAGIC,
    )
    from tcpstream.teleop import (
        TELEOP_VERSION,
        ArmChannel,
        ChannelState,
        OperatorArrived,
        OperatorChannel,
        ReplyReceived,
        SampleArrived,
        StopArrived,
        TeleopKind,
        size_of,
    )
    from tcpstream.teleop import (
        Granted as TeleopGranted,
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


_TELEOP_KINDS = tuple(TeleopKind)
_TELEOP_MAX = max(size_of(k) for k in TeleopKind)


def _teleop_packet(r: Reader) -> bytes:
    kind = _TELEOP_KINDS[r.byte() % len(_TELEOP_KINDS)]
    counter = r.byte() if r.byte() % 2 else int.from_bytes(r.take(4).ljust(4, b"\0"), "big")
    size = size_of(kind)
    head = TELEOP_MAGIC + bytes([TELEOP_VERSION, kind]) + counter.to_bytes(4, "big")
    return (head + r.take(r.byte())).ljust(size, b"\0")[:size]


def _teleop_input(r: Reader, arm_end: bool) -> None:
    now = 0.0
    end: ArmChannel | OperatorChannel
    honest: OperatorChannel | None = None
    if arm_end:
        end = ArmChannel(KEY, bytes(16), rate_deadman=1.0, control_rate=100.0)
        honest = OperatorChannel("liar", WRONG_KEY, bytes(range(16)))
    else:
        end = OperatorChannel("fuzz", KEY, bytes(16))
        end.connect()
        end.data_to_send()
    was_closed = False
    while r.remaining:
        op = r.byte() % 4
        now += 0.01
        if op in (0, 1):
            events = end.receive_data(_teleop_packet(r), now)
        elif op == 2:
            events = end.receive_data(r.take(r.byte()), now)
        elif honest is not None:
            if honest.state is ChannelState.IDLE:
                honest.connect()
            events = end.receive_data(honest.data_to_send(), now)
            honest.receive_data(end.data_to_send(), now)
        else:
            events = []
        for event in events:
            if isinstance(event, (OperatorArrived, SampleArrived, StopArrived)):
                raise AssertionError(f"keyed teleop arm let {event!r} through without the key")
            if isinstance(event, (TeleopGranted, ReplyReceived)):
                raise AssertionError(f"keyed teleop operator took {event!r} from a keyless arm")
        end.data_to_send()
        if was_closed and end.state is not ChannelState.CLOSED:
            raise AssertionError(f"teleop end left CLOSED for {end.state}")
        was_closed = end.state is ChannelState.CLOSED
        if len(end._buf) >= _TELEOP_MAX:
            raise AssertionError(f"{len(end._buf)} teleop bytes left unparsed")


def one_input(data: bytes) -> None:
    r = Reader(data)
    first = r.byte()
    if first >= 0xF0:
        _teleop_input(r, arm_end=first % 2 == 0)
        return
    target = first % 3
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
