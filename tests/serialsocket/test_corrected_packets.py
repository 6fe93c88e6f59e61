"""Corrected data packets (serialsocket/PROTOCOL.md section 15): the sums, the
repair, the agreement, the sender's choice, and whole transfers over a noisy
virtual line."""

from __future__ import annotations

import random

import pytest

from linksim.bench._transfer import simulate
from serialsocket import Endpoint, EndpointConfig
from serialsocket._fec import (
    apply_repair,
    blocks,
    build_corrected,
    repair,
    repair_field,
    survival,
    trailer_length,
)
from serialsocket._length import LengthChooser
from serialsocket._params import negotiate
from serialsocket._wire import PacketType
from serialsocket.packets import (
    EIGHT_BIT_CLEAN,
    PRINTABLE,
    BlockCheck,
    InitParameters,
    Packet,
    PacketParser,
    PacketReceived,
    PacketRejected,
    build_packet,
    data_capacity,
)

from .simlink import Filter

CRCS = (BlockCheck.CRC16, BlockCheck.CRC32)


def _field(rng: random.Random, n: int) -> bytes:
    return bytes(rng.choice(range(2, 256)) for _ in range(n))


def _read(wire: bytes, check: BlockCheck, *, correction: bool = True) -> object:
    parser = PacketParser(max_length=9031, check=check, correction=correction)
    parser.receive_data(wire)
    return parser.next_event()


def test_the_example_of_the_protocol() -> None:
    wire = build_corrected(5, b"hello", BlockCheck.CRC16)
    assert wire == b"\x01-%dhello!JO/(7\r"
    damaged = wire.replace(b"hello", b"heLlo")
    event = _read(damaged, BlockCheck.CRC16)
    assert isinstance(event, PacketReceived)
    assert event.packet == Packet(seq=5, type="D", data=b"hello")


def test_blocks_hold_the_covered_characters() -> None:
    assert [blocks(n, 3) for n in (96, 128, 261, 262, 263, 384, 512, 1024)] == [
        1,
        1,
        1,
        1,
        2,
        2,
        2,
        4,
    ]
    for check in CRCS:
        k = int(check)
        for total in range(12, 9032):
            m = blocks(total, k)
            covered = total - 1 - k - 3 * m
            assert covered <= 255 * m
            assert m == 1 or covered > 255 * (m - 1) - 3
            assert trailer_length(total, k) == 3 * m


@pytest.mark.parametrize("check", CRCS)
@pytest.mark.parametrize("size", [0, 1, 7, 80, 90, 250, 256, 500, 1000, 3000])
def test_one_damaged_character_is_repaired_wherever_the_sums_reach(
    check: BlockCheck, size: int
) -> None:
    rng = random.Random(size * 7 + int(check))
    field = _field(rng, size)
    wire = build_corrected(33, field, check)
    packet = Packet(seq=33, type="D", data=field)
    body = wire[:-1]
    k = int(check)
    header = 7 if body[1] == 32 else 4
    for at in range(1, len(body)):
        value = rng.choice([v for v in range(256) if v not in (1, body[at])])
        damaged = body[:at] + bytes((value,)) + body[at + 1 :]
        event = _read(damaged + b"\r", check)
        if (at == 2 and header == 4) or header <= at < len(body) - k:
            # SEQ (of a normal packet: an extended one's HCHECK rejects a
            # damaged SEQ first), the data and the sums.
            assert isinstance(event, PacketReceived), (at, event)
            assert event.packet == packet
        else:
            # LEN, TYPE, the extended header, the check: never repaired and
            # never read as another packet.
            assert not (isinstance(event, PacketReceived) and event.packet != packet), at


@pytest.mark.parametrize("check", CRCS)
def test_a_burst_of_one_character_per_block_is_repaired(check: BlockCheck) -> None:
    field = _field(random.Random(5), 1000)
    wire = build_corrected(9, field, check)
    m = blocks(len(wire) - 1, int(check))
    assert m == 4
    burst = bytearray(wire)
    for at in range(400, 400 + m):  # m consecutive characters: one in each block
        burst[at] ^= 0x5A
    event = _read(bytes(burst), check)
    assert isinstance(event, PacketReceived)
    assert event.packet.data == field
    burst[400 + m] ^= 0x5A  # one more: a block with two
    assert isinstance(_read(bytes(burst), check), PacketRejected)


def test_two_damaged_characters_in_a_block_are_rejected_never_misread() -> None:
    rng = random.Random(11)
    field = _field(rng, 200)
    wire = build_corrected(3, field, BlockCheck.CRC16)
    rejected = 0
    for _ in range(300):
        damaged = bytearray(wire)
        for at in rng.sample(range(7, len(wire) - 4), 2):
            damaged[at] = rng.choice([v for v in range(2, 256) if v != damaged[at]])
        event = _read(bytes(damaged), BlockCheck.CRC16)
        assert not isinstance(event, PacketReceived) or event.packet.data == field
        rejected += isinstance(event, PacketRejected)
    assert rejected == 300


def test_repair_is_tried_only_under_a_crc() -> None:
    # A 12-bit sum would pass a wrong repair once in 4096 tries.
    field = b"under a weak check"
    marked = build_packet(Packet(seq=1, type="d", data=field + b"!!!"), BlockCheck.SUM12)
    damaged = marked.replace(b"weak", b"Weak")
    assert isinstance(_read(damaged, BlockCheck.SUM12), PacketRejected)
    assert repair(build_corrected(1, field, BlockCheck.CRC16)[:-1], BlockCheck.CRC16) is None


def test_without_the_agreement_a_d_is_an_unknown_type() -> None:
    wire = build_corrected(4, b"payload", BlockCheck.CRC16)
    event = _read(wire, BlockCheck.CRC16, correction=False)
    assert isinstance(event, PacketReceived)
    assert event.packet.type == "d"
    assert event.packet.data.startswith(b"payload")


def test_the_parser_counts_its_repairs() -> None:
    parser = PacketParser(max_length=1024, check=BlockCheck.CRC16, correction=True)
    wire = build_corrected(4, b"x" * 300, BlockCheck.CRC16)
    parser.receive_data(wire + wire.replace(b"xxxx", b"xxXx", 1))
    events = [parser.next_event(), parser.next_event()]
    assert all(isinstance(e, PacketReceived) and e.packet.data == b"x" * 300 for e in events)
    assert parser.statistics().repaired == 1


def _offer(**kw: object) -> EndpointConfig:
    return EndpointConfig(dense=True, **kw)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("mine", "theirs", "agreed"),
    [
        (_offer(correction=True), _offer(correction=True), True),
        (_offer(correction=True), _offer(), False),
        (_offer(correction=True, expedited=False), _offer(correction=True), False),
        (
            _offer(correction=True, check=BlockCheck.CRC32),
            _offer(correction=True),
            True,
        ),
        (
            _offer(correction=True, check=BlockCheck.SUM12),
            _offer(correction=True, check=BlockCheck.SUM12),
            False,
        ),
    ],
)
def test_agreement_needs_both_offers_and_a_crc(
    mine: EndpointConfig, theirs: EndpointConfig, agreed: bool
) -> None:
    # Both inits as they travel: XLANES bit 8 decodes from the wire.
    ours = InitParameters.decode(Endpoint(mine)._mine.encode())
    peer = InitParameters.decode(Endpoint(theirs)._mine.encode())
    answer = InitParameters.decode(peer.answer(ours, peer.long_window).encode())
    assert negotiate(ours, answer).correction is agreed
    assert negotiate(answer, ours).correction is agreed


def _carried(n: int) -> int:
    return data_capacity(n, BlockCheck.CRC16)


def _corrected(n: int) -> int:
    return _carried(n) - trailer_length(n, 3)


def test_sums_never_pay_on_a_line_that_has_lost_nothing() -> None:
    c = LengthChooser(128)
    for _ in range(200):
        c.sent(1025, corrected=c.correcting)
        c.choose(96, 1024, _carried, clean=True, corrected=_corrected)
        assert not c.correcting
    assert c.length == 1024


def test_losses_turn_the_sums_on_and_keep_the_estimate() -> None:
    c = LengthChooser(128)
    for _ in range(20):
        c.sent(385)
    c.length = 512  # (where a clean start took it)
    c.lost()
    c.lost()
    assert c.choose(96, 1024, _carried, clean=False, corrected=_corrected) == 512
    assert c.correcting  # 2 losses in 7.7 KB, about 2e-4: sums pay at 512
    c.length = 128
    c.choose(96, 1024, _carried, clean=False, corrected=_corrected)
    assert not c.correcting  # ... and not at 128
    q = c.byte_error_rate
    assert q is not None
    for _ in range(20):  # sums hide the damage: the estimate barely moves
        c.sent(c.length + 1, corrected=True)
    again = c.byte_error_rate
    assert again is not None
    assert again > 0.8 * q
    without = LengthChooser(128)
    assert without.choose(96, 1024, _carried, clean=False) == 128
    assert not without.correcting  # never without the agreement


def test_survival_counts_one_repairable_hit_per_block() -> None:
    assert survival(1024, 0.0, 3) == 1.0
    q = 1e-3
    assert survival(96, q, 3) > (1 - q) ** 97 + 0.08  # most single hits repaired
    assert survival(1024, 1e-4, 3) > 0.997 > (1 - 1e-4) ** 1025


def test_a_noisy_line_delivers_exactly_with_fewer_resends() -> None:
    payload = random.Random(3).randbytes(8192)
    runs = {
        correction: simulate(
            payload,
            rate=2400,
            delay=1.3,
            byte_error_rate=1e-3,
            burst=None,
            window=31,
            max_len=None,
            encoding=EIGHT_BIT_CLEAN,
            seed=3,
            time_cap=600,
            hints="none",
            dense=True,
            first_flight=True,
            correction=correction,
            max_packet_time=None,  # as the netcat: the length follows the losses alone
        )
        for correction in (False, True)
    }
    for run in runs.values():
        assert run.ok
        assert run.complete
    # (Seed 3: 9 resends and 42.3 s without sums, 6 and 39.5 s with them.)
    assert runs[True].retransmissions < runs[False].retransmissions
    assert runs[True].seconds < runs[False].seconds - 2.0


def test_a_packet_lost_before_the_sums_went_on_is_resent_with_them() -> None:
    """Packets 2-5 are lost whole, once each.  The first resend of each is a
    repair packet (PROTOCOL.md 15.6), which finds nothing to mend at the
    receiver (it never saw them): each is NAKed at once, and by then the
    losses have turned the sums on, so the whole resends go as ``d`` packets
    with the same data (a 513-character ``D`` resent as it was survives 1e-3
    six times in ten: one was lost five times running, each a timeout)."""
    from dataclasses import replace

    from .simlink import MOON_HINTS, QueuedRun, drop_nth

    # (The length measured and uncapped, as the netcat's: the peer's limit,
    # 1024, leaves room for the sums.)
    cfg = replace(MOON_HINTS, correction=True, max_packet_time=None)
    payload = random.Random(9).randbytes(12_000)
    run = QueuedRun(payload, cfg, cfg, [drop_nth(b"D", {2, 3, 4, 5}, "ab")])
    got, _ = run.read_all()
    assert got == payload
    sent = [p for _, p in run.link.sent["ab"]][:64]  # (before SEQ wraps)
    first = {p[2]: p for p in sent if p[3:4] == b"D"}
    repairs = [p for p in sent if p[3:4] == b"r"]
    assert [p[2] - 32 for p in repairs] == [2, 3, 4, 5]
    for wire in repairs:
        plain = first[wire[2]]
        head = 7 if plain[1] == 32 else 4
        assert wire[4:-4].endswith(repair_field(plain[:-1], 3))
        assert len(wire) < 20 < len(plain)
    again = [p for p in sent if p[3:4] == b"d" and p[2] in first and p[2] - 32 <= 5]
    assert sorted(p[2] - 32 for p in again) == [2, 3, 4, 5]
    for wire in again:
        plain = first[wire[2]]
        head = 7 if plain[1] == 32 else 4
        # The same data, then the sums, a new check: a longer packet.
        assert wire[head : len(plain) - 4] == plain[head:-4]
        assert len(wire) > len(plain)
    assert run.a.statistics().retransmissions == 4  # (whole copies only)
    assert run.a.statistics().repairs_sent == 4
    assert run.b.statistics().repairs_failed == 4
    assert run.b.statistics().repaired == 0


def test_a_short_packet_resent_with_the_sums_agreed() -> None:
    """A lost packet shorter than any packet length the chooser weighs (one
    byte: 10 characters) is resent: the resend's form is judged on its own
    length.  (Found by the stateful machine: the resend asked the capacity of
    a 9-character maximum length, and data_to_send raised.)"""
    from dataclasses import replace

    from .simlink import MOON_HINTS, connected_pair, drop_nth

    cfg = replace(MOON_HINTS, correction=True)
    a, b, link = connected_pair(cfg, cfg, filters=[drop_nth(b"D", {1}, "ab")])
    assert a.statistics().correction
    a.send(b"x", link.now)
    got = bytearray()

    def arrived() -> bool:
        got.extend(b.read())
        return bytes(got) == b"x"

    link.run_until(arrived)
    assert a.statistics().retransmissions == 1


def _plain(seq: int, data: bytes) -> bytes:
    """A ``D`` packet under CRC-16, MARK through CHECK (no CR)."""
    return build_packet(Packet(seq=seq, type=PacketType.DATA, data=data), BlockCheck.CRC16)[:-1]


def test_a_repair_packet_mends_one_damaged_character_per_block() -> None:
    rng = random.Random(21)
    for n in (1, 80, 91, 300, 700, 1000):
        plain = _plain(n % 64, bytes(rng.randint(33, 126) for _ in range(n)))
        field = repair_field(plain, 3)
        total = len(plain)
        assert (field[0] - 32) << 6 | (field[1] - 32) == total
        m = -(-(total - 4) // 255)
        assert len(field) == 2 + 3 * m
        head = 7 if plain[1] == 32 else 4
        for at in (2, head, total // 2, total - 4):  # SEQ, the data, its last character
            damaged = bytearray(plain)
            damaged[at] ^= 0x21
            assert apply_repair(bytes(damaged), field, BlockCheck.CRC16) == plain, (n, at)
        assert apply_repair(plain[:-1], field, BlockCheck.CRC16) is None  # another length
        in_check = bytearray(plain)
        in_check[-1] ^= 0x01  # the sums all agree: nothing to mend
        assert apply_repair(bytes(in_check), field, BlockCheck.CRC16) is None
        twice = bytearray(plain)
        twice[head] ^= 0x21
        twice[head + m] ^= 0x12  # the same block twice: refused
        assert apply_repair(bytes(twice), field, BlockCheck.CRC16) is None
        length = bytearray(plain)
        length[1] ^= 0x01  # LEN is never mended
        assert apply_repair(bytes(length), field, BlockCheck.CRC16) is None
    assert apply_repair(plain, b"", BlockCheck.CRC16) is None
    assert apply_repair(plain, b"\x00\x00", BlockCheck.CRC16) is None
    assert apply_repair(plain, field, BlockCheck.SUM6) is None  # only under a CRC


def damage_nth(kind: bytes, which: set[int], direction: str, at: int) -> Filter:
    """A filter damaging character ``at`` of the packets of type ``kind``
    numbered ``which`` (from 1) in ``direction``."""
    seen = 0

    def f(d: str, pkt: bytes, now: float) -> list[bytes]:
        nonlocal seen
        if d == direction and pkt[3:4] == kind:
            seen += 1
            if seen in which:
                hit = bytearray(pkt)
                hit[min(at, len(hit) - 6)] ^= 0x40
                return [bytes(hit)]
        return [pkt]

    return f


def test_a_damaged_data_packet_is_mended_by_a_repair_packet() -> None:
    """Packets 2-5 arrive with one character damaged: the receiver keeps
    them, the sender answers each loss with a 15-character repair packet
    instead of the packet again, and the receiver takes each packet mended,
    exactly as it was sent: no whole resend at all."""
    from dataclasses import replace

    from .simlink import MOON_HINTS, QueuedRun

    cfg = replace(MOON_HINTS, correction=True, max_packet_time=None)
    payload = random.Random(9).randbytes(12_000)
    run = QueuedRun(payload, cfg, cfg, [damage_nth(b"D", {2, 3, 4, 5}, "ab", 40)])
    got, _ = run.read_all()
    assert got == payload
    sent = [p for _, p in run.link.sent["ab"]][:64]
    assert [p[2] - 32 for p in sent if p[3:4] == b"r"] == [2, 3, 4, 5]
    a, b = run.a.statistics(), run.b.statistics()
    assert (a.repairs_sent, a.retransmissions) == (4, 0)
    assert (b.repaired, b.repairs_failed) == (4, 0)
    assert b.duplicates_received == 0


def test_no_repair_packet_without_the_sums_agreed_and_two_at_the_end() -> None:
    """Without sums agreed a damaged packet is resent whole.  With them, the
    last packet of a transfer is repaired too, by two copies of its repair
    (nothing sent after it could show one lost before its timeout); the
    second finds the packet mended and is answered with an ACK."""
    from dataclasses import replace

    from .simlink import MOON_HINTS, QueuedRun

    payload = random.Random(4).randbytes(3000)
    plain = replace(MOON_HINTS, max_packet_time=None)
    run = QueuedRun(payload, plain, plain, [damage_nth(b"D", {2}, "ab", 40)])
    assert run.read_all()[0] == payload
    assert (run.a.statistics().repairs_sent, run.a.statistics().retransmissions) == (0, 1)
    cfg = replace(plain, correction=True)
    last = payload[:300]
    run = QueuedRun(last, cfg, cfg, [damage_nth(b"D", {1}, "ab", 40)])
    assert run.read_all()[0] == last
    assert [p[3:4] for _, p in run.link.sent["ab"]].count(b"r") == 2
    a, b = run.a.statistics(), run.b.statistics()
    assert (a.repairs_sent, a.retransmissions) == (1, 0)
    assert (b.repaired, b.repairs_failed) == (1, 0)


def test_a_repair_for_a_packet_never_held_is_nakked_or_acked_at_once() -> None:
    """The receiver's side alone: a repair packet it cannot use is answered
    at once, a NAK for a packet still missing, an ACK for one it has."""
    from dataclasses import replace

    from .simlink import MOON_HINTS, connected_pair

    cfg = replace(MOON_HINTS, correction=True)
    _, b, link = connected_pair(cfg, cfg)
    assert b.statistics().correction
    seq, head = b._seq_fields(5)
    forged = build_packet(
        Packet(seq=seq, type="r", data=head + repair_field(_plain(5, b"hello" * 30), 3)),
        BlockCheck.CRC16,
    )
    b.receive_data(forged, link.now)
    out = b.data_to_send(link.now)
    assert out[3:4] == b"N"
    assert out[2] - 32 == seq
    assert b.statistics().repairs_failed == 1
    assert b.statistics().repaired == 0


def test_a_packet_longer_than_a_repair_can_name_is_resent_whole() -> None:
    with pytest.raises(ValueError, match="up to 4095"):
        repair_field(_plain(1, b"x" * 4100), 3)
    from dataclasses import replace

    from .simlink import MOON_HINTS, QueuedRun

    cfg = replace(MOON_HINTS, correction=True, max_packet_length=6000, max_packet_time=None)
    payload = random.Random(5).randbytes(20_000)
    run = QueuedRun(payload, cfg, cfg, [damage_nth(b"D", {2}, "ab", 40)])
    assert run.read_all()[0] == payload
    assert max(len(p) for _, p in run.link.sent["ab"]) > 4096
    assert (run.a.statistics().repairs_sent, run.a.statistics().retransmissions) == (0, 1)


def test_a_nak_for_a_packet_sent_once_brings_its_repair_at_once() -> None:
    """A packet sent once has no earlier copy for a NAK to be about: with
    repairs agreed its first resend (a repair packet) goes whatever the NAK
    horizon says; without, the horizon still sets early NAKs aside.  (Judged
    by a model of the line running late, the NAK for the last packet of a
    transfer was set aside and its repair waited 1.6 s for the next ACK.)"""
    from dataclasses import replace

    from .simlink import MOON_HINTS, connected_pair, split_packets

    for correction in (True, False):
        cfg = replace(MOON_HINTS, correction=correction)
        a, _, link = connected_pair(cfg, cfg)
        now = link.now
        a.send(random.Random(2).randbytes(2000), now)
        first = next(p for p in split_packets(a.data_to_send(now)) if p[3:4] == b"D")
        later = now + 1.0  # past its line time, well inside the horizon (2.6 s and more)
        head = first[7:9] if a.statistics().long_sequence else b""  # (extended header)
        nak = build_packet(
            Packet(seq=first[2] - 32, type=PacketType.NAK, data=head),
            BlockCheck.CRC16,
        )
        a.receive_data(nak, later)
        sent = [p[3:4] for p in split_packets(a.data_to_send(later))]
        assert (b"r" in sent) is correction, (correction, sent)
        assert a.statistics().repairs_sent == int(correction)


def test_a_copy_of_a_packet_just_acknowledged_is_not_acknowledged_again() -> None:
    """The listener's EOF and its copies cross our data: a copy that arrives
    before our ACK could have reached the peer draws no second ACK (a netcat
    listener's EOF drew eight, 0.5 s of a 2400 bit/s line); one that arrives
    later does, in case our ACK was lost."""
    from .simlink import connected_pair, split_packets

    a, b, link = connected_pair()
    now = link.now
    b.send_eof(now)
    eof = next(p for p in split_packets(b.data_to_send(now)) if p[3:4] == b"Z")
    srtt = a.statistics().smoothed_rtt
    assert srtt is not None

    def acks_at(t: float) -> int:
        a.receive_data(eof, t)
        return [p[3:4] for p in split_packets(a.data_to_send(t))].count(b"Y")

    assert acks_at(now + 1.0) == 1
    assert acks_at(now + 1.05) == 0  # an idle copy behind it
    assert acks_at(now + 1.0 + 0.8 * srtt) == 0  # a resend our ACK could not have stopped
    assert a.statistics().duplicate_acks_held == 2
    assert acks_at(now + 1.0 + 1.0 * srtt) == 1  # our ACK may have been lost


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_netcat_table_lines_deliver_exactly_against_a_half_closed_listener(seed: int) -> None:
    """As the netcat runs them (no hints, a first flight, dense, sums and
    repairs), against a listener that half-closes at once, as a netcat
    listener with nothing to send does: every byte once, in order, on a
    1e-3 line at 1.3 s and on a printable one at 1e-4."""
    for ber, encoding in ((1e-3, EIGHT_BIT_CLEAN), (1e-4, PRINTABLE)):
        payload = random.Random(seed).randbytes(8192)
        m = simulate(
            payload,
            rate=2400,
            delay=1.3,
            byte_error_rate=ber,
            burst=None,
            window=31,
            max_len=None,
            encoding=encoding,
            seed=seed,
            time_cap=600,
            hints="none",
            dense=True,
            first_flight=True,
            correction=True,
            max_packet_time=None,
            far_eof=True,
        )
        assert (m.end, m.ok, m.delivered) == ("complete", True, 8192), (ber, m)
