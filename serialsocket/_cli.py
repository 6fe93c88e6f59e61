"""Command line: ``serialsocket encode|decode|listen|connect|kermit`` (``python -m serialsocket``).

``encode`` reads payload bytes on stdin and writes wire packets on stdout;
``decode`` reads wire bytes on stdin and prints one JSON object per packet or
per rejected chunk.  ``encode | decode --raw`` reproduces the input exactly.
``listen PORT`` and ``connect PORT`` are a netcat over the serial socket
(see :mod:`serialsocket._netcat`).  ``kermit send|receive`` is Kermit file
transfer (see :mod:`serialsocket._kermit_cli`).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence

from . import __version__
from ._checks import BlockCheck
from ._encoding import EIGHT_BIT_CLEAN, PRINTABLE, Encoding
from ._errors import LocalProtocolError, MalformedDataError
from ._kermit_cli import add_arguments as add_kermit_arguments
from ._kermit_cli import kermit_main
from ._netcat import add_arguments as add_netcat_arguments
from ._netcat import netcat_main
from ._packet import Packet, build_packet, data_capacity
from ._parser import PacketParser, PacketReceived
from ._wire import DEFAULT_MAX_PACKET_LENGTH, MAX_PACKET_LENGTH, SEQ_MODULUS
from .argtypes import (
    BAUD,
    DELAY,
    ENDPOINT_LENGTH,
    PACKET_LENGTH,
    SECONDS,
    SEQ,
    SERIAL_PORT,
    WINDOW,
    PacketTypeLetter,
    retype,
)

__all__ = ["main"]

_PROFILES: dict[str, Encoding] = {"printable": PRINTABLE, "8bit": EIGHT_BIT_CLEAN}
_READ_LIMIT = 64 * 1024 * 1024
"""The inspector holds its input in memory; refuse more than this rather than swap."""


def _check(value: str) -> BlockCheck:
    try:
        return BlockCheck(int(value))
    except ValueError:
        raise argparse.ArgumentTypeError("block check must be 1, 2 or 3") from None


_NETCAT_TYPES: dict[str, object] = {
    "port": SERIAL_PORT,
    "baud": BAUD,
    "window": WINDOW,
    "max_len": ENDPOINT_LENGTH,
    "delay": DELAY,
    "dead_after": SECONDS,
    "max_packet_time": SECONDS,
}
"""Ranges of the netcat options (_netcat.add_arguments declares them with bare int/float)."""


def _prog() -> str:
    """How the user ran us: ``serialsocket`` (the script) or ``python -m serialsocket``."""
    name = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else ""
    return "python -m serialsocket" if name in ("", "__main__.py", "-c") else name


def _parser() -> argparse.ArgumentParser:
    """The whole command line (the bad-input matrix test walks it)."""
    return _build()[0]


def _build() -> tuple[argparse.ArgumentParser, dict[str, argparse.ArgumentParser]]:
    """The top-level parser and each subcommand's (for errors in the right usage)."""
    ap = argparse.ArgumentParser(
        prog=_prog(),
        description="Serial sockets: a netcat over a serial line (listen, connect), the "
        "Kermit packet inspector (encode, decode) and Kermit file transfer (kermit).",
    )
    ap.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)

    enc = sub.add_parser("encode", help="stdin payload -> wire packets on stdout")
    enc.add_argument(
        "--type", type=PacketTypeLetter(), default="D", help="packet type letter (default D)"
    )
    enc.add_argument("--seq", type=SEQ, default=0, help="first sequence number, 0..63")
    enc.add_argument("--check", type=_check, default=BlockCheck.CRC16, help="block check 1/2/3")
    enc.add_argument(
        "--max-len",
        type=PACKET_LENGTH,
        default=DEFAULT_MAX_PACKET_LENGTH,
        help=f"maximum packet length, MARK through CHECK (default {DEFAULT_MAX_PACKET_LENGTH})",
    )
    enc.add_argument("--profile", choices=sorted(_PROFILES), default="printable")
    enc.add_argument("--hex", action="store_true", help="print hex, one packet per line")

    dec = sub.add_parser("decode", help="wire bytes on stdin -> one JSON object per packet")
    dec.add_argument("--check", type=_check, default=BlockCheck.CRC16, help="block check 1/2/3")
    dec.add_argument(
        "--init-check",
        type=_check,
        default=BlockCheck.SUM6,
        help="block check of S/I packets (1, or 3 for FORCE-3)",
    )
    dec.add_argument(
        "--max-len",
        type=PACKET_LENGTH,
        default=MAX_PACKET_LENGTH,
        help=f"longest packet accepted (default {MAX_PACKET_LENGTH})",
    )
    dec.add_argument("--profile", choices=sorted(_PROFILES), default="printable")
    dec.add_argument("--hex", action="store_true", help="stdin is hex text, not raw bytes")
    dec.add_argument(
        "--raw", action="store_true", help="write the decoded payloads to stdout instead of JSON"
    )
    dec.add_argument(
        "file",
        nargs="?",
        default="-",
        help="the wire bytes to read (default: - for stdin); exit 1 if anything was rejected",
    )

    lis = sub.add_parser(
        "listen", help="wait for one connection on PORT; stdin to the link, the link to stdout"
    )
    add_netcat_arguments(lis, listening=True)
    retype(lis, _NETCAT_TYPES)
    _same_spellings(lis)
    con = sub.add_parser("connect", help="connect over PORT; stdin to the link, the link to stdout")
    add_netcat_arguments(con, listening=False)
    retype(con, _NETCAT_TYPES | {"connect_timeout": SECONDS})
    _same_spellings(con)
    ker = sub.add_parser(
        "kermit",
        help="Kermit file transfer with C-Kermit, G-Kermit or ours "
        "(send, receive, server, get, remote)",
    )
    add_kermit_arguments(ker)
    return ap, {"encode": enc, "decode": dec, "listen": lis, "connect": con, "kermit": ker}


def _same_spellings(ap: argparse.ArgumentParser) -> None:
    """listen/connect also take kermit's spellings: ``--port PORT`` (PORT may stay
    positional) and ``--packet-length`` for ``--max-len``."""
    for action in ap._actions:
        if action.dest == "port" and not action.option_strings:
            action.nargs = "?"
            action.default = None
    ap.add_argument(
        "--packet-length",
        dest="max_len",
        type=ENDPOINT_LENGTH,
        default=None,
        metavar="MAX_LEN",
        help="the same as --max-len (as serialsocket kermit spells it)",
    )
    ap.add_argument(
        "--port",
        dest="port_option",
        type=SERIAL_PORT,
        metavar="PORT",
        help="the same as PORT (as serialsocket kermit spells it)",
    )


def _parse(argv: Sequence[str] | None) -> argparse.Namespace:
    """Parse; an unknown option is reported with its subcommand's usage, not the top one's."""
    ap, subs = _build()
    args, extra = ap.parse_known_args(argv)
    if extra:
        subs[args.command].error(f"unrecognized arguments: {' '.join(extra)}")
    if args.command in ("listen", "connect"):
        if args.port is not None and args.port_option is not None:
            subs[args.command].error("PORT given twice (as PORT and as --port)")
        args.port = args.port if args.port is not None else args.port_option
        if args.port is None:
            subs[args.command].error("the following arguments are required: PORT")
    return args


def _read_stdin(path: str = "-") -> bytes:
    if path == "-":
        data = sys.stdin.buffer.read(_READ_LIMIT + 1)
    else:
        with open(path, "rb") as f:
            data = f.read(_READ_LIMIT + 1)
    if len(data) > _READ_LIMIT:
        raise LocalProtocolError(f"input larger than {_READ_LIMIT} bytes: split it")
    return data


def _encode(args: argparse.Namespace) -> int:
    payload = _read_stdin()
    encoding = _PROFILES[args.profile]
    capacity = data_capacity(args.max_len, args.check)
    seq = args.seq
    out = sys.stdout.buffer
    view = memoryview(payload)
    while True:
        field, used = encoding.encode_prefix(view, capacity)
        wire = build_packet(Packet(seq=seq, type=args.type, data=field), args.check)
        out.write(wire.hex().encode() + b"\n" if args.hex else wire)
        view = view[used:]
        seq = (seq + 1) % SEQ_MODULUS
        if not view:
            break
    out.flush()
    return 0


def _decode(args: argparse.Namespace) -> int:
    """Exit 0 if every byte was part of a good packet, 1 if anything was rejected."""
    data = _read_stdin(args.file)
    if args.hex:
        try:
            data = bytes.fromhex(data.decode("ascii", "replace").replace("\n", " "))
        except ValueError as exc:
            print(f"serialsocket decode: --hex input is not hex digits: {exc}", file=sys.stderr)
            return 2
    parser = PacketParser(max_length=args.max_len, check=args.check, init_check=args.init_check)
    parser.receive_data(data)
    encoding = _PROFILES[args.profile]
    out = sys.stdout
    bad = 0
    while (event := parser.next_event()) is not None:
        if isinstance(event, PacketReceived):
            pkt = event.packet
            record: dict[str, object] = {
                "seq": pkt.seq,
                "type": str(pkt.type),
                "check_ok": True,
                "extended": event.extended,
                "length": event.length,
            }
            try:
                payload = encoding.decode(pkt.data)
            except MalformedDataError as exc:
                record["decode_error"] = str(exc)
                record["field_hex"] = pkt.data.hex()
                bad += 1
                payload = b""
            else:
                record["data_hex"] = payload.hex()
            if args.raw:
                sys.stdout.buffer.write(payload)
                continue
        else:
            bad += 1
            record = {"rejected": event.reason.value, "length": event.length}
            if event.seq is not None:
                record["seq"] = event.seq
            if event.type is not None:
                record["type"] = event.type
            record["raw_hex"] = event.raw.hex()
            if args.raw:
                continue
        out.write(json.dumps(record) + "\n")
    if parser.buffered:
        leftover = {"rejected": "incomplete", "length": parser.buffered}
        if not args.raw:
            out.write(json.dumps(leftover) + "\n")
        bad += 1
    out.flush()
    if bad:
        print(f"serialsocket decode: {bad} rejected (see the JSON records)", file=sys.stderr)
    return 1 if bad else 0


def main(argv: Sequence[str] | None = None) -> int:
    """Run a command; returns the process exit status."""
    try:
        return _main(argv)
    except BrokenPipeError:
        # Whoever read our stdout went away (``| head``): stop quietly, as cat
        # does, with the status a shell gives for SIGPIPE.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return 141


def _main(argv: Sequence[str] | None) -> int:
    args = _parse(argv)
    try:
        return _dispatch(args)
    except KeyboardInterrupt:
        # Ctrl-C: the run unwound through its cleanup (the link's and the
        # files' ``finally`` blocks); one line, and the status a shell gives.
        print(f"serialsocket {args.command}: interrupted", file=sys.stderr)
        return 130


def _dispatch(args: argparse.Namespace) -> int:
    try:
        if args.command in ("listen", "connect"):
            return netcat_main(args, listening=args.command == "listen")
        if args.command == "kermit":
            return kermit_main(args)
    except ValueError as exc:
        # A setting the options let through but the port refused when it was
        # opened (pyserial: a URL's options, a baud the driver cannot set).
        print(f"serialsocket {args.command}: {exc}: check --port and --baud", file=sys.stderr)
        return 2
    try:
        if args.command == "encode":
            return _encode(args)
        return _decode(args)
    except LocalProtocolError as exc:
        print(f"serialsocket: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        raise
    except OSError as exc:
        print(f"serialsocket {args.command}: {exc.strerror or exc}: {args.file}", file=sys.stderr)
        return 2
