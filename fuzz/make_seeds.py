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
