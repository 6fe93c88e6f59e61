"""The packet inspector, run as a user runs it."""

from __future__ import annotations

import json
import pathlib
import random
import subprocess
import sys

import pytest

from serialsocket import __version__


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


def test_decode_exit_status_says_whether_anything_was_rejected(tmp_path: pathlib.Path) -> None:
    wire = run(["encode"], b"clean").stdout
    clean = run(["decode"], wire)
    assert clean.returncode == 0, clean.stderr
    noisy = run(["decode"], b"junk" + wire)
    assert noisy.returncode == 1
    assert b"1 rejected" in noisy.stderr
    # A file instead of stdin, and "-" for stdin.
    path = tmp_path / "capture.bin"
    path.write_bytes(wire)
    from_file = run(["decode", "--raw", str(path)], b"")
    assert (from_file.returncode, from_file.stdout) == (0, b"clean")
    assert run(["decode", "--raw", "-"], wire).stdout == b"clean"
    missing = run(["decode", str(tmp_path / "nope")], b"")
    assert missing.returncode == 2
    assert b"No such file" in missing.stderr


def test_version_and_the_name_the_user_typed() -> None:
    assert __version__ not in ("", "0+unknown")
    as_module = run(["--version"], b"")
    assert as_module.stdout.decode().strip() == f"python -m serialsocket {__version__}"
    script = pathlib.Path(sys.executable).with_name("serialsocket")
    as_script = subprocess.run([str(script), "--version"], capture_output=True, timeout=60)
    assert as_script.stdout.decode().strip() == f"serialsocket {__version__}"


def test_an_unknown_option_shows_the_subcommands_usage() -> None:
    done = run(["decode", "--bogus"], b"")
    assert done.returncode == 2
    err = done.stderr.decode()
    assert err.startswith("usage: python -m serialsocket decode ")
    assert "error: unrecognized arguments: --bogus" in err


def test_a_closed_pipe_on_stdout_ends_quietly() -> None:
    """``serialsocket decode | head -1``: no BrokenPipeError traceback."""
    payload = random.Random(9).randbytes(200_000)
    wire = run(["encode"], payload).stdout
    proc = subprocess.Popen(
        [sys.executable, "-m", "serialsocket", "decode"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert proc.stdout is not None
    assert proc.stdin is not None
    proc.stdout.close()  # the reader is gone before anything is written
    proc.stdin.write(wire)
    proc.stdin.close()
    assert proc.wait(timeout=60) == 141
    assert proc.stderr is not None
    assert b"Traceback" not in proc.stderr.read()
