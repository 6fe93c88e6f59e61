"""Capture (issue 24, part 4): the pcapng writer and reader, and the capturing stream.

No tshark here: every capture is parsed back with :func:`read_pcapng`, and
the bytes of a block are asserted exactly.  The dissector's tests are in
``test_capture_tshark.py``; the command lines' ``--capture`` in
``test_capture_cli.py``.
"""

from __future__ import annotations

import pathlib
import struct

import pytest
import trio
import trio.testing

from linksim import DirectionConfig, LinkConfig, endpoint_config_for
from linksim.link import ImpairedLink
from serialsocket import accept, connect
from serialsocket._params import negotiate
from serialsocket.capture import (
    LINKTYPE_SERIAL,
    LINKTYPE_TCPSTREAM,
    Capture,
    CapturedPacket,
    CaptureFile,
    CapturingStream,
    Direction,
    Interface,
    PcapngError,
    PcapngWriter,
    read_pcapng,
)
from serialsocket.packets import (
    MAX_PACKET_LENGTH,
    BlockCheck,
    InitParameters,
    Packet,
    PacketParser,
    PacketReceived,
)

EPOCH = 1_764_000_000.0
"""A fixed wall-clock origin for the virtual-clock captures (2025-11-24 16:00 UTC)."""


def test_linktypes_are_the_user_ones() -> None:
    assert (LINKTYPE_SERIAL, LINKTYPE_TCPSTREAM) == (147, 148)  # LINKTYPE_USER0, USER1


def test_section_header_bytes() -> None:
    shb = PcapngWriter("tl").header()
    assert shb.hex() == (
        "0a0d0d0a"  # block type (the same in either byte order)
        + "28000000"  # total length 40
        + "4d3c2b1a"  # byte-order magic
        + "01000000"  # version 1.0
        + "ffffffffffffffff"  # section length unknown
        + "04000200"
        + "746c0000"  # shb_userappl "tl", padded
        + "00000000"  # opt_endofopt
        + "28000000"
    )


def test_interface_and_packet_bytes() -> None:
    writer = PcapngWriter()
    interface, idb = writer.add_interface(Interface("a", LINKTYPE_SERIAL))
    assert interface == 0
    assert idb.hex() == (
        "01000000"
        + "20000000"  # 32
        + "9300"
        + "0000"
        + "00000000"  # LINKTYPE_USER0, reserved, snaplen 0
        + "02000100"
        + "61000000"  # if_name "a"
        + "00000000"
        + "20000000"
    )
    epb = writer.packet(0, b"abc", 1.5, Direction.OUTBOUND)
    assert epb.hex() == (
        "06000000"
        + "30000000"  # 48
        + "00000000"  # interface 0
        + "00000000"
        + "60e31600"  # 1 500 000 us, high then low word
        + "03000000"
        + "03000000"  # captured and original length
        + "61626300"  # data, padded to 4
        + "02000400"
        + "02000000"  # epb_flags: outbound
        + "00000000"
        + "30000000"
    )


@pytest.mark.parametrize("size", [0, 1, 2, 3, 4, 5, 216, 9024])
def test_round_trip_every_padding(size: int) -> None:
    writer = PcapngWriter("telelink test")
    blob = writer.header()
    _, idb = writer.add_interface(Interface("/dev/pts/5", LINKTYPE_SERIAL, "side a"))
    blob += idb
    _, idb = writer.add_interface(Interface("tcp 127.0.0.1:5", LINKTYPE_TCPSTREAM))
    blob += idb
    data = bytes(range(256)) * (size // 256) + bytes(range(size % 256))
    blob += writer.packet(0, data, EPOCH + 0.25, Direction.INBOUND)
    blob += writer.packet(1, data[::-1], EPOCH + 1.0)
    assert len(blob) % 4 == 0
    assert read_pcapng(blob) == Capture(
        "telelink test",
        (
            Interface("/dev/pts/5", LINKTYPE_SERIAL, "side a"),
            Interface("tcp 127.0.0.1:5", LINKTYPE_TCPSTREAM),
        ),
        (
            CapturedPacket(0, EPOCH + 0.25, data, Direction.INBOUND),
            CapturedPacket(1, EPOCH + 1.0, data[::-1], Direction.UNKNOWN),
        ),
    )


def test_reader_takes_big_endian_files_and_skips_unknown_blocks() -> None:
    def block(kind: int, body: bytes) -> bytes:
        return struct.pack(">II", kind, 12 + len(body)) + body + struct.pack(">I", 12 + len(body))

    blob = block(0x0A0D0D0A, struct.pack(">IHHq", 0x1A2B3C4D, 1, 0, -1))
    blob += block(1, struct.pack(">HHI", 148, 0, 0))
    blob += block(5, b"\0" * 8)  # an Interface Statistics Block: skipped
    blob += block(6, struct.pack(">IIIII", 0, 0, 2_000_000, 2, 2) + b"hi\0\0")
    assert read_pcapng(blob) == Capture("", (Interface("", 148),), (CapturedPacket(0, 2.0, b"hi"),))


def test_reader_names_the_offset_of_a_bad_block() -> None:
    writer = PcapngWriter()
    good = writer.header() + writer.add_interface(Interface("a"))[1]
    epb = writer.packet(0, b"abcd", 1.0)
    with pytest.raises(PcapngError, match="no Section Header Block"):
        read_pcapng(b"\0" * 40)
    with pytest.raises(PcapngError, match=f"offset {len(good)}: a truncated block header"):
        read_pcapng(good + epb[:8])
    with pytest.raises(PcapngError, match=f"offset {len(good)}: bad block length"):
        read_pcapng(good + epb[:-4])
    with pytest.raises(PcapngError, match=f"offset {len(good)}: the trailing block length"):
        read_pcapng(good + epb[:-4] + b"\xff\0\0\0")
    other = PcapngWriter()
    other.add_interface(Interface("a"))
    other.add_interface(Interface("b"))
    with pytest.raises(PcapngError, match="undescribed interface 1"):
        read_pcapng(good + other.packet(1, b"x", 1.0))


def test_writer_refuses_an_undescribed_interface_and_negative_time() -> None:
    writer = PcapngWriter()
    with pytest.raises(ValueError, match="interface 0 is not described"):
        writer.packet(0, b"x", 1.0)
    writer.add_interface(Interface("a"))
    with pytest.raises(ValueError, match="before 1970"):
        writer.packet(0, b"x", -1.0)


def test_capture_file_writes_as_it_goes_and_ignores_records_after_close(
    tmp_path: pathlib.Path,
) -> None:
    path = tmp_path / "c.pcapng"
    times = iter([EPOCH + 1, EPOCH + 2])
    cap = CaptureFile(path, clock=lambda: next(times))
    port = cap.add_interface("p")
    cap.record(port, b"one", Direction.OUTBOUND)
    cap.record(port, b"", Direction.INBOUND)  # nothing seen: no block
    # Flushed at once: readable while the file is still open.
    assert read_pcapng(path.read_bytes()).packets == (
        CapturedPacket(0, EPOCH + 1, b"one", Direction.OUTBOUND),
    )
    cap.record(port, b"two", Direction.INBOUND, timestamp=EPOCH + 5)
    cap.close()
    cap.record(port, b"late", Direction.INBOUND)
    cap.close()
    assert cap.records == 2
    assert [p.data for p in read_pcapng(path.read_bytes()).packets] == [b"one", b"two"]


def arq_capture(path: pathlib.Path) -> bytes:
    """A real serial-socket session over a 0.25 s line, captured at the connecting side.

    The client sends ``hello`` and more (control and 8-bit bytes, a run for the
    repeat prefix), the server answers the same upper-cased; both close.
    Virtual clock: the capture is the same on every run.  Returns the payload.
    """
    payload = b"hello \x01\x80 world" + b"~" * 8 + b"#&" + bytes(range(256))
    link = LinkConfig.symmetric(DirectionConfig(delay=0.25, rate=9600))
    cfg = endpoint_config_for(link)

    async def main() -> None:
        line = ImpairedLink(link)
        with CaptureFile(path, clock=lambda: EPOCH + trio.current_time()) as cap:
            client_line = CapturingStream(line.a, cap, cap.add_interface("client"))
            async with trio.open_nursery() as nursery:
                accepted: list[trio.abc.HalfCloseableStream] = []

                async def serve() -> None:
                    sock = await accept(line.b, cfg, nursery=nursery)
                    accepted.append(sock)
                    got = b""
                    while chunk := await sock.receive_some():
                        got += chunk
                    await sock.send_all(got.upper())
                    await sock.aclose()

                nursery.start_soon(serve)
                client = await connect(client_line, cfg, nursery=nursery)
                await client.send_all(payload)
                await client.send_eof()
                echoed = b""
                while chunk := await client.receive_some():
                    echoed += chunk
                await client.aclose()
                assert echoed == payload.upper()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    return payload


def _packets(packets: tuple[CapturedPacket, ...], direction: Direction) -> list[Packet]:
    """The Kermit packets carried one way (every one must check good), of any
    length the protocol allows: on a clean line the measured length grows
    past the parser's default."""
    parser = PacketParser(
        max_length=MAX_PACKET_LENGTH, check=BlockCheck.CRC16, init_check=BlockCheck.CRC16
    )
    parser.receive_data(b"".join(p.data for p in packets if p.direction == direction))
    found = []
    while (event := parser.next_event()) is not None:
        assert isinstance(event, PacketReceived), event
        found.append(event.packet)
    return found


def _payload(packets: tuple[CapturedPacket, ...], direction: Direction) -> bytes:
    """The data bytes carried one way, decoded from the captured Kermit packets.

    The encoding is the one the two captured inits negotiate; when both offer
    long sequence numbers, each data field starts with the two characters of
    the high bits: skipped.
    """
    inits = [
        InitParameters.decode(p.data)
        for way in (Direction.OUTBOUND, Direction.INBOUND)
        for p in _packets(packets, way)
        if p.seq == 0 and (p.type == "I" or (p.type == "Y" and len(p.data) >= 12))
    ]
    assert len(inits) == 2
    # The data encoding both inits agreed on (a dense one between two telelink
    # ends, serialsocket/PROTOCOL.md section 10).
    agreed = negotiate(*inits)
    head = 2 if agreed.long_seq else 0
    return b"".join(
        agreed.encoding.decode(p.data[head:]) for p in _packets(packets, direction) if p.type == "D"
    )


def test_capturing_stream_records_both_directions(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "arq.pcapng"
    payload = arq_capture(path)
    capture = read_pcapng(path.read_bytes())
    assert capture.interfaces == (Interface("client", LINKTYPE_SERIAL),)
    assert {p.direction for p in capture.packets} == {Direction.INBOUND, Direction.OUTBOUND}
    assert _payload(capture.packets, Direction.OUTBOUND) == payload
    assert _payload(capture.packets, Direction.INBOUND) == payload.upper()
    # The init leaves at t = 0.  The acceptor answers once the init's
    # characters (MARK..CHECK) have arrived, 0.25 s later, and its answer
    # comes back byte by byte: complete (CR included) at 0.5 s plus both
    # packets' character times at 9600 bit/s.
    first = capture.packets[0]
    assert (first.direction, first.data[3:4], first.timestamp) == (
        Direction.OUTBOUND,
        b"I",
        EPOCH,
    )
    init_chars = first.data.index(b"\r")
    received = b""
    for packet in capture.packets:
        if packet.direction == Direction.INBOUND:
            received += packet.data
            if b"\r" in received:
                break
    assert received[3:4] == b"Y"
    answer_chars = len(received)
    assert packet.timestamp - EPOCH == pytest.approx(
        0.5 + (init_chars + answer_chars) * 10 / 9600, abs=1e-5
    )
    stamps = [p.timestamp for p in capture.packets]
    assert stamps == sorted(stamps)
