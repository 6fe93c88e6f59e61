"""Command line: ``tcpstream decode`` -- 216-byte packets to JSON, tags verified with a key.

``tcpstream decode [FILE ...]`` reads one or more byte streams of packets (a
capture of each direction, or both directions concatenated; ``-`` is stdin)
and prints one JSON object per packet, or per chunk it had to skip.  With
``--key-file`` (or ``--key HEX``) it derives the session key from the HELLO
and CHALLENGE it finds in the input (PROTOCOL.md section 8) and checks every
tag; the direction byte that makes a tag verify says who sent the packet.
Exit status 0: every byte was part of a good packet (and, with a key, every
tag verified); 1 otherwise; 2 for bad arguments or unreadable input.
"""

from __future__ import annotations

import argparse
import json
import os
import struct
import sys
from collections.abc import Iterator, Sequence
from typing import Any

from . import __version__, _auth
from ._commands import CommandCode, FailureReason
from ._events import CloseReason, RefuseReason
from ._keys import load_key_file
from ._packet import (
    MAGIC,
    NUMERIC_KINDS,
    PACKET_SIZE,
    SIGNED_SIZE,
    BadMagic,
    Packet,
    PacketError,
    PacketKind,
    decode_packet,
    unpack_text,
)

__all__ = ["main"]

_READ_LIMIT = 64 * 1024 * 1024
"""Inputs are held in memory; refuse more than this rather than swap."""

_HELLO = struct.Struct("!32sQ16s")
_TEXT_KINDS = (PacketKind.FAILED, PacketKind.REFUSE, PacketKind.BYE)
_STATUS_ENUMS: dict[PacketKind, type[FailureReason | RefuseReason | CloseReason]] = {
    PacketKind.FAILED: FailureReason,
    PacketKind.REFUSE: RefuseReason,
    PacketKind.BYE: CloseReason,
}


def _prog() -> str:
    name = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else ""
    return "python -m tcpstream" if name in ("", "__main__.py", "-c") else name


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog=_prog(), description="tcpstream tools: decode captured command packets."
    )
    ap.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    dec = sub.add_parser("decode", help="216-byte packets to JSON (tags checked with --key)")
    dec.add_argument("files", nargs="*", default=["-"], help="captures to read (default: stdin)")
    keys = dec.add_mutually_exclusive_group()
    keys.add_argument("--key-file", help="the pre-shared key file (hex), to verify tags")
    keys.add_argument("--key", help="the pre-shared key as hex digits, to verify tags")
    dec.add_argument("--hex", action="store_true", help="the inputs are hex text, not raw bytes")
    dec.set_defaults(usage_parser=dec)
    return ap


def _split(data: bytes) -> Iterator[tuple[bytes, Packet | PacketError]]:
    """Packets at 216-byte boundaries; after a bad magic, resynchronise on the next "TL"."""
    pos = 0
    while len(data) - pos >= PACKET_SIZE:
        raw = data[pos : pos + PACKET_SIZE]
        try:
            yield raw, decode_packet(raw)
        except BadMagic as exc:
            at = data.find(MAGIC, pos + 1)
            skip_to = at if at >= 0 else len(data)
            yield data[pos:skip_to], exc
            pos = skip_to
            continue
        except PacketError as exc:
            yield raw, exc
        pos += PACKET_SIZE
    if pos < len(data):
        yield data[pos:], PacketError(f"{len(data) - pos} trailing bytes: an incomplete packet")


def _session_key(key: bytes, packets: list[Packet]) -> bytes | None:
    hello = next((p for p in packets if p.kind is PacketKind.HELLO), None)
    challenge = next((p for p in packets if p.kind is PacketKind.CHALLENGE), None)
    if hello is None or challenge is None:
        return None
    identity, incarnation, client_nonce = _HELLO.unpack_from(hello.body)
    server_nonce = challenge.body[: _auth.NONCE_SIZE]
    return _auth.derive_session_key(key, client_nonce, server_nonce, identity, incarnation)


def _record(packet: Packet) -> dict[str, Any]:
    kind = packet.kind
    rec: dict[str, Any] = {"kind": kind.name, "counter": packet.counter}
    if packet.request_id:
        rec["request_id"] = packet.request_id
    if packet.code:
        codes = {c.value for c in CommandCode}
        rec["code"] = CommandCode(packet.code).name if packet.code in codes else packet.code
    if packet.flags:
        rec["flags"] = packet.flags
    if packet.status:
        enum = _STATUS_ENUMS.get(kind)
        try:
            rec["status"] = enum(packet.status).name if enum is not None else packet.status
        except ValueError:
            rec["status"] = packet.status
    if any(packet.aux):
        rec["aux"] = list(packet.aux)
    if kind in NUMERIC_KINDS:
        rec["words"] = list(packet.words())
    elif kind in _TEXT_KINDS:
        rec["text"] = unpack_text(packet.body)
    elif kind is PacketKind.HELLO:
        identity, incarnation, nonce = _HELLO.unpack_from(packet.body)
        rec["identity"] = identity.rstrip(b"\0").decode("utf-8", "replace")
        rec["incarnation"] = incarnation
        rec["client_nonce"] = nonce.hex()
    elif kind is PacketKind.CHALLENGE:
        rec["server_nonce"] = packet.body[: _auth.NONCE_SIZE].hex()
    elif kind is PacketKind.GRANT:
        rec["instance"] = struct.unpack_from("!Q", packet.body, _auth.PROOF_SIZE)[0]
        rec["remembered"] = packet.body[_auth.PROOF_SIZE + 8] == 1
    return rec


def _tag(session_key: bytes, packet: Packet, raw: bytes) -> tuple[str, str | None]:
    """("ok" | "bad" | "untagged", the direction the tag proves)."""
    if packet.kind in (PacketKind.HELLO, PacketKind.CHALLENGE, PacketKind.REFUSE):
        return ("untagged", None) if not any(packet.tag) else ("bad", None)
    for direction, name in ((_auth.TO_SERVER, "C->A"), (_auth.TO_CLIENT, "A->C")):
        expected = _auth.packet_tag(session_key, direction, raw[:SIGNED_SIZE])
        if _auth.verify(expected, packet.tag):
            return "ok", name
    return "bad", None


def _read(path: str, as_hex: bool) -> bytes:
    if path == "-":
        data = sys.stdin.buffer.read(_READ_LIMIT + 1)
    else:
        with open(path, "rb") as f:
            data = f.read(_READ_LIMIT + 1)
    if len(data) > _READ_LIMIT:
        raise ValueError(f"{path}: larger than {_READ_LIMIT} bytes; split it")
    if as_hex:
        try:
            data = bytes.fromhex(data.decode("ascii", "replace").replace("\n", " "))
        except ValueError as exc:
            raise ValueError(f"{path}: --hex input is not hex digits: {exc}") from None
    return data


def _decode(args: argparse.Namespace) -> int:
    key: bytes | None = None
    if args.key_file:
        key = load_key_file(args.key_file)
    elif args.key:
        key = bytes.fromhex(args.key)
        if len(key) < _auth.MIN_KEY_SIZE:
            raise ValueError(f"--key: at least {_auth.MIN_KEY_SIZE} bytes are needed")
    inputs = [(path, list(_split(_read(path, args.hex)))) for path in args.files]
    good = [p for _, items in inputs for _, p in items if isinstance(p, Packet)]
    session_key = _session_key(key, good) if key is not None else None
    if key is not None and session_key is None:
        print(
            "tcpstream decode: no HELLO and CHALLENGE in the input, so no session key: "
            "tags not checked (give both directions of the session)",
            file=sys.stderr,
        )
    bad = 0
    for path, items in inputs:
        for index, (raw, item) in enumerate(items):
            rec: dict[str, Any] = {"file": path, "index": index}
            if isinstance(item, PacketError):
                bad += 1
                rec |= {"rejected": type(item).__name__, "message": item.message}
                rec["length"] = len(raw)
            else:
                rec |= _record(item)
                if session_key is not None:
                    rec["tag"], direction = _tag(session_key, item, raw)
                    bad += rec["tag"] == "bad"
                    if direction is not None:
                        rec["direction"] = direction
            print(json.dumps(rec))
    if bad:
        print(f"tcpstream decode: {bad} rejected or failed the tag check", file=sys.stderr)
    return 1 if bad else 0


def main(argv: Sequence[str] | None = None) -> int:
    """``tcpstream decode ...``; returns the exit status."""
    ap = _parser()
    args, extra = ap.parse_known_args(argv)
    if extra:  # reported with the subcommand's usage, not the top level's
        args.usage_parser.error(f"unrecognized arguments: {' '.join(extra)}")
    try:
        return _decode(args)
    except BrokenPipeError:
        # Whoever read our stdout went away (``| head``): stop quietly, as cat
        # does, with the status a shell gives for SIGPIPE.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return 141
    except (OSError, ValueError) as exc:
        if isinstance(exc, OSError) and exc.strerror:
            text = f"{exc.strerror}: {exc.filename}"
        else:
            text = str(exc)
        print(f"tcpstream decode: {text}", file=sys.stderr)
        return 2
