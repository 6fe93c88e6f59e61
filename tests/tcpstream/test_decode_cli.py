"""``tcpstream decode``: captures to JSON, tags checked with the key (issue 24)."""

from __future__ import annotations

import json
import pathlib
import subprocess
import sys

import pytest

from tcpstream._cli import main

from .vectors import KEY, session_vectors


def _captures(tmp_path: pathlib.Path) -> tuple[pathlib.Path, pathlib.Path]:
    vectors, _ = session_vectors()
    to_arm = b"".join(v.raw for v in vectors if v.direction == "C -> A")
    to_ctl = b"".join(v.raw for v in vectors if v.direction == "A -> C" and v.name != "REFUSE")
    a, b = tmp_path / "to-arm.bin", tmp_path / "to-controller.bin"
    a.write_bytes(to_arm)
    b.write_bytes(to_ctl)
    return a, b


def _records(capsys: pytest.CaptureFixture[str]) -> tuple[list[dict[str, object]], str]:
    out, err = capsys.readouterr()
    return [json.loads(line) for line in out.splitlines()], err


def test_both_directions_with_the_key_verify_every_tag(
    tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]
) -> None:
    a, b = _captures(tmp_path)
    assert main(["decode", "--key", KEY.hex(), str(a), str(b)]) == 0
    records, _ = _records(capsys)
    assert [r["kind"] for r in records[:3]] == ["HELLO", "AUTH", "COMMAND"]
    assert records[0]["identity"] == "vector"
    assert records[0]["tag"] == "untagged"
    tagged = [r for r in records if r["tag"] == "ok"]
    assert len(tagged) == len(records) - 2  # all but HELLO and CHALLENGE
    assert {r["direction"] for r in tagged if r["file"] == str(a)} == {"C->A"}
    assert {r["direction"] for r in tagged if r["file"] == str(b)} == {"A->C"}
    command = records[2]
    assert command["code"] == "MOVE_JOINT"
    assert command["request_id"] == 1
    assert command["words"][:2] == [1.0, 0.5]  # type: ignore[index]
    failed = next(r for r in records if r["kind"] == "FAILED")
    assert (failed["status"], failed["text"]) == ("UNREACHABLE", "out of reach")
    grant = next(r for r in records if r["kind"] == "GRANT")
    assert (grant["instance"], grant["remembered"]) == (0x1122334455667788, False)


def test_a_tampered_packet_fails_its_tag_and_the_exit_status(
    tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]
) -> None:
    a, b = _captures(tmp_path)
    data = bytearray(a.read_bytes())
    data[2 * 216 + 60] ^= 0x01  # a word of the COMMAND
    a.write_bytes(bytes(data))
    assert main(["decode", "--key", KEY.hex(), str(a), str(b)]) == 1
    records, err = _records(capsys)
    assert next(r["tag"] for r in records if r["kind"] == "COMMAND") == "bad"
    assert "1 rejected or failed the tag check" in err


def test_garbage_is_skipped_and_decoding_resumes_without_a_key(
    tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]
) -> None:
    a, _ = _captures(tmp_path)
    noisy = tmp_path / "noisy.bin"
    noisy.write_bytes(b"junk!" + a.read_bytes() + b"TL")
    assert main(["decode", str(noisy)]) == 1
    records, _ = _records(capsys)
    assert records[0]["rejected"] == "BadMagic"
    assert records[0]["length"] == 5
    assert [r.get("kind") for r in records[1:4]] == ["HELLO", "AUTH", "COMMAND"]
    assert "tag" not in records[1]
    assert records[-1]["rejected"] == "PacketError"  # the 2 trailing bytes


def test_bad_inputs_exit_2_with_one_line(
    tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["decode", str(tmp_path / "missing.bin")]) == 2
    assert "No such file or directory" in capsys.readouterr().err
    assert main(["decode", "--key", "abcd", "-"]) == 2
    assert "at least 16 bytes" in capsys.readouterr().err


def test_runs_as_a_module_and_says_its_version() -> None:
    from tcpstream import __version__

    done = subprocess.run(
        [sys.executable, "-m", "tcpstream", "--version"], capture_output=True, timeout=60
    )
    assert done.stdout.decode().strip() == f"python -m tcpstream {__version__}"


def test_a_closed_pipe_on_stdout_ends_quietly(tmp_path: pathlib.Path) -> None:
    a, _ = _captures(tmp_path)
    big = tmp_path / "big.bin"
    big.write_bytes(a.read_bytes() * 300)
    proc = subprocess.Popen(
        [sys.executable, "-m", "tcpstream", "decode", str(big)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert proc.stdout is not None
    proc.stdout.close()
    assert proc.wait(timeout=60) == 141
    assert proc.stderr is not None
    assert b"Traceback" not in proc.stderr.read()
