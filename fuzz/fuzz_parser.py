"""atheris harness: the Kermit packet parser and the prefix decoders.

Input: a byte stream cut into chunks at positions the fuzzer chooses, fed to a
:class:`~serialsocket.packets.PacketParser` whose ``max_length`` and expected block
check are also chosen by the fuzzer.  Properties (any violation raises):

* the parser never raises on input: damage is a counted ``PacketRejected``;
* it buffers at most one packet of ``max_length`` plus the last chunk;
* every accepted packet re-serialises to bytes the parser accepts again as the
  same packet;
* both prefix decoders (``decode`` and the sequential reference) agree on the
  accepted packet's data, raising only ``MalformedDataError``.
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
        PacketParser,
        PacketReceived,
        PacketRejected,
        Radix91Encoding,
        build_packet,
    )

_CHECKS = tuple(BlockCheck)
_DENSE = (EscapeEncoding(), EscapeEncoding(unsafe=XON_XOFF), Radix91Encoding())


def _decoded(decode: object, data: bytes) -> bytes | str:
    try:
        return decode(data)  # type: ignore[operator,no-any-return]
    except MalformedDataError as exc:
        return type(exc).__name__


def one_input(data: bytes) -> None:
    if len(data) < 3:
        return
    max_length = 12 + int.from_bytes(data[:2], "big") % 9020
    check = _CHECKS[data[2] % len(_CHECKS)]
    stream = data[3:]
    parser = PacketParser(max_length=max_length, check=check)
    pos = 0
    step = 1 + (data[2] >> 2)
    while pos < len(stream):
        chunk = stream[pos : pos + step]
        pos += step
        parser.receive_data(chunk)
        while (event := parser.next_event()) is not None:
            if isinstance(event, PacketReceived):
                again = PacketParser(max_length=max(max_length, event.length), check=event.check)
                again.receive_data(build_packet(event.packet, event.check))
                echo = again.next_event()
                if not isinstance(echo, PacketReceived) or echo.packet != event.packet:
                    raise AssertionError(f"re-serialised {event.packet!r} parsed as {echo!r}")
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


if __name__ == "__main__":
    from fuzz._atheris import run

    run(one_input)
    sys.exit(0)
