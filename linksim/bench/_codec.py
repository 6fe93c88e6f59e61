"""``linksim bench codec``: Kermit encode/decode speed on this machine.

Measures, for 1 MiB (by default) of random binary and of text, in the default
printable profile, the 8-bit-clean profile, and the dense encodings of
serialsocket/DENSE.md (``escape``, ``escape+xon``, ``radix91``; not
negotiated yet):

* ``encode`` / ``decode``: the data-field codec over the whole buffer;
* ``packetize`` / ``parse``: the full packet path at a given maximum packet
  length -- cut into data fields a window (31 packets) at a time, frame with
  CRC-16; then parse the wire stream 64 KiB at a time (the serial socket's
  read size) and decode the fields of each read together;
* ``parse_per_field`` (JSON only): the same parse, decoding every field on
  its own, one call per packet.

Each figure is the best of ``--repeat`` runs in process CPU time (the least
disturbed by other load; the codec is single-threaded, so on an idle machine
this is the wall time too), in MB/s of *payload* (10^6 bytes).  This is a
benchmark, not a test.
"""

from __future__ import annotations

import random
import time
from collections.abc import Callable
from functools import partial
from typing import Protocol

from serialsocket.packets import (
    EIGHT_BIT_CLEAN,
    PRINTABLE,
    XON_XOFF,
    BlockCheck,
    EscapeEncoding,
    Packet,
    PacketParser,
    PacketReceived,
    PacketType,
    Radix91Encoding,
    build_packet,
    data_capacity,
)

__all__ = ["PROFILES", "run", "sample_payload"]


class _FieldCodec(Protocol):
    """What a sender and a receiver use of a data-field encoding."""

    def encode(self, data: bytes, /) -> bytes: ...
    def decode(self, field: bytes, /) -> bytes: ...
    def decode_fields(self, fields: list[bytes], /) -> bytes: ...
    def encode_fields(
        self, data: memoryview, capacity: int, count: int, /
    ) -> list[tuple[bytes, int]]: ...


PROFILES: tuple[tuple[str, _FieldCodec], ...] = (
    ("printable", PRINTABLE),
    ("8bit", EIGHT_BIT_CLEAN),
    ("escape", EscapeEncoding()),
    ("escape+xon", EscapeEncoding(unsafe=XON_XOFF)),
    ("radix91", Radix91Encoding()),
)
"""The Kermit profiles, then the dense encodings (serialsocket/DENSE.md; not
negotiated yet): 8-bit escape of MARK and CAN only, or of XON/XOFF too, and
radix-91 for printable lines."""

_WORDS = (
    "move arm to position rock bin center fingers close open weigh return home joint velocity "
    "gripper approach sliding vector tactile error telemetry command status link delay moon "
    "earth packet window retransmit 0.25 1.30 -12.5 90.0 45 7 3"
).split()


def sample_payload(kind: str, size: int, seed: int = 1) -> bytes:
    """Deterministic benchmark data: ``binary`` (uniform random) or ``text`` (word salad)."""
    rng = random.Random(seed)
    if kind == "binary":
        return rng.randbytes(size)
    out: list[str] = []
    length = 0
    while length < size:
        line = " ".join(rng.choice(_WORDS) for _ in range(rng.randint(4, 12))) + "\n"
        out.append(line)
        length += len(line)
    return "".join(out).encode()[:size]


def _best(fn: Callable[[], object], repeat: int) -> float:
    """Least CPU time of ``repeat`` calls: the codec is single-threaded and
    CPU-bound, so on a shared machine process time measures it and wall time
    measures the neighbours (on an idle machine the two agree)."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def _packetize(data: bytes, enc: _FieldCodec, max_len: int) -> bytes:
    cap = data_capacity(max_len, BlockCheck.CRC16)
    view = memoryview(data)
    wire: list[bytes] = []
    append = wire.append
    at = seq = 0
    data_type = PacketType.DATA  # (an Enum member lookup costs ~0.2 us in Python 3.11)
    while at < len(data):
        # A sender fills a window at a time: 31 packets, Kermit's largest window.
        for field, used in enc.encode_fields(view[at:], cap, 31):
            append(build_packet(Packet(seq=seq, type=data_type, data=field)))
            at += used
            seq = (seq + 1) & 63
    return b"".join(wire)


READ_SIZE = 65536
"""Bytes per read in the parse figure: what the serial socket's driver asks
the port for (``serialsocket._driver._READ_SIZE``)."""


def _parse(wire: bytes, enc: _FieldCodec, max_len: int, read: int = READ_SIZE) -> bytes:
    """Parse ``read`` bytes at a time; decode the fields of each read together
    (``decode_fields``: one vectorised pass, as ``Receiver.take_fields`` does
    with the fields of one arrival).
    """
    parser = PacketParser(max_length=max_len)
    out: list[bytes] = []
    for at in range(0, len(wire), read):
        parser.receive_data(wire[at : at + read])
        fields: list[bytes] = []
        while (ev := parser.next_event()) is not None:
            if isinstance(ev, PacketReceived):
                fields.append(ev.packet.data)
        out.append(enc.decode_fields(fields))
    return b"".join(out)


def _parse_per_field(wire: bytes, enc: _FieldCodec, max_len: int) -> bytes:
    """Parse the whole stream; decode every field on its own (one call per packet)."""
    parser = PacketParser(max_length=max_len)
    parser.receive_data(wire)
    out: list[bytes] = []
    while (ev := parser.next_event()) is not None:
        if isinstance(ev, PacketReceived):
            out.append(enc.decode(ev.packet.data))
    return b"".join(out)


def run(size: int, repeat: int, max_len: int) -> list[dict[str, object]]:
    """Measure every combination; returns one record per (data, profile)."""
    results: list[dict[str, object]] = []
    for kind in ("binary", "text"):
        data = sample_payload(kind, size)
        for name, enc in PROFILES:
            field = enc.encode(data)
            if enc.decode(field) != data:
                raise AssertionError(f"codec round trip failed for {kind}/{name}")
            wire = _packetize(data, enc, max_len)
            if _parse(wire, enc, max_len) != data or _parse_per_field(wire, enc, max_len) != data:
                raise AssertionError(f"packet round trip failed for {kind}/{name}")
            mb = size / 1e6
            results.append(
                {
                    "data": kind,
                    "profile": name,
                    "bytes": size,
                    "expansion": round(len(field) / size, 4),
                    "encode_MBps": round(mb / _best(partial(enc.encode, data), repeat), 2),
                    "decode_MBps": round(mb / _best(partial(enc.decode, field), repeat), 2),
                    "max_len": max_len,
                    "wire_bytes": len(wire),
                    "packetize_MBps": round(
                        mb / _best(partial(_packetize, data, enc, max_len), repeat), 2
                    ),
                    "parse_MBps": round(mb / _best(partial(_parse, wire, enc, max_len), repeat), 2),
                    "parse_per_field_MBps": round(
                        mb / _best(partial(_parse_per_field, wire, enc, max_len), repeat), 2
                    ),
                }
            )
    return results
