"""The packet inspector, run as a user runs it."""

from __future__ import annotations

import json
import random
import subprocess
import sys

import pytest


def run(args: list[str], data: bytes) -> subprocess.CompletedProcess[bytes]:
    return subprocess.run(
        [sys.executable, "-m", "serialsocket", *args], input=data, capture_output=True, timeout=60
    )


@pytest.mark.parametrize("max_len", ["40", "128", "2048"])
@pytest.mark.parametrize("profile", ["printable", "8bit"])
def test_encode_decode_round_trip(max_len: str, profile: str) -> None:
    payload = random.Random(4).randbytes(3000) + b"\x00" * 300 + b"text\r\n" * 50
    wire = run(["encode", "--max-len", max_len, "--profile", profile], payload)
    assert wire.returncode == 0, wire.stderr
    if profile == "printable":
        assert set(wire.stdout) <= {1, 13} | set(range(32, 127))
    back = run(["decode", "--raw", "--profile", profile], wire.stdout)
    assert back.returncode == 0, back.stderr
    assert back.stdout == payload


def test_decode_json_records() -> None:
    wire = run(["encode", "--type", "D", "--seq", "1"], b"hi\x00").stdout
    noisy = b"junk" + wire + b"\x01%#Y/R8\r"
    out = run(["decode"], noisy)
    records = [json.loads(line) for line in out.stdout.splitlines()]
    assert records[0] == {"rejected": "garbage", "length": 4, "raw_hex": b"junk".hex()}
    assert records[1] == {
        "seq": 1,
        "type": "D",
        "check_ok": True,
        "extended": False,
        "length": len(wire) - 1,
        "data_hex": b"hi\x00".hex(),
    }
    assert records[2]["rejected"] == "bad check"
    assert records[2]["seq"] == 3


def test_encode_hex_and_seq_wraps() -> None:
    out = run(["encode", "--hex", "--seq", "63", "--max-len", "20"], b"abcdefghijklmnop")
    lines = out.stdout.decode().split()
    assert len(lines) == 2
    first, second = (bytes.fromhex(x) for x in lines)
    assert first[2] == 32 + 63
    assert second[2] == 32 + 0


def test_bad_arguments_give_clear_errors() -> None:
    out = run(["encode", "--max-len", "5"], b"x")
    assert out.returncode == 2
    assert b"argument --max-len: must be an integer in 12..9031, got '5'" in out.stderr
    out = run(["encode", "--check", "7"], b"x")
    assert out.returncode == 2
    assert b"block check must be 1, 2 or 3" in out.stderr
