"""atheris harness: the Kermit packet parser and the prefix decoders.

Input: a byte stream cut into chunks at positions the fuzzer chooses, fed to a
:class:`~serialsocket.packets.PacketParser` whose ``max_length``, expected block
check and ``correction`` (``d`` packets repaired, PROTOCOL.md section 15;
bit 7 of the second byte) are also chosen by the fuzzer.  Properties (any
violation raises):

* the parser never raises on input: damage is a counted ``PacketRejected``;
* it buffers at most one packet of ``max_length`` plus the last chunk;
* every accepted packet re-serialises to bytes the parser accepts again as the
  same packet;
* both prefix decoders (``decode`` and the sequential reference) agree on the
  accepted packet's data, raising only ``MalformedDataError``;
* every dense decoder (escape code, escape with XON/XOFF, radix 91; PROTOCOL.md
  section 10) accepts an accepted packet's data only in its canonical encoding;
* with ``correction``, every accepted ``D`` packet sent as a ``d`` packet
  (``build_corrected``) with one character damaged, anywhere past LEN, TYPE
  and the extended header and before the check, to any value but MARK, is
  read back as the same packet (PROTOCOL.md 15.3), and damaged in the
  check it is never read as another packet.

The same cut chunks, and the data fields of the accepted packets, are then
decoded as the fields of one arrival by every encoding, prefix and dense:

* ``decode_fields`` (what the ARQ receiver calls) decodes exactly as
  ``decode`` field by field: the same bytes, or ``MalformedDataError`` when
  any field is malformed on its own (no token may cross a field, PROTOCOL.md
  sections 1 and 10.3-10.4);
* ``encode_fields`` of the stream at a capacity the fuzzer chooses cuts
  fields of at most that many characters, carrying at least one byte each,
  the same fields as ``encode_prefix`` over what is left, and they decode
  back to the bytes they carry.
"""

from __future__ import annotations

import sys

from fuzz._instrument import instrumented

with instrumented(__name__ == "__main__"):
    from serialsocket import MalformedDataError
    from serialsocket.packets import (
        EIGHT_BIT_CLEAN,
        PRINTABLE,
        XON_XOFF,
        BlockCheck,
        EscapeEncoding,
        Packet,
        PacketParser,
        PacketReceived,
        PacketRejected,
        Radix91Encoding,
        build_corrected,
        build_packet,
    )

_CHECKS = tuple(BlockCheck)
_DENSE = (EscapeEncoding(), EscapeEncoding(unsafe=XON_XOFF), Radix91Encoding())
_ALL = (PRINTABLE, EIGHT_BIT_CLEAN, *_DENSE)
_MIN_CAPACITY = 5
"""The smallest capacity every encoding cuts fields at (a prefix token)."""


def _decoded(decode: object, data: bytes) -> bytes | str:
    try:
        return decode(data)  # type: ignore[operator,no-any-return]
    except MalformedDataError as exc:
        return type(exc).__name__


def _check_fields(fields: list[bytes]) -> None:
    """``decode_fields`` decodes as ``decode`` field by field, or raises when it does."""
    for enc in _ALL:
        each = [_decoded(enc.decode, f) for f in fields]
        together = _decoded(enc.decode_fields, fields)
        if all(isinstance(e, bytes) for e in each):
            expected: bytes | str = b"".join(e for e in each if isinstance(e, bytes))
        else:
            expected = "MalformedDataError"
        if together != expected:
            raise AssertionError(
                f"{enc!r}.decode_fields({fields!r}) = {together!r}, field by field {expected!r}"
            )


def _check_cutting(stream: bytes, capacity: int, count: int) -> None:
    """``encode_fields`` cuts what ``encode_prefix`` cuts, within capacity, and decodes back."""
    for enc in _ALL:
        fields = enc.encode_fields(stream, capacity, count)
        carried = 0
        for field, n in fields:
            prefix = enc.encode_prefix(stream[carried:], capacity)
            if (field, n) != prefix or len(field) > capacity or n < 1:
                raise AssertionError(
                    f"{enc!r}: field {field!r} carrying {n} at {carried}, "
                    f"encode_prefix {prefix!r}, capacity {capacity}"
                )
            carried += n
        if len(fields) < count and carried != len(stream):
            raise AssertionError(f"{enc!r}: {len(fields)} fields carried {carried} bytes")
        back = enc.decode_fields([f for f, _ in fields])
        if back != stream[:carried]:
            raise AssertionError(f"{enc!r}: cut fields decode to {back!r}")


def _check_repair(packet: Packet, check: BlockCheck, where: int, value: int) -> None:
    """``packet`` as a ``d`` packet damaged at one character is read back as
    itself where the sums repair it (SEQ of a normal packet, and past the
    header before the check) and rejected when the damage is in the check.  (Damage
    to LEN or TYPE reframes the packet: CRC-16 then passes it about once in
    65 536 tries, not a property to hold the repair to.)"""
    wire = build_corrected(packet.seq, packet.data, check)[:-1]  # (no CR)
    at = 1 + where % (len(wire) - 1)
    if value == 1 or wire[at] == value:
        return
    damaged = wire[:at] + bytes((value,)) + wire[at + 1 :]
    reader = PacketParser(max_length=len(wire), check=check, correction=True)
    reader.receive_data(damaged)
    got = reader.next_event()
    header = 7 if wire[1] == 32 else 4
    repairable = (at == 2 and header == 4) or header <= at < len(wire) - int(check)
    if at >= len(wire) - int(check):
        if isinstance(got, PacketReceived):
            raise AssertionError(f"{damaged!r} (its check damaged) read as {got.packet!r}")
    elif repairable and (not isinstance(got, PacketReceived) or got.packet != packet):
        raise AssertionError(f"{damaged!r} (damaged at {at}) read as {got!r}, not {packet!r}")


def one_input(data: bytes) -> None:
    if len(data) < 3:
        return
    max_length = 12 + int.from_bytes(data[:2], "big") % 9020
    check = _CHECKS[data[2] % len(_CHECKS)]
    correction = bool(data[1] & 0x80)
    stream = data[3:]
    parser = PacketParser(max_length=max_length, check=check, correction=correction)
    pos = 0
    step = 1 + (data[2] >> 2)
    chunks: list[bytes] = []
    accepted: list[bytes] = []
    while pos < len(stream):
        chunk = stream[pos : pos + step]
        chunks.append(chunk)
        pos += step
        parser.receive_data(chunk)
        while (event := parser.next_event()) is not None:
            if isinstance(event, PacketReceived):
                accepted.append(event.packet.data)
                again = PacketParser(max_length=max(max_length, event.length), check=event.check)
                again.receive_data(build_packet(event.packet, event.check))
                echo = again.next_event()
                if not isinstance(echo, PacketReceived) or echo.packet != event.packet:
                    raise AssertionError(f"re-serialised {event.packet!r} parsed as {echo!r}")
                if correction and event.packet.type == "D" and int(event.check) >= 3:
                    _check_repair(event.packet, event.check, data[0] * 256 + data[1], data[2])
                for enc in (PRINTABLE, EIGHT_BIT_CLEAN):
                    fast = _decoded(enc.decode, event.packet.data)
                    slow = _decoded(enc._decode_sequential, event.packet.data)
                    if fast != slow:
                        raise AssertionError(f"decoders disagree: {fast!r} != {slow!r}")
                for dense in _DENSE:
                    plain = _decoded(dense.decode, event.packet.data)
                    if isinstance(plain, bytes) and dense.encode(plain) != event.packet.data:
                        raise AssertionError(f"{dense!r} accepted a non-canonical field")
            elif not isinstance(event, PacketRejected):
                raise AssertionError(f"unexpected event {event!r}")
        if parser.buffered > max(max_length, len(chunk)) + len(chunk):
            raise AssertionError(f"parser holds {parser.buffered} bytes")
    _check_fields(chunks)
    if accepted:
        _check_fields(accepted)
    _check_cutting(stream, _MIN_CAPACITY + data[0] % 128 + data[1] % 128, 1 + data[1] % 8)


if __name__ == "__main__":
    from fuzz._atheris import run

    run(one_input)
    sys.exit(0)
