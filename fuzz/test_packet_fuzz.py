"""Property fuzzing of the packet layer (``make fuzz`` runs it with the deep profile).

The same properties run in ``make test`` with the derandomized CI profile; here
hypothesis explores fresh inputs on every run.
"""

from __future__ import annotations

from collections.abc import Callable

from hypothesis import given
from hypothesis import strategies as st

from serialsocket import MalformedDataError
from serialsocket.packets import (
    EIGHT_BIT_CLEAN,
    PRINTABLE,
    PacketParser,
    PacketReceived,
    build_packet,
)


def _outcome(fn: Callable[[bytes], bytes], data: bytes) -> bytes | str:
    """The decoded bytes, or the error type's name: both decoders must agree."""
    try:
        return fn(data)
    except MalformedDataError as exc:
        return type(exc).__name__


@given(st.lists(st.binary(max_size=300), max_size=20), st.integers(12, 9031))
def test_parser_survives_any_byte_stream(chunks: list[bytes], max_len: int) -> None:
    parser = PacketParser(max_length=max_len)
    for chunk in chunks:
        parser.receive_data(chunk)
        while (ev := parser.next_event()) is not None:
            if isinstance(ev, PacketReceived):
                # Anything accepted re-serialises to a packet the parser accepts again.
                again = PacketParser(max_length=max(max_len, ev.length))
                again.receive_data(build_packet(ev.packet, ev.check))
                assert isinstance(again.next_event(), PacketReceived)
                for enc in (PRINTABLE, EIGHT_BIT_CLEAN):
                    assert _outcome(enc.decode, ev.packet.data) == _outcome(
                        enc._decode_sequential, ev.packet.data
                    )
        assert parser.buffered <= max(max_len, len(chunk))
