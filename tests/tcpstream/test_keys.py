"""Key files: made with owner-only permissions, read with comments, refused when short."""

from __future__ import annotations

import logging
import os
import pathlib
import stat

import pytest

from tcpstream import KEY_SIZE, generate_key, load_key_file, write_key_file


def test_a_written_key_file_is_private_and_reads_back(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "arm.key"
    key = write_key_file(path)
    assert len(key) == KEY_SIZE
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    assert load_key_file(path) == key
    with pytest.raises(FileExistsError):
        write_key_file(path)  # never overwrites


def test_hex_with_whitespace_and_comments(tmp_path: pathlib.Path) -> None:
    key = generate_key()
    path = tmp_path / "k"
    hex_digits = key.hex()
    path.write_text(f"# for the arm in bay 2\n{hex_digits[:20]}  {hex_digits[20:]}\n  # end\n")
    path.chmod(0o600)
    assert load_key_file(path) == key


def test_bad_and_short_keys_say_what_to_do(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "k"
    path.write_text("not hex at all")
    with pytest.raises(ValueError, match=r"hex digits .*linksim keygen"):
        load_key_file(path)
    path.write_text("00" * 15)
    with pytest.raises(ValueError, match="15 bytes; at least 16"):
        load_key_file(path)
    with pytest.raises(FileNotFoundError):
        load_key_file(tmp_path / "missing")


def test_a_world_readable_key_file_is_used_with_a_warning(
    tmp_path: pathlib.Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "k"
    path.write_text("ab" * 16)
    path.chmod(0o644)
    with caplog.at_level(logging.WARNING, logger="tcpstream._keys"):
        assert load_key_file(path) == bytes([0xAB]) * 16
    assert "chmod 600" in caplog.text
