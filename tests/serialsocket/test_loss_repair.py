"""Repairs that do not wait for a timer (PROTOCOL.md 4.4).

On a long line every round trip of waiting is minutes, so three rules find
and fill losses sooner than a retransmission timeout:

* time-order loss detection: the ACK of a packet sent once proves every copy
  handed before it and still unacknowledged lost (the line and the peer's
  ACKs are first in, first out) -- any hole, not only the first;
* idle copies: while the line would idle, second copies of the packets in
  flight, newest first;
* doubled late resends: a packet already resent and lost again goes out
  twice.

Deterministic: scripted losses on the discrete-event line of simlink.
"""

from __future__ import annotations

import dataclasses

from serialsocket import Endpoint, EndpointConfig
from serialsocket.packets import Packet, PacketType, build_packet

from .simlink import SimLink, split_packets
from .test_arq_scenarios import CFG, connected, data


def _seq(packet: bytes) -> int:
    return packet[2] - 32  # MARK LEN SEQ TYPE: the wire's sequence number


def _is_data(packet: bytes) -> bool:
    return packet[3:4] == b"D"


def _seqs(wire: bytes) -> list[int]:
    return [_seq(p) for p in split_packets(wire)]


def _ack(seq: int, expected: int, window: int = 8) -> bytes:
    return build_packet(
        Packet(seq=seq, type=PacketType.ACK, data=bytes((32 + expected, 32 + window)))
    )


def test_a_lost_resend_behind_another_hole_is_found_by_a_later_ack() -> None:
    """Holes at 1 and 3; both resends are lost.  The ACK of packet 5, sent
    after them, proves both lost: 1 is the cumulative hole (fast retransmit
    found it before), 3 is not -- it waited for its timer, at Mars distance
    a backed-off timeout of two hours instead of one round trip."""
    cfg = dataclasses.replace(CFG, window=8)
    a, b, t = connected(cfg)
    sent = []
    for word in (b"one", b"two", b"three", b"four"):
        a.send(word, t)
        sent.append(a.data_to_send(t))
    b.receive_data(sent[1] + sent[3], t + 1)  # 1 and 3 lost
    a.receive_data(b.data_to_send(t + 1), t + 2)
    assert _seqs(a.data_to_send(t + 2)) == [1, 3]  # resent, and lost again
    a.send(b"five", t + 2)
    assert a.data_to_send(t + 2) == data(5, b"five")
    # Packet 5 arrives; only its ACK gets back (the NAKs are lost).
    a.receive_data(_ack(5, 1), t + 4)
    assert a.data_to_send(t + 4) == data(1, b"one") + data(3, b"three")
    s = a.statistics()
    assert s.timeouts == 0
    assert s.retransmissions == 4


def test_an_ack_proves_only_copies_sent_before_its_first_copy_lost() -> None:
    """Packet 1 was resent after packet 2 left.  An ACK of 1 may be for its
    first copy, which left before 2: it says nothing about 2."""
    cfg = dataclasses.replace(CFG, window=8)
    a, _b, t = connected(cfg)
    for word in (b"one", b"two"):
        a.send(word, t)
        a.data_to_send(t)
    a.receive_data(build_packet(Packet(seq=1, type=PacketType.NAK)), t + 2)
    assert a.data_to_send(t + 2) == data(1, b"one")
    a.receive_data(_ack(1, 2), t + 2.5)  # for the first copy of 1
    assert a.data_to_send(t + 2.5) == b""
    assert a.statistics().fast_retransmits == 0


LONG = EndpointConfig(one_way_delay=20.0, line_rate=2400, expedited=False)


def _long_pair(
    cfg: EndpointConfig, drop: set[tuple[int, int]]
) -> tuple[Endpoint, Endpoint, SimLink]:
    """A 2400 bit/s line, 20 s one way; ``drop`` names (sequence number,
    copy) pairs of data packets a->b that the line loses."""
    copies: dict[int, int] = {}

    def lose(direction: str, pkt: bytes, now: float) -> list[bytes]:
        if direction != "ab" or not _is_data(pkt):
            return [pkt]
        seq = _seq(pkt)
        copies[seq] = copies.get(seq, 0) + 1
        return [] if (seq, copies[seq]) in drop else [pkt]

    a, b = Endpoint(cfg), Endpoint(cfg)
    link = SimLink(a, b, delay=20.0, rate=2400, filters=[lose])
    b.listen()
    a.connect(0.0)
    link.run_until(lambda: a.parameters is not None and b.parameters is not None)
    return a, b, link


def _send_all(a: Endpoint, b: Endpoint, link: SimLink, payload: bytes) -> tuple[bytes, float]:
    start = link.now
    sent = 0
    got = bytearray()
    while len(got) < len(payload):
        sent += a.send(payload[sent:], link.now)
        assert link.step()
        got += b.read(None, link.now)
    return bytes(got), link.now - start


PAYLOAD = bytes(range(256)) * 4  # about 18 packets of 128 characters


def test_a_lost_last_packet_is_repaired_by_its_idle_copy() -> None:
    """The last packet has no later packet to reveal its loss: only its timer
    would, more than a round trip later.  Its idle copy, sent as soon as the
    line had nothing else to carry, arrives a few packet times after it."""
    a, b, link = _long_pair(LONG, drop=set())
    n = len(_send_all(a, b, link, PAYLOAD)[0])
    last = (a.statistics().send_next - 1) % 64
    clean = _long_pair(LONG, drop=set())
    _got, clean_time = _send_all(*clean, PAYLOAD)
    a, b, link = _long_pair(LONG, drop={(last, 1)})
    got, lossy_time = _send_all(a, b, link, PAYLOAD)
    assert got == PAYLOAD
    assert len(got) == n
    s = a.statistics()
    assert s.idle_copies > 0
    assert (s.timeouts, s.retransmissions) == (0, 0)
    assert lossy_time < clean_time + 2.0  # not a round trip (40 s) later


def test_without_idle_copies_the_same_loss_waits_a_round_trip() -> None:
    off = dataclasses.replace(LONG, idle_copies=0)
    a, b, link = _long_pair(off, drop=set())
    _send_all(a, b, link, PAYLOAD)
    last = (a.statistics().send_next - 1) % 64
    _got, clean_time = _send_all(*_long_pair(off, drop=set()), PAYLOAD)
    a, b, link = _long_pair(off, drop={(last, 1)})
    _got, lossy_time = _send_all(a, b, link, PAYLOAD)
    assert lossy_time > clean_time + 40.0
    assert a.statistics().idle_copies == 0


def test_no_idle_copies_where_a_round_trip_is_a_few_packets() -> None:
    short = dataclasses.replace(LONG, one_way_delay=0.27)
    a, b = Endpoint(short), Endpoint(short)
    link = SimLink(a, b, delay=0.27, rate=2400)
    b.listen()
    a.connect(0.0)
    link.run_until(lambda: a.parameters is not None and b.parameters is not None)
    _send_all(a, b, link, PAYLOAD)
    link.run_for(5.0)
    assert a.statistics().idle_copies == 0
    assert b.statistics().duplicates_received == 0


def _copies_of(link: SimLink, seq: int) -> list[float]:
    """When data packets with wire number ``seq`` (mod 64) went a->b."""
    return [t for t, p in link.sent["ab"] if _is_data(p) and _seq(p) == seq]


def test_a_packet_lost_on_its_resend_goes_out_twice_next_time() -> None:
    """Lost on its first copy and on its resend, a packet holds the window's
    base for a third round trip; its next resend goes out twice, so a third
    loss (one in 20 at 512 characters and 1e-4) does not add a fourth.
    Mid-transfer: new data is still queued when it goes.  (512 characters,
    fixed: the scenario counts copies by wire sequence number, and packet 67
    must come after the third copy of packet 3.)"""
    cfg = dataclasses.replace(LONG, idle_copies=0, max_packet_length=512)
    a, b, link = _long_pair(cfg, drop={(3, 1), (3, 2), (3, 3)})
    payload = bytes(range(256)) * 120
    got, _elapsed = _send_all(a, b, link, payload)
    assert got == payload
    first, resend, third, fourth = _copies_of(link, 3)[:4]  # then packet 67 (mod 64)
    assert resend - first > 40.0  # a round trip each
    assert third - resend > 40.0
    assert fourth - third < 1.0  # back to back
    assert a.statistics().doubled_resends == 1


def test_at_the_end_of_a_transfer_every_resend_goes_out_twice() -> None:
    """Nothing new to send: the line would idle, so a resend costs nothing
    twice, and a lost resend of the last round trip's packets does not add
    a round trip to the transfer."""
    cfg = dataclasses.replace(LONG, idle_copies=0)
    a, b, link = _long_pair(cfg, drop={(3, 1), (3, 2)})
    got, _elapsed = _send_all(a, b, link, PAYLOAD)
    assert got == PAYLOAD
    first, resend, twin = _copies_of(link, 3)
    assert resend - first > 40.0
    assert twin - resend < 1.0
    assert a.statistics().doubled_resends == 1


def test_an_interactive_sender_sends_no_idle_copies() -> None:
    """Commands written one at a time, each as the line allows, never wait
    for the line: copies would only make the next one wait behind them."""
    a, b, link = _long_pair(LONG, drop=set())
    for i in range(5):
        a.send(b"MOVE %d" % i, link.now)
        link.run_for(3.0)
    link.run_for(60.0)
    assert b.read(None, link.now) == b"".join(b"MOVE %d" % i for i in range(5))
    assert a.statistics().idle_copies == 0
    assert b.statistics().duplicates_received == 0
