"""An E packet is accepted only with the check in force (PROTOCOL.md section 2).

Kermit receivers also take an E with a 6-bit checksum; on a telelink
connection that let one bit error turn a data packet into a bogus abort about
once in 64 damaged packets (found by the deep ARQ fuzzer).
"""

from __future__ import annotations

import random

from serialsocket import EndpointConfig, State
from serialsocket.packets import (
    BlockCheck,
    Packet,
    PacketParser,
    PacketReceived,
    PacketRejected,
    RejectReason,
    build_packet,
)

from .simlink import connected_pair


def _events(parser: PacketParser, wire: bytes) -> list[object]:
    parser.receive_data(wire)
    out: list[object] = []
    while (ev := parser.next_event()) is not None:
        out.append(ev)
    return out


def _passes_as_error(wire: bytes) -> bool:
    """Would a Kermit receiver (type-1 E fallback) take this as an E packet?"""
    events = _events(PacketParser(max_length=9024), wire)
    return any(isinstance(e, PacketReceived) and e.packet.type == "E" for e in events)


def _d_to_e(wire: bytes) -> bytes:
    return wire[:3] + b"E" + wire[4:]


def test_the_fallback_is_kermits_and_can_be_turned_off() -> None:
    e_sum6 = build_packet(Packet(seq=0, type="E", data=b"disk full"), BlockCheck.SUM6)
    classic = _events(PacketParser(check=BlockCheck.CRC16), e_sum6)
    assert [type(e) for e in classic] == [PacketReceived]
    strict = _events(PacketParser(check=BlockCheck.CRC16, error_fallback=False), e_sum6)
    assert [type(e) for e in strict] == [PacketRejected]
    assert isinstance(strict[0], PacketRejected)
    assert strict[0].reason is RejectReason.BAD_CHECK
    e_crc = build_packet(Packet(seq=0, type="E", data=b"disk full"), BlockCheck.CRC16)
    strict = _events(PacketParser(check=BlockCheck.CRC16, error_fallback=False), e_crc)
    assert [type(e) for e in strict] == [PacketReceived]


def test_a_data_packet_damaged_into_an_error_does_not_abort_the_connection() -> None:
    damaged: set[bytes] = set()

    def flip(direction: str, pkt: bytes, now: float) -> list[bytes]:
        # Damage (once each) the D packets whose D -> E flip a 6-bit checksum accepts.
        if (
            direction == "ab"
            and pkt[3:4] == b"D"
            and pkt not in damaged
            and _passes_as_error(_d_to_e(pkt))
        ):
            damaged.add(pkt)
            return [_d_to_e(pkt)]
        return [pkt]

    # Normal-format packets: an extended packet's header check covers TYPE.
    short = EndpointConfig(one_way_delay=1.3, line_rate=2400, max_packet_length=90)
    a, b, link = connected_pair(short, short, filters=[flip])
    data = random.Random(7).randbytes(24_000)
    got = bytearray()
    sent = 0
    while len(got) < len(data):
        if sent < len(data):
            sent += a.send(data[sent : sent + 4096], link.now)
        link.step()
        got += b.read()
        assert b.state is State.ESTABLISHED, f"b left ESTABLISHED after {len(damaged)} damaged"
        assert link.now < 3600
    assert len(damaged) >= 3
    assert bytes(got) == data
