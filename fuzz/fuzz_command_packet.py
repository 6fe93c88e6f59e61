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


def one_input(data: bytes) -> None:
    if not data:
        return
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
