"""atheris harness: the tcpstream command-packet decoder.

Input: the first byte picks a shape -- raw bytes of any length, or exactly
:data:`~tcpstream.commands.PACKET_SIZE` bytes with a correct magic and version so the
fuzzer spends its time in the field checks.  Properties (any violation raises):

* :func:`~tcpstream.commands.decode_packet` either returns a :class:`~tcpstream.commands.Packet`
  or raises a :class:`~tcpstream.commands.PacketError` subclass carrying a
  ``FailureReason`` (never ``struct.error``, ``ValueError`` or the like);
* a decoded packet re-encodes to exactly the input bytes (nothing the decoder
  accepts is ambiguous), its words are finite, and ``describe()`` works;
* a COMMAND's arguments through ``validate_arguments`` pass or fail with
  ``BAD_ARGUMENT``, never another exception.

The same input is also read as a **teleoperation packet** (tcpstream
PROTOCOL.md section 14; with a shape that is not 0 mod 4 its header is forced
to ``TT``, version 1 and a kind chosen by the next byte, so the field checks
see most inputs):

* :func:`~tcpstream.teleop.decode_header` returns a known kind and that
  kind's size, or raises :class:`~tcpstream.teleop.TeleopPacketError`;
* a SAMPLE or REPLY decodes or raises ``TeleopPacketError`` (never
  ``struct.error`` or ``ValueError``), its reals are finite, and it re-encodes
  to exactly the input bytes before the tag (nothing accepted is ambiguous).
"""

from __future__ import annotations

import math
import sys

from fuzz._instrument import instrumented

with instrumented(__name__ == "__main__"):
    from tcpstream import Command, CommandCode, CommandFailed, FailureReason
    from tcpstream.commands import (
        MAGIC,
        NUMERIC_KINDS,
        PACKET_SIZE,
        PROTOCOL_VERSION,
        CommandFlags,
        PacketError,
        PacketKind,
        decode_packet,
        encode_packet,
        validate_arguments,
    )
    from tcpstream.teleop import (
        MAGIC as TELEOP_MAGIC,
    )
    from tcpstream.teleop import (
        TAG_SIZE,
        TELEOP_VERSION,
        TeleopKind,
        TeleopPacketError,
        decode_header,
        decode_reply,
        decode_sample,
        encode_reply,
        encode_sample,
        size_of,
    )

_TELEOP_KINDS = tuple(TeleopKind)


def one_input(data: bytes) -> None:
    if not data:
        return
    _command_packet(data)
    _teleop_packet(data)


def _teleop_packet(data: bytes) -> None:
    shape, rest = data[0], data[1:]
    if shape % 4 != 0 and rest:
        kind = _TELEOP_KINDS[rest[0] % len(_TELEOP_KINDS)]
        head = TELEOP_MAGIC + bytes([TELEOP_VERSION, kind])
        rest = (head + rest[4:]).ljust(size_of(kind), b"\0")[: size_of(kind)]
    try:
        kind, _, size = decode_header(rest)
    except TeleopPacketError:
        return
    if size != size_of(kind):
        raise AssertionError(f"{kind!r} decoded with size {size}")
    if len(rest) < size:
        return
    raw = rest[:size]
    try:
        if kind is TeleopKind.SAMPLE:
            sample = decode_sample(raw)
            reals = [sample.stamp, *sample.words]
            again = encode_sample(sample, int.from_bytes(raw[4:8], "big"), None, b"")
        elif kind is TeleopKind.REPLY:
            reply = decode_reply(raw)
            reals = [reply.stamp, reply.held, *reply.force, *reply.commanded, *reply.actual]
            again = encode_reply(reply, int.from_bytes(raw[4:8], "big"), None, b"")
        else:
            return
    except TeleopPacketError:
        return
    if not all(math.isfinite(x) for x in reals):
        raise AssertionError(f"non-finite real accepted in a {kind.name}")
    if again[:-TAG_SIZE] != raw[:-TAG_SIZE]:
        raise AssertionError(f"a {kind.name} does not re-encode to its input")


def _command_packet(data: bytes) -> None:
    shape, rest = data[0], data[1:]
    if shape % 4 != 0:
        rest = (MAGIC + bytes([PROTOCOL_VERSION]) + rest[3:]).ljust(PACKET_SIZE, b"\0")
        rest = rest[:PACKET_SIZE]
    try:
        packet = decode_packet(rest)
    except PacketError as exc:
        if not isinstance(exc.reason, FailureReason):
            raise AssertionError(f"{exc!r} has no FailureReason") from exc
        return
    if encode_packet(packet) != rest:
        raise AssertionError(f"{packet!r} does not re-encode to its input")
    if not all(math.isfinite(w) for w in packet.aux):
        raise AssertionError("non-finite aux word accepted")
    if packet.kind in NUMERIC_KINDS and not all(math.isfinite(w) for w in packet.words()):
        raise AssertionError("non-finite body word accepted")
    packet.describe()
    if packet.kind is PacketKind.COMMAND:
        command = Command(CommandCode(packet.code), packet.words(), CommandFlags(packet.flags))
        try:
            validate_arguments(command)
        except CommandFailed as exc:
            if exc.reason is not FailureReason.BAD_ARGUMENT:
                raise AssertionError(f"argument check failed with {exc.reason!r}") from exc


if __name__ == "__main__":
    from fuzz._atheris import run

    run(one_input)
    sys.exit(0)
