"""The bad-input matrix (issue 11), serial line: hostile bytes at a connected endpoint.

The matrix covers every entry point: the serial line (this file), the TCP
session (test_bad_input_tcp.py), command-line options and config files
(test_bad_input_cli.py).  For each input the expected
outcome is asserted exactly -- a counted drop, a typed error, a refusal or a
disconnect -- and then the entry point is shown to still work: the serial link
still delivers a transfer intact.  Memory under floods is measured with
tracemalloc.  Everything runs on SimLink's explicit virtual clock with seeded
randomness.
"""

from __future__ import annotations

import dataclasses
import random
import tracemalloc
from collections.abc import Callable

import pytest

from serialsocket import ConnectionAborted, Endpoint, EndpointConfig, State
from serialsocket.packets import (
    BlockCheck,
    InitParameters,
    Packet,
    PacketParser,
    PacketReceived,
    build_packet,
)

from .serialsocket.simlink import SimLink, split_packets

# --- serial line ------------------------------------------------------------------

DELAY = 0.5
TRANSFER = random.Random(11).randbytes(20_000)


def _config() -> EndpointConfig:
    return EndpointConfig(one_way_delay=DELAY, line_rate=9600.0, window=8, max_packet_length=256)


def _connected() -> SimLink:
    link = SimLink(Endpoint(_config()), Endpoint(_config()), delay=DELAY, rate=9600.0)
    link.b.listen()
    link.a.connect(0.0)
    link.run_until(lambda: link.a.state is State.ESTABLISHED and link.b.state is State.ESTABLISHED)
    link.a.events()
    link.b.events()
    return link


def _transfer_survives(link: SimLink) -> None:
    """After the abuse, A -> B still carries 20 kB intact, in order, exactly once."""
    got = bytearray()
    sent = 0

    def done() -> bool:
        nonlocal sent
        if sent < len(TRANSFER):
            sent += link.a.send(TRANSFER[sent:], link.now)
        got.extend(link.b.read(None, link.now))
        return bytes(got) == TRANSFER

    link.run_until(done, limit=link.now + 600.0)
    assert link.b.state is State.ESTABLISHED


def _data_packet(seq: int, data: bytes = b"hello") -> bytes:
    return build_packet(Packet(seq=seq, type="D", data=data))


def _feed_b(link: SimLink, wire: bytes) -> None:
    link.b.receive_data(wire, link.now)
    link.flush()


SerialCase = tuple[str, Callable[[SimLink], bytes], Callable[[dict[str, int]], bool], bytes]


def _delta(before: dict[str, int], after: dict[str, int]) -> dict[str, int]:
    return {k: after[k] - before[k] for k in before if isinstance(before[k], int)}


def _stats(ep: Endpoint) -> dict[str, int]:
    return {k: v for k, v in vars_of(ep.statistics()).items() if isinstance(v, int)}


def vars_of(record: object) -> dict[str, object]:
    return {name: getattr(record, name) for name in record.__dataclass_fields__}  # type: ignore[attr-defined]


def _garbage(_: SimLink) -> bytes:
    rng = random.Random(1)
    return bytes(b for b in rng.randbytes(70_000) if b not in b"\x00\x01\r\n")[:65_536]


def _truncated(link: SimLink) -> bytes:
    # Cut short by the next packet's MARK; that next packet is well formed (but out
    # of the window, so a forged copy cannot collide with the real transfer).
    whole = _data_packet((link.b.statistics().receive_expected + 40) % 64)
    return whole[: len(whole) // 2] + whole


def _oversized(_: SimLink) -> bytes:
    # An extended-format header announcing 2000 characters: more than max_packet_length.
    body = b" " + b"#D" + bytes([32 + 2000 // 95, 32 + 2000 % 95])
    hcheck = bytes([32 + ((sum(body) + ((sum(body) & 192) >> 6)) & 63)])
    return b"\x01" + body + hcheck + b"x" * 2100


def _bad_check(link: SimLink) -> bytes:
    wire = bytearray(_data_packet(link.b.statistics().receive_expected % 64))
    wire[-2] ^= 0x01  # the last CRC character
    return bytes(wire)


def _out_of_window(link: SimLink) -> bytes:
    seq = (link.b.statistics().receive_expected + 40) % 64
    return _data_packet(seq, b"never delivered")


def _unknown_type(_: SimLink) -> bytes:
    return build_packet(Packet(seq=3, type="Q", data=b"nonsense"))


def _ack_of_nothing(link: SimLink) -> bytes:
    seq = (link.b.statistics().send_next + 20) % 64
    return build_packet(Packet(seq=seq, type="Y"))


def _bad_prefixes(link: SimLink) -> bytes:
    # Valid CRC, nonsense encoding: a data field ending inside a prefix sequence.
    return _data_packet(link.b.statistics().receive_expected % 64, b"abc#")


SERIAL_CASES: list[SerialCase] = [
    # (name, input, expected counter deltas, what the application may read after)
    ("garbage", _garbage, lambda d: d["garbage_bytes"] == 65_536 and d["rejected"] == 1, b""),
    (
        "truncated",
        _truncated,
        lambda d: d["rejected"] == 1 and d["packets_received"] == 1 and d["out_of_window"] == 1,
        b"",
    ),
    ("oversized", _oversized, lambda d: d["rejected"] >= 1 and d["packets_received"] == 0, b""),
    (
        "bad check",
        _bad_check,
        lambda d: d["check_failures"] == 1 and d["packets_received"] == 0,
        b"",
    ),
    ("out of window", _out_of_window, lambda d: d["out_of_window"] == 1, b""),
    ("unknown type", _unknown_type, lambda d: d["ignored_packets"] == 1, b""),
    ("ACK of nothing sent", _ack_of_nothing, lambda d: d["bytes_acknowledged"] == 0, b""),
]


@pytest.mark.parametrize(
    ("name", "make", "expect", "readable"), SERIAL_CASES, ids=[c[0] for c in SERIAL_CASES]
)
def test_serial_line_counts_bad_input_and_keeps_working(
    name: str,
    make: Callable[[SimLink], bytes],
    expect: Callable[[dict[str, int]], bool],
    readable: bytes,
) -> None:
    link = _connected()
    before = _stats(link.b)
    _feed_b(link, make(link))
    delta = _delta(before, _stats(link.b))
    assert expect(delta), (name, {k: v for k, v in delta.items() if v})
    assert link.b.state is State.ESTABLISHED
    assert link.b.read(None, link.now) == readable  # nothing bogus reached the application
    _transfer_survives(link)


def test_serial_line_valid_check_but_malformed_data_aborts_with_a_typed_error() -> None:
    """A packet whose check verifies but whose prefix encoding is broken is a remote
    protocol error: the connection aborts with a reason (ConnectionAborted), and
    the endpoint does not raise."""
    link = _connected()
    _feed_b(link, _bad_prefixes(link))
    events = link.b.events()
    aborted = [e for e in events if isinstance(e, ConnectionAborted)]
    assert len(aborted) == 1
    assert "prefix" in aborted[0].reason
    assert link.b.state is State.FAILED
    assert link.b.read(None, link.now) == b""


def _init_packet(version: int) -> bytes:
    probe = Endpoint(_config())
    probe.connect(0.0)
    parser = PacketParser(init_check=BlockCheck.CRC16)
    parser.receive_data(probe.data_to_send(0.0))
    event = parser.next_event()
    assert isinstance(event, PacketReceived)
    params = InitParameters.decode(event.packet.data)
    forged = dataclasses.replace(params, version=version)
    return build_packet(Packet(seq=0, type="I", data=forged.encode()), event.check)


def test_serial_line_wrong_version_is_refused_with_an_error_packet() -> None:
    listener = Endpoint(_config())
    listener.listen()
    listener.receive_data(_init_packet(version=7), 0.0)
    out = split_packets(listener.data_to_send(0.0))
    assert listener.events() == []  # no ConnectionRequested, no Connected
    assert listener.state is State.LISTEN  # still listening for a good peer
    parser = PacketParser()
    parser.receive_data(b"".join(out))
    event = parser.next_event()
    assert isinstance(event, PacketReceived)
    assert event.packet.type == "E"
    assert b"version 7" in event.packet.data


def test_serial_line_nak_flood_is_counted_and_bounded() -> None:
    """10 000 NAKs at one instant: each outstanding packet is resent at most once
    (a NAK inside the repair horizon of the last copy is not honoured again)."""
    link = _connected()
    link.a.send(b"z" * 4000, link.now)
    link.run_for(0.6)
    in_flight = link.a.statistics().in_flight
    assert in_flight >= 1
    before = link.a.statistics()
    naks = b"".join(build_packet(Packet(seq=i % 64, type="N")) for i in range(10_000))
    link.a.receive_data(naks, link.now)
    out = link.a.data_to_send(link.now)
    after = link.a.statistics()
    assert after.naks_received - before.naks_received == 10_000
    resent = after.retransmissions - before.retransmissions
    assert resent <= in_flight
    assert len(out) <= in_flight * 300
    assert link.a.state is State.ESTABLISHED
    link.run_until(lambda: link.a.all_acknowledged, limit=link.now + 300)


def test_serial_line_init_storm_before_data_is_answered_one_for_one() -> None:
    """Repeated INITs on a fresh link (our answer lost, as far as the peer knows):
    each is answered, nothing else happens, and the link then works."""
    link = _connected()
    init = _init_packet(version=1)
    for _ in range(200):
        link.b.receive_data(init, link.now)
    out = split_packets(link.b.data_to_send(link.now))
    assert len(out) == 200
    assert link.b.state is State.ESTABLISHED
    assert link.b.events() == []


def test_serial_line_init_storm_on_a_live_link_aborts_once_and_stays_quiet() -> None:
    """An INIT after data flowed means the peer restarted: one typed abort
    (ConnectionAborted), then the FAILED endpoint answers the storm with at most
    one ERROR packet per timeout, not one per INIT."""
    link = _connected()
    link.a.send(b"data", link.now)
    link.run_until(lambda: link.b.readable == 4)
    init = _init_packet(version=1)
    wire_before = link.b.statistics().wire_bytes_sent
    for i in range(1000):
        link.b.receive_data(init, link.now + i * 0.001)
    link.b.data_to_send(link.now + 1.0)
    aborted = [e for e in link.b.events() if isinstance(e, ConnectionAborted)]
    assert len(aborted) == 1
    assert aborted[0].by_peer
    assert link.b.state is State.FAILED
    assert link.b.statistics().wire_bytes_sent - wire_before < 200


def test_serial_line_memory_stays_bounded_under_a_megabyte_flood() -> None:
    link = _connected()
    rng = random.Random(7)
    good = [_data_packet((link.b.statistics().receive_expected + 40) % 64, b"x" * 90)]
    chunks = [rng.randbytes(4096) for _ in range(8)] + good * 8
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        for i in range(256):  # ~1.2 MB of noise and out-of-window packets
            link.b.receive_data(chunks[i % len(chunks)], link.now)
            link.b.data_to_send(link.now)
            link.b.events()
        grown = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert grown < 256 * 1024, grown
    assert link.b.state in (State.ESTABLISHED, State.FAILED)
