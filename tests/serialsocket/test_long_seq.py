"""Long sequence numbers (PROTOCOL.md section 9): the offer, the wire format,
the wrap of the 18-bit space, a classic peer, and a window wider than 31 on a
long line."""

from __future__ import annotations

import random
from dataclasses import replace

import pytest

from serialsocket import Endpoint, EndpointConfig, RemoteProtocolError, State
from serialsocket._params import (
    LONG_SEQ_MODULUS,
    MAX_LONG_WINDOW,
    InitParameters,
    decode18,
    encode18,
    negotiate,
)
from serialsocket.packets import BlockCheck, PacketParser, PacketReceived, PacketType

from .simlink import SimLink

LONG = EndpointConfig(one_way_delay=30.0, line_rate=9600, max_packet_length=128)
"""Hints of a line that 31 packets cannot keep busy: a connector offers long
numbers (the tests' own line is short; the hints only decide the offer)."""


def _connect(
    cfg_a: EndpointConfig, cfg_b: EndpointConfig, *, delay: float = 0.01, rate: float | None = None
) -> tuple[Endpoint, Endpoint, SimLink]:
    a, b = Endpoint(cfg_a), Endpoint(cfg_b)
    link = SimLink(a, b, delay=delay, rate=rate)
    b.listen()
    a.connect(0.0)
    link.run_until(lambda: a.state is State.ESTABLISHED and b.state is State.ESTABLISHED)
    return a, b, link


def _transfer(a: Endpoint, b: Endpoint, link: SimLink, data: bytes) -> bytes:
    got = bytearray()
    pos = 0

    def done() -> bool:
        nonlocal pos
        if pos < len(data):
            pos += a.send(data[pos:], link.now)
        got.extend(b.read(None, link.now))
        return len(got) >= len(data)

    link.run_until(done)
    return bytes(got)


@pytest.mark.parametrize("n", [0, 1, 63, 64, 4095, 4096, LONG_SEQ_MODULUS - 1])
def test_eighteen_bit_numbers_spell_in_three_printable_characters(n: int) -> None:
    chars = encode18(n)
    assert len(chars) == 3
    assert all(32 <= c <= 95 for c in chars)
    assert decode18(chars) == n
    assert chars[2] - 32 == n % 64  # the last one is the packet's SEQ character


def test_a_long_line_negotiates_long_numbers_and_the_wide_window() -> None:
    assert LONG.needs_long_window()
    a, b, _ = _connect(LONG, LONG)
    for ep in (a, b):
        assert ep.parameters is not None
        assert ep.parameters.long_seq
        assert ep.parameters.window == MAX_LONG_WINDOW
        assert ep.statistics().long_sequence


def test_a_listener_without_hints_agrees_to_the_connector_s_offer() -> None:
    a, b, link = _connect(LONG, EndpointConfig())
    assert a.parameters is not None
    assert a.parameters.long_seq
    assert b.parameters is not None
    assert b.parameters.long_seq
    data = bytes(range(256)) * 40
    assert _transfer(a, b, link, data) == data
    assert _transfer(b, a, link, data) == data


@pytest.mark.parametrize(
    "cfg",
    [
        EndpointConfig(),  # no hints: the line may be a 20-minute one
        EndpointConfig(line_rate=2400),  # no delay hint: likewise
        EndpointConfig(one_way_delay=1.3),  # no rate hint: likewise
        # Hints that say 31 packets cover the line are offered anyway: a
        # delay hint 10x too low (2 s given, 20 s true) or a rate hint 10x
        # too low left the window at 31 packets for the whole transfer, 0.33
        # of the exact hints' goodput (linksim bench goodput --hints
        # wrong-delay-low --delay 20; 0.99 of it with the offer).
        EndpointConfig(one_way_delay=1.3, line_rate=2400),
        EndpointConfig(one_way_delay=1.3, line_rate=9600),
        EndpointConfig(one_way_delay=2.0, line_rate=2400),
    ],
    ids=["no-hints", "rate-only", "delay-only", "2400-moon", "9600-moon", "2400-2s"],
)
def test_the_offer_is_made_whatever_the_hints_say(cfg: EndpointConfig) -> None:
    assert cfg.needs_long_window()
    a, b, _ = _connect(cfg, cfg)
    assert a.parameters is not None
    assert a.parameters.long_seq
    assert b.parameters is not None
    assert b.parameters.long_seq


@pytest.mark.parametrize(
    "cfg",
    [
        EndpointConfig(one_way_delay=1.3, line_rate=2400, long_window=None),  # turned off
        EndpointConfig(one_way_delay=1.3, line_rate=2400, window=8),  # a narrower window
    ],
    ids=["turned-off", "narrow-window"],
)
def test_no_offer_when_the_user_keeps_the_classic_window(cfg: EndpointConfig) -> None:
    assert not cfg.needs_long_window()
    a, _b, _ = _connect(cfg, cfg)
    assert a.parameters is not None
    assert not a.parameters.long_seq


@pytest.mark.parametrize(
    ("other", "window"),
    [
        (replace(LONG, long_window=None), 31),  # may not use them: classic, 31
        (replace(LONG, window=8), 8),  # a narrowed window is the window wanted
    ],
    ids=["no-offer", "window-8"],
)
def test_one_side_without_the_offer_keeps_classic_kermit_numbers(
    other: EndpointConfig, window: int
) -> None:
    data = bytes(range(256)) * 40
    for first, second in ((LONG, other), (other, LONG)):
        a, b, link = _connect(first, second)
        assert a.parameters is not None
        assert not a.parameters.long_seq
        assert a.parameters.window == window
        assert _transfer(a, b, link, data) == data


def test_the_smaller_long_window_wins() -> None:
    a, _b, _ = _connect(replace(LONG, long_window=500), replace(LONG, long_window=4000))
    assert a.parameters is not None
    assert a.parameters.window == 500


def test_an_init_without_the_offer_is_the_classic_26_characters() -> None:
    classic = InitParameters.mine(
        max_packet_length=128,
        window=31,
        check=BlockCheck.CRC16,
        encoding=EndpointConfig().encoding,
        timeout_hint=1.0,
    )
    offered = InitParameters.mine(
        max_packet_length=128,
        window=31,
        check=BlockCheck.CRC16,
        encoding=EndpointConfig().encoding,
        timeout_hint=1.0,
        long_window=1000,
    )
    assert len(classic.encode()) == 26
    assert offered.encode() == classic.encode() + b"!" + encode18(1000)
    assert InitParameters.decode(offered.encode()).long_window == 1000
    assert InitParameters.decode(classic.encode()).long_window is None
    assert negotiate(offered, InitParameters.decode(classic.encode())).long_seq is False


@pytest.mark.parametrize(
    "tail", [b"!" + encode18(0), b"!" + encode18(MAX_LONG_WINDOW + 1), b"!~~~", b"\x7f"]
)
def test_a_bad_long_window_offer_is_refused_with_its_field_named(tail: bytes) -> None:
    base = InitParameters.mine(
        max_packet_length=128,
        window=31,
        check=BlockCheck.CRC16,
        encoding=EndpointConfig().encoding,
        timeout_hint=1.0,
    ).encode()
    with pytest.raises(RemoteProtocolError, match=r"XCAPAS|XWINDO"):
        InitParameters.decode(base + tail)


def test_data_packets_carry_the_high_bits_before_the_data() -> None:
    a, b, link = _connect(LONG, LONG)
    # Start the sequence space just below 4096 so the high characters are not zero.
    a._sender.base = a._sender.next = a._sender.peer_cum = 4094
    b._receiver.expected = 4094
    a.send(b"hello", link.now)
    parser = PacketParser(max_length=9031, check=BlockCheck.CRC16, init_check=BlockCheck.CRC16)
    parser.receive_data(a.data_to_send(link.now))
    event = parser.next_event()
    assert isinstance(event, PacketReceived)
    assert event.packet.type == PacketType.DATA
    packet = event.packet
    assert decode18(packet.data[:2] + bytes((packet.seq + 32,))) == 4094
    assert a.parameters is not None
    assert a.parameters.encoding.decode(packet.data[2:]) == b"hello"  # the agreed encoding


def test_transfers_across_the_wrap_of_the_18_bit_space_both_ways() -> None:
    cfg = replace(LONG, max_packet_length=64)
    a, b, link = _connect(cfg, cfg)
    assert a.statistics().long_sequence
    start = LONG_SEQ_MODULUS - 40
    for ep in (a, b):
        ep._sender.base = ep._sender.next = ep._sender.peer_cum = start
        ep._receiver.expected = start
    data = bytes((i * 7) % 256 for i in range(20_000))  # ~400 packets: through the wrap
    assert _transfer(a, b, link, data) == data
    assert _transfer(b, a, link, data[::-1]) == data[::-1]
    assert a.statistics().send_next > LONG_SEQ_MODULUS


def test_a_long_line_keeps_more_than_31_packets_in_flight() -> None:
    """At 9600 bit/s and 60 s one way the bandwidth-delay bound is about 2700
    packets of 128: classic Kermit numbers would idle the line 98 % of the time."""
    cfg = EndpointConfig(one_way_delay=60.0, line_rate=9600, max_packet_length=128)
    a, b, link = _connect(cfg, cfg, delay=60.0, rate=9600)
    assert a.statistics().effective_window > 1000
    data = random.Random(1).randbytes(400_000)
    pos = 0
    most = 0

    def seen() -> bool:
        nonlocal most, pos
        pos += a.send(data[pos:], link.now)
        most = max(most, a.statistics().in_flight)
        b.read(None, link.now)
        return link.now > 200.0

    link.run_until(seen)
    assert most > 500
    assert b.statistics().receive_buffer > 64 * 1024  # grown with the bandwidth-delay product
