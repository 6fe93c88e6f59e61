"""Write the committed seed inputs of the atheris harnesses (``python -m fuzz.make_seeds``).

Seeds are small, valid inputs that get each harness past its first gate at
once: real Kermit packets for the parser, real command packets for the
decoder, operation scripts that connect and exchange data for the ARQ and
session harnesses.  libFuzzer grows the corpus from them; only ``seed-*``
files are committed (.gitignore).
"""

from __future__ import annotations

from fuzz._atheris import CORPUS
from serialsocket.packets import (
    PRINTABLE,
    XON_XOFF,
    BlockCheck,
    EscapeEncoding,
    Packet,
    Radix91Encoding,
    build_packet,
)
from tcpstream import commands
from tcpstream.commands import Packet as CommandPacket
from tcpstream.commands import PacketKind, encode_packet, words_body


def _seeds() -> dict[str, dict[str, bytes]]:
    data = build_packet(Packet(seq=1, type="D", data=b"hello #M world"))
    ack = build_packet(Packet(seq=1, type="Y"), BlockCheck.SUM6)
    init = build_packet(Packet(seq=0, type="I", data=b'~* @-#Y3~^>J)0___F"U1@'), BlockCheck.SUM6)
    move = commands.move_joints((0.1, 0.2, 0.3, 0.0, 0.0, 0.0))
    command = encode_packet(
        CommandPacket(
            PacketKind.COMMAND, code=move.code, request_id=7, counter=3, body=words_body(move.args)
        )
    )
    hello = encode_packet(CommandPacket(PacketKind.HELLO, flags=1, counter=1))
    # Dense data fields (PROTOCOL.md section 10) in CRC-32 packets, and streams
    # that are runs of fields for decode_fields: fuzz_parser's third byte is
    # the check (mod 4; 3 = CRC-32) and the chunk length - 1 (>> 2).
    binary = bytes(range(256)) * 3
    radix = Radix91Encoding().encode(binary[:650])  # 50 blocks, 800 characters
    escaped = EscapeEncoding(unsafe=XON_XOFF).encode(binary)
    dense_packets = b"".join(
        build_packet(Packet(seq=i, type="D", data=field), BlockCheck.CRC32)
        for i, field in enumerate((radix[:93], escaped[:90], radix[96:160], escaped[300:390]))
    )
    # fuzz_arq_receive: per side window, max length (2 bytes), encoding; then operations.
    small = b"\x07\x00\x80\x00" * 2
    wide = b"\x1e\x05\x00\x01" * 2
    # Dense sides (flag 0x20; 0x40 XON/XOFF, 0x80 CRC-32, PROTOCOL.md 10), each
    # configuration: flags, [window unless long], length (2 bytes; >= 0xF000
    # measured), line (odd: 8-bit).  Then A sends bytes every encoding escapes,
    # the two exchange, B reads, and a D packet encoded as agreed is forged.
    escape_8bit = b"\x21\x02\x00\x01" * 2  # long sequence numbers, 552
    radix_crc32 = b"\xa0\x07\x00\x80\x00" * 2  # window 8, 168, printable
    xon_measured = b"\x61\xf0\x00\x01" * 2  # long, measured length, 8-bit
    awkward = bytes((1, 0x18, 0x11, 0x13, 0x91, 0x93, 0xFF, 0, 0x7E, 0x23, 0x26)) * 4
    dense_ops = (
        b"\x06" + bytes((len(awkward),)) + awkward + b"\x07\x03\x04\x07\x04\x00"
        b"\x01\x00\x02\x0b" + awkward[:11]
    )
    return {
        "fuzz_parser": {
            "seed-data": b"\x00\x80\x03" + data,
            "seed-mixed": b"\x00\x80\x07" + b"noise\r\n" + ack + data[:9] + data + init,
            "seed-sum6": b"\x01\x00\x00" + ack + init,
            "seed-dense-crc32": b"\x04\x00\xff" + dense_packets,
            "seed-radix91-fields": b"\x00\x80\x3f" + radix,
            "seed-escape-fields": b"\x00\x80\x93" + escaped,
            "seed-prefix-fields": b"\x00\x80\x9e" + PRINTABLE.encode(binary),
        },
        "fuzz_command_packet": {
            "seed-command": b"\x00" + command,
            "seed-hello": b"\x00" + hello,
            "seed-shaped": b"\x01" + command[3:],
        },
        "fuzz_arq_receive": {
            "seed-exchange": small + b"\x06\x20" + b"x" * 32 + b"\x07\x03\x04\x07\x04\x00",
            "seed-forged": wide + b"\x01\x00\x01\x05hello\x03\x08\x02\x03AB\x00\x04\x00",
            "seed-nak-flood": wide
            + b"\x06\x40"
            + b"y" * 64
            + b"\x07"
            + b"\x00\x02\x01\x00\x01" * 16,
            "seed-dense-escape": escape_8bit + dense_ops + b"\x00\x00\x01\x07\x04\x00",
            "seed-dense-radix91-crc32": radix_crc32 + dense_ops + b"\x01\x07\x04\x00",
            "seed-dense-xon-measured": xon_measured + dense_ops + b"\x00\x00\x01\x07\x04\x00",
        },
        "fuzz_session": {
            "seed-unkeyed-grant": b"\x01\x04\x04\x04\x04\x03\x20\x04",
            "seed-keyed-liar": b"\x00\x04\x04\x04\x04\x04",
            "seed-client": b"\x02\x00\x02" + b"\x00" * 40,
            "seed-raw-hello": b"\x01\x02\xd8" + hello,
        },
    }


def main() -> None:
    for harness, files in _seeds().items():
        folder = CORPUS / harness
        folder.mkdir(parents=True, exist_ok=True)
        for name, blob in files.items():
            (folder / name).write_bytes(blob)


if __name__ == "__main__":
    main()
