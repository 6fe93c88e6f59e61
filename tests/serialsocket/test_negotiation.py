"""The dense encodings and CRC-32 in the init exchange (PROTOCOL.md section 10).

A matrix of both ends' capabilities and line profiles, the classic cases
(a peer without XCAPAS gets exactly the classic answer), unknown XCAPAS bits,
and whole connections carrying random binary on virtual time in every
profile, CRC-32 included, over clean and damaging lines.
"""

from __future__ import annotations

import itertools
import random
from dataclasses import replace

import pytest

from serialsocket import ConnectionAborted, Endpoint, EndpointConfig, State
from serialsocket._params import (
    FEATURE_CRC32,
    FEATURE_ESCAPE,
    FEATURE_EXPEDITED,
    FEATURE_RADIX91,
    FEATURE_XON_XOFF,
    crc32_wanted,
    negotiate,
)
from serialsocket.kermit import KermitConfig
from serialsocket.kermit._params import KermitInit
from serialsocket.packets import (
    EIGHT_BIT_CLEAN,
    PRINTABLE,
    XON_XOFF,
    BlockCheck,
    Encoding,
    EscapeEncoding,
    InitParameters,
    Packet,
    PacketType,
    Radix91Encoding,
    build_packet,
    crc32_chars,
)

from .simlink import SimLink


def _handshake(cfg_a: EndpointConfig, cfg_b: EndpointConfig) -> tuple[Endpoint, Endpoint]:
    """A connects to B; both must be established after one request and one answer."""
    a, b = Endpoint(cfg_a), Endpoint(cfg_b)
    b.listen()
    a.connect(0.0)
    b.receive_data(a.data_to_send(0.0), 0.5)
    a.receive_data(b.data_to_send(0.5), 1.0)
    assert (a.state, b.state) == (State.ESTABLISHED, State.ESTABLISHED)
    return a, b


def _init_field(ep: Endpoint, now: float) -> bytes:
    wire = ep.data_to_send(now)
    assert wire[0] == 1
    assert wire.endswith(b"\r")
    return wire[4:-4]  # normal packet: MARK LEN SEQ TYPE ... 3 CRC characters, CR


# -- the matrix ---------------------------------------------------------------------------

PROFILES = {"printable": PRINTABLE, "8bit": EIGHT_BIT_CLEAN}
SIDE = list(itertools.product(PROFILES, (True, False), (BlockCheck.CRC16, BlockCheck.CRC32)))


def _expected(
    a: tuple[str, bool, BlockCheck], b: tuple[str, bool, BlockCheck]
) -> tuple[type, BlockCheck]:
    """What section 10.2 says, written out independently of negotiate()."""
    printable = "printable" in (a[0], b[0])
    dense = a[1] and b[1]
    if dense:
        codec: type = Radix91Encoding if printable else EscapeEncoding
    else:
        codec = Encoding
    wants_crc32 = BlockCheck.CRC32 in (a[2], b[2])
    return codec, BlockCheck.CRC32 if dense and wants_crc32 else BlockCheck.CRC16


@pytest.mark.parametrize(("side_a", "side_b"), list(itertools.product(SIDE, SIDE)), ids=repr)
def test_every_combination_agrees_on_what_section_10_says(
    side_a: tuple[str, bool, BlockCheck], side_b: tuple[str, bool, BlockCheck]
) -> None:
    def cfg(side: tuple[str, bool, BlockCheck]) -> EndpointConfig:
        return EndpointConfig(encoding=PROFILES[side[0]], dense=side[1], check=side[2])

    a, b = _handshake(cfg(side_a), cfg(side_b))
    assert a.parameters is not None
    assert b.parameters is not None
    codec, check = _expected(side_a, side_b)
    for p in (a.parameters, b.parameters):
        assert type(p.encoding) is codec
        assert p.check is check
        if codec is Encoding:
            assert isinstance(p.encoding, Encoding)
            want_qbin = ord("&") if "printable" in (side_a[0], side_b[0]) else None
            assert p.encoding.qbin == want_qbin
    assert a.parameters.encoding == b.parameters.encoding


def test_simultaneous_open_agrees_on_the_same_codec_and_check() -> None:
    cfg_a = EndpointConfig(
        dense=True, long_window=None, encoding=EIGHT_BIT_CLEAN, check=BlockCheck.CRC32
    )
    cfg_b = EndpointConfig(dense=True, long_window=None, encoding=EIGHT_BIT_CLEAN, xon_xoff=True)
    a, b = Endpoint(cfg_a), Endpoint(cfg_b)
    a.connect(0.0)
    b.connect(0.0)
    ia, ib = a.data_to_send(0.0), b.data_to_send(0.0)
    a.receive_data(ib, 0.5)
    b.receive_data(ia, 0.5)
    a.receive_data(b.data_to_send(0.5), 1.0)
    b.receive_data(a.data_to_send(0.5), 1.0)
    assert a.parameters is not None
    assert b.parameters is not None
    for p in (a.parameters, b.parameters):
        assert p.encoding == EscapeEncoding(unsafe=XON_XOFF)
        assert p.check is BlockCheck.CRC32


# -- the bytes of the offer and the answer --------------------------------------------------


def test_a_connector_offers_escape_and_radix91_in_one_xcapas_character() -> None:
    a = Endpoint(EndpointConfig(dense=True, long_window=None))
    a.connect(0.0)
    field = _init_field(a, 0.0)
    assert field == b'~  @-#&5~&?*c0___@"TL@!  R6!'  # PROTOCOL.md 10.1's example
    assert InitParameters.decode(field).features == (
        FEATURE_ESCAPE | FEATURE_RADIX91 | FEATURE_EXPEDITED
    )
    b = Endpoint(
        EndpointConfig(
            dense=True,
            long_window=None,
            encoding=EIGHT_BIT_CLEAN,
            check=BlockCheck.CRC32,
            xon_xoff=True,
        )
    )
    b.connect(0.0)
    field = _init_field(b, 0.0)
    assert field[6:7] == b"Y"  # QBIN: an 8-bit line
    assert field[26:] == bytes((32 + (2 | 4 | 8 | 16 | 32), 32 + 1))  # "^" and XLANES "!"


def test_a_request_without_xcapas_gets_exactly_the_classic_answer() -> None:
    classic = EndpointConfig(dense=False, long_window=None, expedited=False)
    for listener in (EndpointConfig(dense=True, long_window=None), classic):
        a, b = Endpoint(classic), Endpoint(listener)
        b.listen()
        a.connect(0.0)
        request = a.data_to_send(0.0)
        assert len(_field_of(request)) == 26
        b.receive_data(request, 0.5)
        answers = [b.data_to_send(0.5)]
        answers.append(answers[0])
        assert len(_field_of(answers[0])) == 26
        assert b.parameters is not None
        assert b.parameters.encoding == PRINTABLE
        assert b.parameters.check is BlockCheck.CRC16
    # The dense listener's answer is byte for byte the classic listener's.
    first = _answer(classic, EndpointConfig(dense=True, long_window=None))
    second = _answer(classic, EndpointConfig(dense=False, long_window=None))
    assert first == second


def _field_of(wire: bytes) -> bytes:
    return wire[4:-4]


def _answer(cfg_a: EndpointConfig, cfg_b: EndpointConfig) -> bytes:
    a, b = Endpoint(cfg_a), Endpoint(cfg_b)
    b.listen()
    a.connect(0.0)
    b.receive_data(a.data_to_send(0.0), 0.5)
    return b.data_to_send(0.5)


def test_a_classic_request_with_long_numbers_gets_only_the_long_number_fields() -> None:
    long_line = EndpointConfig(
        dense=True, one_way_delay=30.0, line_rate=9600, max_packet_length=128
    )
    a = Endpoint(replace(long_line, dense=False, expedited=False))
    b = Endpoint(EndpointConfig(dense=True))
    b.listen()
    a.connect(0.0)
    b.receive_data(a.data_to_send(0.0), 0.5)
    field = _field_of(b.data_to_send(0.5))
    assert field[26:27] == b"!"  # XCAPAS 1 only: no dense bits to a peer that offered none
    assert b.parameters is not None
    assert b.parameters.long_seq
    assert b.parameters.encoding == PRINTABLE


def test_unknown_and_reserved_bits_are_ignored_and_never_echoed() -> None:
    mine = InitParameters.mine(
        max_packet_length=128,
        window=31,
        check=BlockCheck.CRC16,
        encoding=EIGHT_BIT_CLEAN,
        timeout_hint=1.0,
        features=FEATURE_ESCAPE | FEATURE_RADIX91,
    )
    field = mine.encode()
    # A peer with the expedited lane (16, not offered here) and an unknown
    # bit 64 besides escape.
    future = InitParameters.decode(field[:-1] + bytes((32 + (FEATURE_ESCAPE | 16 | 64),)))
    assert future.features == FEATURE_ESCAPE | FEATURE_EXPEDITED | 64
    answer = mine.answer(future, None)
    assert answer.features == FEATURE_ESCAPE
    assert answer.encode()[-1] == 32 + FEATURE_ESCAPE
    agreed = negotiate(answer, future)
    assert agreed.encoding == EscapeEncoding()
    assert agreed.check is BlockCheck.CRC16
    # Only bits this side does not offer: nothing dense, the classic 8-bit profile.
    only_future = InitParameters.decode(field[:-1] + bytes((32 + 16,)))
    agreed = negotiate(mine.answer(only_future, None), only_future)
    assert agreed.encoding == EIGHT_BIT_CLEAN


@pytest.mark.parametrize("tail", [b"\x7f", b"\x1f"])
def test_an_xcapas_outside_tochar_is_refused_with_its_field_named(tail: bytes) -> None:
    field = InitParameters.mine(
        max_packet_length=128,
        window=31,
        check=BlockCheck.CRC16,
        encoding=PRINTABLE,
        timeout_hint=1.0,
    ).encode()
    from serialsocket import RemoteProtocolError

    with pytest.raises(RemoteProtocolError, match="XCAPAS"):
        InitParameters.decode(field + tail)


def test_our_kermit_file_transfer_never_sends_xcapas() -> None:
    for config in (KermitConfig(), KermitConfig(max_packet_length=4000)):
        field = KermitInit.mine(config).encode()
        decoded = InitParameters.decode(field)
        assert decoded.features is None
        assert decoded.version is None


def test_crc32_rule_follows_the_residual_error_target() -> None:
    # N q^2 > 2^17 x 1e-12 at the design rate 1e-5: N > 1310; always past 4093.
    assert not crc32_wanted(512)
    assert not crc32_wanted(1024)
    assert crc32_wanted(2048)
    assert crc32_wanted(4094, byte_error_rate=1e-9)
    assert crc32_wanted(128, byte_error_rate=1e-4)
    assert not crc32_wanted(4093, byte_error_rate=1e-6)
    for length, wanted in ((1024, False), (2048, True)):
        ep = Endpoint(EndpointConfig(dense=True, long_window=None, max_packet_length=length))
        ep.connect(0.0)
        features = InitParameters.decode(_field_of_any(ep.data_to_send(0.0))).features
        assert features is not None
        assert bool(features & FEATURE_CRC32) is wanted


def _field_of_any(wire: bytes) -> bytes:
    """The data field of a normal or extended init packet."""
    return wire[7:-4] if wire[1] == 32 else wire[4:-4]


def test_xon_xoff_is_escaped_when_either_side_declares_it() -> None:
    a, b = _handshake(
        EndpointConfig(dense=True, long_window=None, encoding=EIGHT_BIT_CLEAN),
        EndpointConfig(dense=True, long_window=None, encoding=EIGHT_BIT_CLEAN, xon_xoff=True),
    )
    assert a.parameters is not None
    assert b.parameters is not None
    features = b.parameters.peer.features
    assert features is not None
    assert not features & FEATURE_XON_XOFF
    assert a.parameters.encoding == b.parameters.encoding == EscapeEncoding(unsafe=XON_XOFF)
    a.send(bytes(range(256)), 1.0)
    wire = a.data_to_send(1.0)
    for c in XON_XOFF:
        assert c not in wire


# -- CRC-32 on the wire ----------------------------------------------------------------------


def test_a_crc32_packet_carries_six_check_characters_and_parses() -> None:
    a, b = _handshake(
        EndpointConfig(
            dense=True, long_window=None, encoding=EIGHT_BIT_CLEAN, check=BlockCheck.CRC32
        ),
        EndpointConfig(dense=True, long_window=None, encoding=EIGHT_BIT_CLEAN),
    )
    a.send(b"\x01\x18hello\x11\xff", 1.0)
    wire = a.data_to_send(1.0)
    assert wire[4:-7] == b"\x18A\x18Xhello\x11\xff"  # PROTOCOL.md 10.3's example
    assert wire[-7:-1] == crc32_chars(wire[1:-7])
    assert wire == build_packet(
        Packet(seq=1, type=PacketType.DATA, data=wire[4:-7]), BlockCheck.CRC32
    )
    b.receive_data(wire, 1.5)
    assert b.read(None, 1.5) == b"\x01\x18hello\x11\xff"


# -- whole connections on virtual time --------------------------------------------------------

CASES = {
    "radix91": EndpointConfig(dense=True, long_window=None),
    "radix91+crc32": EndpointConfig(dense=True, long_window=None, check=BlockCheck.CRC32),
    "escape": EndpointConfig(dense=True, long_window=None, encoding=EIGHT_BIT_CLEAN),
    "escape+crc32+xonxoff": EndpointConfig(
        dense=True, encoding=EIGHT_BIT_CLEAN, check=BlockCheck.CRC32, xon_xoff=True
    ),
    "escape+long": EndpointConfig(
        dense=True, encoding=EIGHT_BIT_CLEAN, max_packet_length=2048, one_way_delay=0.05
    ),
}
CODEC = {
    "radix91": Radix91Encoding,
    "radix91+crc32": Radix91Encoding,
    "escape": EscapeEncoding,
    "escape+crc32+xonxoff": EscapeEncoding,
    "escape+long": EscapeEncoding,
}


def _damage(seed: int, rate: float):  # type: ignore[no-untyped-def]
    rng = random.Random(seed)

    def f(direction: str, pkt: bytes, now: float) -> list[bytes]:
        out = bytearray(pkt)
        for i in range(len(out)):
            if rng.random() < rate:
                out[i] = rng.randrange(256)
        if rng.random() < rate * 20:
            out = out[: rng.randrange(1, len(out) + 1)]  # cut short
        return [bytes(out)]

    return f


@pytest.mark.parametrize("damaged", [False, True], ids=["clean", "damaged"])
@pytest.mark.parametrize("name", list(CASES))
def test_random_binary_round_trips_both_ways(name: str, damaged: bool) -> None:
    cfg = CASES[name]
    a, b = Endpoint(cfg), Endpoint(cfg)
    # About one packet in five damaged (bytes changed, or cut short) whatever the length.
    damage = 0.2 / cfg.derived_max_packet_length() if damaged else 0.0
    filters = [_damage(7, damage)] if damage else []
    link = SimLink(a, b, delay=0.05, rate=115200, filters=filters)
    b.listen()
    a.connect(0.0)
    link.run_until(lambda: a.state is State.ESTABLISHED and b.state is State.ESTABLISHED)
    assert a.parameters is not None
    assert type(a.parameters.encoding) is CODEC[name]
    assert (a.parameters.check is BlockCheck.CRC32) == (
        "crc32" in name or cfg.max_packet_length == 2048
    )
    rng = random.Random(name)
    ab, ba = rng.randbytes(40_000), rng.randbytes(25_000)
    got_ab, got_ba = bytearray(), bytearray()
    sent = {"ab": 0, "ba": 0}

    def done() -> bool:
        if sent["ab"] < len(ab):
            sent["ab"] += a.send(ab[sent["ab"] :], link.now)
        if sent["ba"] < len(ba):
            sent["ba"] += b.send(ba[sent["ba"] :], link.now)
        got_ab.extend(b.read(None, link.now))
        got_ba.extend(a.read(None, link.now))
        return len(got_ab) >= len(ab) and len(got_ba) >= len(ba)

    link.run_until(done, limit=3000.0)
    assert bytes(got_ab) == ab
    assert bytes(got_ba) == ba
    if damage:
        rejected = a.statistics().rejected + b.statistics().rejected
        assert rejected > 0


# -- malformed dense fields ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("profile", "field"),
    [
        (PRINTABLE, b"!"),  # a radix-91 length no byte string has
        (PRINTABLE, b"~~"),  # outside the alphabet
        (EIGHT_BIT_CLEAN, b"ab\x18"),  # an escape at the end
        (EIGHT_BIT_CLEAN, b"\x18\x00"),  # an escape of nothing reserved
    ],
)
def test_a_malformed_dense_field_with_a_good_check_aborts_the_link_in_order(
    profile: Encoding, field: bytes
) -> None:
    _a, b = _handshake(
        EndpointConfig(dense=True, long_window=None, encoding=profile),
        EndpointConfig(dense=True, long_window=None, encoding=profile),
    )
    b.events()
    forged = build_packet(Packet(seq=1, type=PacketType.DATA, data=field))
    b.receive_data(forged, 2.0)  # a peer bug, not line noise: no exception escapes
    assert b.state is not State.ESTABLISHED
    events = b.events()
    assert any(isinstance(e, ConnectionAborted) for e in events)
    assert b"Malformed dense data field" in b.data_to_send(2.0)
