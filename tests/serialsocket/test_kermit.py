"""Kermit file transfer: Send-Init fields, negotiation and the two state machines.

Deterministic: the machines run on virtual time against a model wire (delay,
seeded byte corruption); the one trio test moves a file over a real pty pair.
"""

from __future__ import annotations

import heapq
import io
import pathlib
import random

import pytest
import trio

from serialsocket import LocalProtocolError, RemoteProtocolError, open_pty_pair
from serialsocket._cli import main as cli_main
from serialsocket.kermit import (
    FileCompleted,
    FileData,
    FileStarted,
    KermitConfig,
    KermitEvent,
    KermitReceiver,
    KermitSender,
    KermitState,
    KermitStatistics,
    OutgoingFile,
    TransferComplete,
    TransferFailed,
    kermit_receive,
    kermit_send,
)
from serialsocket.kermit._io import safe_file_name
from serialsocket.kermit._params import KermitInit, negotiate_kermit
from serialsocket.packets import BlockCheck, Packet, build_packet

Side = KermitSender | KermitReceiver

# -- Send-Init fields ------------------------------------------------------------


def test_our_send_init_field_is_exact() -> None:
    # MAXL 89 'y', TIME 9 (the timers assume 8 x 1000 characters queued at an
    # assumed 9600 bit/s, 8.4 s, plus 1 s), no padding, EOL CR, '#', QBIN Y,
    # CHKT 3, REPT '~', CAPAS 2|4|8|16 '>', WINDO 31 '?', MAXLX 993 = 10*95+43
    # '*K', CHKPNT 0, CHKINT ___, WHATAMI tochar(32|2) 'B'.
    assert KermitInit.mine(KermitConfig()).encode() == b"y) @-#Y3~>?*K0___B"


def test_seven_bit_normal_packets_field() -> None:
    config = KermitConfig(max_packet_length=94, window=1, seven_bit=True, repeat=False)
    # MAXL 89 (C-Kermit overshoot margin), TIME 2 (the floor), QBIN '&',
    # REPT blank, CAPAS 8|16 (attributes, RESEND), WINDO 1.
    assert KermitInit.mine(config).encode() == b'y" @-#&3 8! w0___B'


def test_decode_gkermit_send_init() -> None:
    peer = KermitInit.decode(b"~' @-#Y3~*!J*0+++B\"U1A")  # reference/kermit.md section 4
    assert (peer.max_packet_length, peer.timeout, peer.eol) == (4007, 7.0, 13)
    assert (peer.qctl, peer.qbin, peer.rept) == (ord("#"), ord("Y"), ord("~"))
    assert peer.check is BlockCheck.CRC16
    assert (peer.long_packets, peer.windows, peer.attributes, peer.window) == (
        True,
        False,
        True,
        1,
    )


def test_decode_ckermit_send_init() -> None:
    peer = KermitInit.decode(b'~/ @-#Y3~^(J)0___F"U1@')
    assert (peer.max_packet_length, peer.timeout, peer.window) == (3999 + 7, 15.0, 8)
    assert peer.windows
    assert peer.long_packets
    assert peer.attributes


def test_negotiate_with_ckermit_and_gkermit() -> None:
    config = KermitConfig()
    mine = KermitInit.mine(config)
    ck = negotiate_kermit(config, mine, KermitInit.decode(b'~/ @-#Y3~^(J)0___F"U1@'))
    assert (ck.window, ck.send_max_length, ck.check) == (8, 1000, BlockCheck.CRC16)
    assert ck.timeout == pytest.approx(1 + 8 * 1012 * 10 / 9600)  # the line's, not the peer's
    assert ck.peer_time == 15
    assert ck.recovery  # C-Kermit's CAPAS '^' has RESEND
    assert ck.send_encoding.qbin is None
    assert ck.send_encoding.rept == ord("~")
    gk = negotiate_kermit(config, mine, KermitInit.decode(b"~' @-#Y3~*!J*0+++B\"U1A"))
    assert (gk.window, gk.retry_limit) == (1, 10)


def test_eighth_bit_prefix_when_the_peer_asks() -> None:
    config = KermitConfig()
    neg = negotiate_kermit(config, KermitInit.mine(config), KermitInit.decode(b"~' @-#&3~"))
    assert neg.send_encoding.qbin == ord("&")
    assert neg.receive_encoding.qbin == ord("&")
    assert neg.check is BlockCheck.CRC16


def test_seven_bit_line_refused_by_peer_is_a_remote_error() -> None:
    config = KermitConfig(seven_bit=True)
    with pytest.raises(RemoteProtocolError, match="refuses 8th-bit prefixing"):
        negotiate_kermit(config, KermitInit.mine(config), KermitInit.decode(b"~' @-#N3~"))


def test_fixed_local_timeout_overrides_peer_time_and_retry_limit_covers_window() -> None:
    config = KermitConfig(timeout=30.0, window=31, retry_limit=5)
    neg = negotiate_kermit(config, KermitInit.mine(config), KermitInit.mine(config))
    assert (neg.timeout, neg.window, neg.retry_limit) == (30.0, 31, 32)


def test_config_errors_say_what_to_do() -> None:
    with pytest.raises(LocalProtocolError, match=r"choose e\.g\. 96 or 1000"):
        KermitConfig(max_packet_length=5)
    with pytest.raises(LocalProtocolError, match=r"1\.\.31"):
        KermitConfig(window=32)


# -- the machines on a model wire -----------------------------------------------


def _simulate(
    sender: KermitSender,
    receiver: KermitReceiver,
    *,
    delay: float = 0.0,
    error: float = 0.0,
    seed: int = 0,
    steps: int = 200_000,
) -> tuple[bytes, list[KermitEvent], list[KermitEvent], float]:
    """Run both machines to the end on virtual time; returns (received, s_events, r_events, t)."""
    rng = random.Random(seed)
    now = 0.0
    flight: list[tuple[float, int, int, bytes]] = []
    order = 0
    sides: tuple[Side, Side] = (sender, receiver)
    received = bytearray()
    s_events: list[KermitEvent] = []
    r_events: list[KermitEvent] = []
    for _ in range(steps):
        for i, side in enumerate(sides):
            out = bytearray(side.data_to_send())
            for j in range(len(out)):
                if error and rng.random() < error:
                    out[j] ^= 1 << rng.randrange(8)
            if out:
                heapq.heappush(flight, (now + delay, order, 1 - i, bytes(out)))
                order += 1
        while (e := sender.next_event()) is not None:
            s_events.append(e)
        while (e := receiver.next_event()) is not None:
            r_events.append(e)
            if isinstance(e, FileData):
                received += e.data
        if sender.finished and receiver.finished:
            break
        times = [t for t in (sender.get_timer(), receiver.get_timer()) if t is not None]
        if flight:
            times.append(flight[0][0])
        if not times:
            break
        now = max(now, min(times))
        while flight and flight[0][0] <= now:
            _, _, dest, data = heapq.heappop(flight)
            sides[dest].receive_data(data, now)
        for side in sides:
            timer = side.get_timer()
            if timer is not None and timer <= now:
                side.handle_timer(now)
    return bytes(received), s_events, r_events, now


def _payload(size: int, seed: int = 7) -> bytes:
    head = bytes(range(256)) + b"\x00" * 300 + b"~" * 100 + b"\xfe" * 50
    return (head + random.Random(seed).randbytes(size))[:size]


def _pair(config: KermitConfig, data: bytes) -> tuple[KermitSender, KermitReceiver]:
    files = [OutgoingFile("a.bin", len(data), io.BytesIO(data))]
    return KermitSender(files, config, 0.0), KermitReceiver(config, 0.0)


@pytest.mark.parametrize(
    ("window", "length", "seven_bit"),
    [(1, 96, False), (1, 1000, True), (8, 96, True), (8, 1000, False), (31, 9031, False)],
)
def test_clean_transfer_is_exact(window: int, length: int, seven_bit: bool) -> None:
    data = _payload(30_000)
    config = KermitConfig(window=window, max_packet_length=length, seven_bit=seven_bit)
    sender, receiver = _pair(config, data)
    got, s_events, r_events, _ = _simulate(sender, receiver)
    assert got == data
    assert s_events == [FileStarted("a.bin"), FileCompleted("a.bin", False), TransferComplete()]
    assert r_events[0] == FileStarted("a.bin")
    assert r_events[-2:] == [FileCompleted("a.bin", False, len(data)), TransferComplete()]
    stats = sender.statistics()
    assert (stats.retransmissions, stats.timeouts, stats.damaged) == (0, 0, 0)
    assert (stats.state, receiver.state) == (KermitState.DONE, KermitState.DONE)
    assert stats.file_bytes == len(data) == receiver.statistics().file_bytes
    assert stats.window == window
    # S, F, A, the D packets, Z, B: every packet sent once and acknowledged once.
    assert stats.packets_sent == receiver.statistics().packets_received
    assert receiver.statistics().packets_sent == stats.packets_received == stats.packets_sent


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("window", [1, 8])
def test_delayed_noisy_transfer_delivers_every_byte(seed: int, window: int) -> None:
    data = _payload(20_000, seed)
    config = KermitConfig(window=window, max_packet_length=1000, timeout=2.0, retry_limit=0)
    sender, receiver = _pair(config, data)
    got, _, r_events, t = _simulate(sender, receiver, delay=0.25, error=2e-4, seed=seed)
    assert got == data
    assert r_events[-1] == TransferComplete()
    assert sender.state is KermitState.DONE
    assert t > 0.5  # the delay was really there: at least S/ACK and B/ACK round trips
    # The noise was really there and was repaired by retransmission.
    assert receiver.statistics().damaged > 0
    assert sender.statistics().retransmissions > 0


def test_several_files_and_an_empty_one() -> None:
    blobs = [b"", b"x" * 5000, _payload(3000)]
    files = [OutgoingFile(f"f{i}", len(b), io.BytesIO(b)) for i, b in enumerate(blobs)]
    config = KermitConfig(window=4)
    sender, receiver = KermitSender(files, config, 0.0), KermitReceiver(config, 0.0)
    got, _, r_events, _ = _simulate(sender, receiver)
    assert got == b"".join(blobs)
    done = [e for e in r_events if isinstance(e, FileCompleted)]
    assert done == [FileCompleted(f"f{i}", False, len(b)) for i, b in enumerate(blobs)]
    assert sender.statistics().files == 3


def test_sender_gives_up_after_the_retry_limit_with_an_e_packet() -> None:
    sender = KermitSender([], KermitConfig(retry_limit=3, timeout=7.0), 0.0)
    first = sender.data_to_send()
    assert first.startswith(b"\x01")
    assert first[3:4] == b"S"
    assert sender.get_timer() == 7.0  # a fixed --timeout: no backoff
    for k in range(1, 4):
        sender.handle_timer(7.0 * k)
        assert sender.data_to_send() == first  # the same S, byte for byte
        assert sender.get_timer() == 7.0 * (k + 1)
    sender.handle_timer(28.0)
    error = build_packet(Packet(seq=1, type="E", data=b"Too many retries"), BlockCheck.SUM6)
    assert sender.data_to_send() == error
    assert sender.next_event() == TransferFailed(
        "no answer at all: nothing came back from the peer in 28 s (packet 0 (S) was never "
        "acknowledged, 4 tries); is the other side running, on this line and rate?",
        by_peer=False,
    )
    assert sender.get_timer() is None
    assert sender.state is KermitState.FAILED


def _ack_s(config: KermitConfig) -> bytes:
    return build_packet(
        Packet(seq=0, type="Y", data=KermitInit.mine(config).encode()), BlockCheck.SUM6
    )


def test_nak_of_the_next_packet_acknowledges_the_current_one() -> None:
    config = KermitConfig(window=1, attributes=False)
    data = b"hello"
    sender = KermitSender([OutgoingFile("h", 5, io.BytesIO(data))], config, 0.0)
    sender.data_to_send()
    sender.receive_data(_ack_s(config), 1.0)
    f = sender.data_to_send()
    assert f[3:4] == b"F"
    assert f[2] == 32 + 1
    sender.receive_data(build_packet(Packet(seq=2, type="N"), BlockCheck.CRC16), 2.0)
    d = sender.data_to_send()
    assert d == build_packet(Packet(seq=2, type="D", data=b"hello"), BlockCheck.CRC16)
    assert sender.state is KermitState.SEND_DATA


def test_reack_of_the_previous_packet_resends_at_once_in_stop_and_wait() -> None:
    # G-Kermit answers a damaged packet by ACKing the one before it.
    config = KermitConfig(window=1, attributes=False)
    sender = KermitSender([OutgoingFile("h", 1, io.BytesIO(b"z"))], config, 0.0)
    sender.data_to_send()
    sender.receive_data(_ack_s(config), 1.0)
    f = sender.data_to_send()
    sender.receive_data(build_packet(Packet(seq=0, type="Y"), BlockCheck.CRC16), 2.0)
    assert sender.data_to_send() == f
    assert sender.statistics().retransmissions == 1


def test_receiver_reacks_a_repeated_send_init_identically() -> None:
    config = KermitConfig()
    receiver = KermitReceiver(config, 0.0)
    s = build_packet(Packet(seq=0, type="S", data=b"~' @-#Y3~*!J*0+++B\"U1A"), BlockCheck.SUM6)
    receiver.receive_data(s, 1.0)
    ack = receiver.data_to_send()
    assert ack == _ack_s(config)
    receiver.receive_data(s, 2.0)  # our ACK was lost: the same bytes again
    assert receiver.data_to_send() == ack
    assert receiver.state is KermitState.RECEIVE_FILE


def test_error_packet_from_the_peer_ends_the_transfer() -> None:
    receiver = KermitReceiver(KermitConfig(), 0.0)
    receiver.receive_data(
        build_packet(Packet(seq=0, type="E", data=b"Disk full"), BlockCheck.SUM6), 1.0
    )
    assert receiver.next_event() == TransferFailed("peer reported: Disk full", by_peer=True)
    assert receiver.data_to_send() == b""  # E is never acknowledged
    assert receiver.get_timer() is None


def test_receiver_naks_window_low_on_timeout() -> None:
    receiver = KermitReceiver(KermitConfig(timeout=4.0), 0.0)
    assert receiver.get_timer() == 4.0
    receiver.handle_timer(4.0)
    assert receiver.data_to_send() == build_packet(Packet(seq=0, type="N"), BlockCheck.SUM6)
    assert receiver.get_timer() == 8.0


def test_illegal_transition_is_a_local_error() -> None:
    sender = KermitSender([], KermitConfig(), 0.0)
    with pytest.raises(LocalProtocolError, match="illegal Kermit transition"):
        sender._goto(KermitState.RECEIVE_DATA)


@pytest.mark.parametrize(
    ("name", "safe"),
    [
        ("a.bin", "a.bin"),
        ("../../etc/passwd", "passwd"),
        ("/x/y", "y"),
        ("..", "unnamed"),
        ("", "unnamed"),
        ("a\x00b", "a_b"),
        ("C:\\dir\\f.txt", "f.txt"),
    ],
)
def test_safe_file_name(name: str, safe: str) -> None:
    assert safe_file_name(name) == safe


# -- the trio driver and the CLI -------------------------------------------------


def test_send_and_receive_over_a_pty_pair(tmp_path: pathlib.Path) -> None:
    src = tmp_path / "src"
    out = tmp_path / "out"
    src.mkdir()
    out.mkdir()
    paths = [src / "one.bin", src / "two.txt"]
    paths[0].write_bytes(_payload(50_000))
    paths[1].write_bytes(b"line\r\n" * 3000)
    config = KermitConfig(window=8, max_packet_length=1000, timeout=30.0)

    async def run() -> KermitStatistics:
        a, b = open_pty_pair()
        with trio.fail_after(60):
            async with a, b, trio.open_nursery() as nursery:
                nursery.start_soon(kermit_receive, b, out, config)
                return await kermit_send(a, paths, config)

    stats = trio.run(run)
    for p in paths:
        assert (out / p.name).read_bytes() == p.read_bytes()
    assert not list(out.glob("*.part"))
    assert (stats.files, stats.file_bytes, stats.retransmissions) == (2, 68_000, 0)


def test_cli_rejects_a_bad_packet_length(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["kermit", "send", "x", "--port", "/nonexistent", "--packet-length", "5"]
    with pytest.raises(SystemExit) as info:
        cli_main(argv)
    assert info.value.code == 2
    assert "argument --packet-length/--max-len: must be an integer in 12..9031" in (
        capsys.readouterr().err
    )


def test_cli_reports_a_port_that_cannot_be_opened(
    tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli_main(["kermit", "receive", str(tmp_path), "--port", "/nonexistent/tty"]) == 2
    assert "/nonexistent/tty" in capsys.readouterr().err


def test_ack_for_a_later_packet_resends_window_low_once_per_lost_copy() -> None:
    config = KermitConfig(window=8, max_packet_length=96, attributes=False, timeout=10.0)
    data = b"".join(b"line %04d\n" % i for i in range(200))
    sender = KermitSender([OutgoingFile("t", len(data), io.BytesIO(data))], config, 0.0)
    sender.data_to_send()
    sender.receive_data(_ack_s(config), 0.1)
    sender.data_to_send()  # F, seq 1

    def ack(seq: int, t: float) -> bytes:
        sender.receive_data(build_packet(Packet(seq=seq, type="Y"), BlockCheck.CRC16), t)
        return sender.data_to_send()

    burst = ack(1, 0.2)  # D 2..9 fill the window
    assert burst.count(b"\x01") == 8
    d2 = burst[: burst.index(b"\x01", 1)]
    assert ack(3, 0.3) == d2  # D 3 acked, D 2 not: its copy or its ACK was lost
    assert ack(4, 0.3) == b""  # D 4 left before the resend of D 2: proves nothing new
    assert sender.statistics().retransmissions == 1
    after = ack(2, 0.5)  # the resend got through: the window slides by 3
    assert after.count(b"\x01") == 3
    assert sender.statistics().timeouts == 0


def _sender_at_break(config: KermitConfig) -> tuple[KermitSender, bytes]:
    sender = KermitSender([], config, 0.0)
    sender.data_to_send()
    sender.receive_data(_ack_s(config), 1.0)
    b = sender.data_to_send()
    assert b == build_packet(Packet(seq=1, type="B"), BlockCheck.CRC16)
    return sender, b


def test_damaged_ack_of_break_ends_the_batch_without_waiting() -> None:
    # Captured through the relay: the ACK of B with its SEQ byte hit (bad header).
    sender, _ = _sender_at_break(KermitConfig(timeout=5.0))
    sender.receive_data(b"\x01%\xe7Y*A)\r", 2.0)
    assert sender.next_event() == TransferComplete(break_acknowledged=False)
    assert sender.state is KermitState.DONE
    assert sender.data_to_send() == b""


def test_unanswered_break_is_resent_twice_then_the_batch_ends() -> None:
    sender, b = _sender_at_break(KermitConfig(timeout=5.0, retry_limit=10))
    sender.handle_timer(6.0)
    sender.handle_timer(11.0)
    assert sender.data_to_send() == b + b
    sender.handle_timer(16.0)
    assert sender.data_to_send() == b""
    assert sender.next_event() == TransferComplete(break_acknowledged=False)
    assert sender.get_timer() is None


def test_with_windows_a_nak_of_the_next_packet_acknowledges_nothing() -> None:
    """Issue 17, finding 9: C-Kermit with windows NAKs sequence numbers beyond a
    packet it still misses.  Our sender took NAK(last sent + 1) as an ACK of
    everything outstanding, sent Z with data missing and exited 0."""
    config = KermitConfig(window=8, max_packet_length=96, attributes=False, timeout=10.0)
    data = b"".join(b"line %04d\n" % i for i in range(40))  # a few D packets
    sender = KermitSender([OutgoingFile("t", len(data), io.BytesIO(data))], config, 0.0)
    sender.data_to_send()
    sender.receive_data(_ack_s(config), 0.1)
    sender.data_to_send()  # F, seq 1
    sender.receive_data(build_packet(Packet(seq=1, type="Y"), BlockCheck.CRC16), 0.2)
    burst = sender.data_to_send()
    sent = burst.count(b"\x01")
    assert 2 <= sent <= 8  # D 2 .. 2+sent-1, the whole file
    nxt = 2 + sent
    # The receiver got every D but the first, ACKs them, then NAKs ahead.
    for seq in range(3, nxt):
        sender.receive_data(build_packet(Packet(seq=seq, type="Y"), BlockCheck.CRC16), 0.3)
    sender.data_to_send()
    sender.receive_data(build_packet(Packet(seq=nxt, type="N"), BlockCheck.CRC16), 0.4)
    out = sender.data_to_send()
    assert out[3:4] == b"D", "D 2 is still missing: resend it, never Z"
    assert out[2] - 32 == 2
    assert sender.state is KermitState.SEND_DATA
    # Only once D 2 is acknowledged does Z go out.
    sender.receive_data(build_packet(Packet(seq=2, type="Y"), BlockCheck.CRC16), 0.5)
    z = sender.data_to_send()
    assert z[3:4] == b"Z"
    assert sender.state is KermitState.SEND_EOF
