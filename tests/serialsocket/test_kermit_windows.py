"""Kermit windows: no false completion (issue 17, finding 9), on virtual time.

C-Kermit, with windows, NAKs sequence numbers beyond a packet it still
misses, and ACKs in-window packets (Z and B too) as they arrive.  Our sender
took a NAK of the packet after the last one sent as an ACK of everything
outstanding, sent Z with a D packet missing, got Z and B acknowledged, and
exited 0 with the receiver holding part of the file.  Here a scripted
receiver that does exactly that (:class:`NakAheadReceiver`) talks to the real
:func:`kermit_send` over a memory stream on trio's MockClock; and our own
receiver is checked for the mirror mistake (acknowledging Z before the data
in front of it).
"""

from __future__ import annotations

import pathlib
import random

import trio
import trio.testing

from serialsocket.kermit import (
    FileCompleted,
    KermitConfig,
    KermitReceiver,
    KermitTransferError,
    TransferComplete,
    kermit_receive,
    kermit_send,
)
from serialsocket.kermit._params import KermitInit, negotiate_kermit
from serialsocket.packets import BlockCheck, Packet, PacketParser, PacketReceived, build_packet

CONFIG = KermitConfig(window=8, max_packet_length=96, attributes=False, timeout=5.0, retry_limit=6)
"""Window 8, normal packets (about 90 file bytes per D), a fixed 5 s timeout."""

SIZE = 700
"""Eight D packets: more than one window, so the sender's window slides."""


class NakAheadReceiver:
    """A scripted windowed receiver that answers like C-Kermit in the issue's logs.

    Every packet that arrives is ACKed at once (Z and B included: the ACK says
    "got this packet", nothing more).  While an earlier D is missing, each D
    that arrives is also answered by a NAK of the sequence number after the
    highest one seen: a NAK *ahead*.  The ``victim``-th distinct D packet (0 =
    the first) is lost on the line ``lose`` times.

    Attributes:
        arrivals: (type, seq) of every packet that reached it, lost ones excluded.
        data: file bytes of each D received, by sequence number.
    """

    def __init__(self, *, victim: int, lose: int) -> None:
        self._victim = victim
        self._lose = lose
        self._neg = negotiate_kermit(CONFIG, KermitInit.mine(CONFIG), KermitInit.mine(CONFIG))
        self._parser = PacketParser(max_length=200, check=BlockCheck.SUM6)
        self._d_order: list[int] = []
        self.arrivals: list[tuple[str, int]] = []
        self.data: dict[int, bytes] = {}

    @property
    def victim_seq(self) -> int:
        return self._d_order[self._victim]

    def missing(self) -> bool:
        """An earlier D is missing: one was seen first after the victim, the victim never came."""
        return len(self._d_order) > self._victim and self.victim_seq not in self.data

    def before_victim(self) -> bytes:
        """The file bytes received in order before the victim's place."""
        return b"".join(self.data[seq] for seq in self._d_order[: self._victim])

    def file(self) -> bytes:
        """The D packets' bytes in sending order (a gap where one never arrived)."""
        return b"".join(self.data.get(seq, b"") for seq in self._d_order)

    def answer(self, line: bytes) -> bytes:
        """The bytes it sends back for ``line``."""
        out = bytearray()
        self._parser.receive_data(line)
        while (event := self._parser.next_event()) is not None:
            assert isinstance(event, PacketReceived), event  # a clean line
            packet = event.packet
            if packet.type == "S":
                init = KermitInit.mine(CONFIG).encode()
                out += build_packet(Packet(seq=packet.seq, type="Y", data=init), BlockCheck.SUM6)
                self._parser.check = self._neg.check
                continue
            if packet.type == "D":
                if packet.seq not in self._d_order:
                    self._d_order.append(packet.seq)
                victim = len(self._d_order) > self._victim and packet.seq == self.victim_seq
                if victim and self._lose > 0:
                    self._lose -= 1
                    continue  # lost on the line
                self.data[packet.seq] = self._neg.receive_encoding.decode(packet.data)
            self.arrivals.append((packet.type, packet.seq))
            out += build_packet(Packet(seq=packet.seq, type="Y"), self._neg.check)
            if packet.type == "D" and self.missing():
                ahead = (max(self.data) + 1) % 64
                out += build_packet(Packet(seq=ahead, type="N"), self._neg.check)
        return bytes(out)


def _send_to_script(
    tmp_path: pathlib.Path, script: NakAheadReceiver
) -> tuple[bytes, object, list[object]]:
    """Run kermit_send against ``script`` on virtual time; (file, stats or error, events)."""
    data = random.Random(17).randbytes(SIZE)
    path = tmp_path / "f.bin"
    path.write_bytes(data)
    events: list[object] = []

    async def run() -> object:
        ours, theirs = trio.testing.memory_stream_pair()

        async def far_end() -> None:
            while chunk := await theirs.receive_some(65536):
                if reply := script.answer(chunk):
                    await theirs.send_all(reply)

        async with trio.open_nursery() as nursery:
            nursery.start_soon(far_end)
            try:
                result: object = await kermit_send(ours, [path], CONFIG, on_event=events.append)
            except KermitTransferError as exc:
                result = exc
            nursery.cancel_scope.cancel()
        return result

    result = trio.run(run, clock=trio.testing.MockClock(autojump_threshold=0))
    return data, result, events


def test_a_nak_ahead_does_not_complete_the_file_and_the_missing_packet_is_resent(
    tmp_path: pathlib.Path,
) -> None:
    """The second D is lost twice.  The old sender took the NAK ahead as an ACK
    of everything, sent Z and B, had both ACKed, and returned success with the
    receiver short of 90 bytes."""
    script = NakAheadReceiver(victim=1, lose=2)
    data, result, events = _send_to_script(tmp_path, script)
    assert script.file() == data  # the receiver has the whole file
    victim = script.victim_seq
    # The missing D was retransmitted and arrived before Z went out.
    types = [t for t, _ in script.arrivals]
    assert types.index("Z") > script.arrivals.index(("D", victim))
    assert all(t == "D" for t in types[types.index("F") + 1 : types.index("Z")])
    assert types[-2:] == ["Z", "B"]
    assert not isinstance(result, KermitTransferError), result
    stats = result
    assert getattr(stats, "acknowledged_bytes", None) == SIZE
    assert getattr(stats, "files", None) == 1
    assert events[-1] == TransferComplete()


def test_a_packet_that_never_arrives_ends_in_failure_saying_what_was_acknowledged(
    tmp_path: pathlib.Path,
) -> None:
    """The second D never arrives.  The old sender returned success (Z and B
    ACKed by a receiver with a 90-byte hole); now it gives up after its retries,
    never sends Z, and says how much the receiver acknowledged."""
    script = NakAheadReceiver(victim=1, lose=10**6)
    data, result, events = _send_to_script(tmp_path, script)
    assert isinstance(result, KermitTransferError), result
    assert not result.by_peer
    assert "Z" not in [t for t, _ in script.arrivals]
    assert not any(isinstance(e, TransferComplete | FileCompleted) for e in events)
    stats = result.statistics
    first = len(script.before_victim())  # only the D before the hole counts
    assert stats.acknowledged_bytes == first
    # The window (8 D packets) filled up behind the hole; the rest never left.
    assert script.before_victim() == data[:first]
    sent = stats.file_bytes
    assert len(script.file()) < sent < SIZE
    assert str(result) == (
        f"too many retries: packet 3 (D) was never acknowledged, after 10 tries; "
        f"the receiver confirmed 0 of 1 files whole; "
        f"of {SIZE} bytes, {first} were acknowledged, {sent - first} sent but not "
        f"acknowledged, {SIZE - sent} never sent"
    )
    assert script.file() != data


# -- the receiver: the mirror mistake ------------------------------------------------


def _packet(seq: int, ptype: str, data: bytes = b"") -> bytes:
    return build_packet(Packet(seq=seq, type=ptype, data=data), BlockCheck.CRC16)


def _receiver_in_a_file() -> KermitReceiver:
    receiver = KermitReceiver(CONFIG, 0.0)
    init = KermitInit.mine(CONFIG).encode()
    receiver.receive_data(build_packet(Packet(seq=0, type="S", data=init), BlockCheck.SUM6), 0.1)
    receiver.receive_data(_packet(1, "F", b"f.bin"), 0.2)
    receiver.data_to_send()
    while receiver.next_event() is not None:
        pass
    return receiver


def test_receiver_acks_z_only_once_every_d_before_it_has_arrived() -> None:
    """A Z that overtakes a missing D (a sender that does not wait, or a lost
    D) is not acknowledged: its ACK would tell the sender the whole file is
    here.  The old receiver ACKed every in-window packet on arrival."""
    receiver = _receiver_in_a_file()
    receiver.receive_data(_packet(3, "D", b"world"), 1.0)
    receiver.receive_data(_packet(4, "Z"), 1.1)
    assert receiver.data_to_send() == _packet(3, "Y") + _packet(2, "N")
    assert receiver.next_event() is None
    receiver.receive_data(_packet(4, "Z"), 1.2)  # a second copy: still held
    assert receiver.data_to_send() == b""
    receiver.receive_data(_packet(2, "D", b"hello "), 2.0)
    assert receiver.data_to_send() == _packet(2, "Y") + _packet(4, "Y")
    events = []
    while (event := receiver.next_event()) is not None:
        events.append(event)
    assert events[-1] == FileCompleted("f.bin", discarded=False)
    receiver.receive_data(_packet(4, "Z"), 2.1)  # an old copy: its ACK again
    assert receiver.data_to_send() == _packet(4, "Y")


def test_receiver_acks_b_only_in_order() -> None:
    receiver = _receiver_in_a_file()
    receiver.receive_data(_packet(3, "B"), 1.0)  # Z 2 is missing
    assert receiver.data_to_send() == _packet(2, "N")  # no ACK of B
    assert not receiver.finished
    receiver.receive_data(_packet(2, "Z"), 1.1)
    assert receiver.data_to_send() == _packet(2, "Y") + _packet(3, "Y")
    assert receiver.finished


def test_a_file_that_cannot_be_stored_is_never_acknowledged(tmp_path: pathlib.Path) -> None:
    """The ACK of Z leaves only after the file is renamed into place; when that
    fails, E goes out instead and both sides fail.  The old loop sent the ACK
    of Z before storing the file, and the OSError escaped as a traceback."""
    src = tmp_path / "f.bin"
    src.write_bytes(b"x" * 300)
    out = tmp_path / "out"
    (out / "f.bin").mkdir(parents=True)  # the final name is taken by a directory
    (out / "f.bin" / "keep").write_bytes(b"")

    async def run() -> tuple[BaseException | None, BaseException | None]:
        a, b = trio.testing.memory_stream_pair()
        errors: list[BaseException | None] = [None, None]

        async def side(i: int, coro: object) -> None:
            try:
                await coro  # type: ignore[misc]
            except KermitTransferError as exc:
                errors[i] = exc

        async with trio.open_nursery() as nursery:
            nursery.start_soon(side, 1, kermit_receive(b, out, CONFIG))
            await side(0, kermit_send(a, [src], CONFIG))
        return errors[0], errors[1]

    sent, received = trio.run(run, clock=trio.testing.MockClock(autojump_threshold=0))
    assert isinstance(received, KermitTransferError)
    assert not received.by_peer
    assert str(received).startswith(f"cannot store {out / 'f.bin'}: ")
    assert str(received).endswith(
        "; 0 files stored whole; 300 bytes of the file in progress kept in "
        + str(out / "f.bin.part")
    )
    assert isinstance(sent, KermitTransferError)
    assert sent.by_peer
    assert str(sent).startswith("peer reported: Cannot store file; the receiver confirmed 0 of 1")
    assert sent.statistics.files == 0
