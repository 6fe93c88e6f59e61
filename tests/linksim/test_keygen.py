"""``linksim keygen`` writes a key file the arm server and controller read with
``--key-file`` (issue 19: no more ``secrets.token_hex(32)`` by hand)."""

from __future__ import annotations

import os
import pathlib
import stat

import pytest

from linksim.cli import main
from linksim.cli._args import read_key
from tcpstream import load_key_file


def test_keygen_writes_a_private_key_file_that_loads(
    tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "arm.key"
    assert main(["keygen", str(path)]) == 0
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    key = load_key_file(path)
    assert len(key) == 32
    out, err = capsys.readouterr()
    assert out == ""  # nothing a script would capture by mistake
    assert f"--key-file {path}" in err


def test_keygen_never_overwrites(
    tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "arm.key"
    assert main(["keygen", str(path)]) == 0
    before = path.read_bytes()
    capsys.readouterr()
    assert main(["keygen", str(path)]) == 1
    assert path.read_bytes() == before
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "not overwriting" in err


def test_keygen_into_a_missing_directory_is_one_line(
    tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["keygen", str(tmp_path / "no" / "such" / "k")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "cannot write" in err


def test_the_command_line_reads_keys_as_the_library_does(tmp_path: pathlib.Path) -> None:
    """Comments and whitespace are allowed in a key file everywhere (the CLI had its own reader)."""
    path = tmp_path / "k"
    path.write_text("# the arm's key\n" + "ab" * 16 + "\n  " + "cd" * 16 + "\n")
    path.chmod(0o600)
    assert read_key(str(path)) == load_key_file(path) == bytes.fromhex("ab" * 16 + "cd" * 16)
