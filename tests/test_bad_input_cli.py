"""The bad-input matrix (issue 11), command lines and config files.

Every bad option or file must end in a one-line message naming the problem and
a non-zero exit status (2: the user's input is wrong; 1: the environment
failed, such as a missing port) -- never a traceback.  The commands run
in-process through their ``main(argv)``; those that would open a port or a pty
fail during option checking, before any I/O.
"""

from __future__ import annotations

import io
import pathlib
import sys

import pytest

from linksim import LinkConfig
from linksim import _cli as linksim_cli
from linksim._config import ConfigError
from serialsocket import _cli as serial_cli


def _run(main: object, argv: list[str], stdin: bytes, monkeypatch: pytest.MonkeyPatch) -> int:
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(stdin)))
    try:
        return main(argv)  # type: ignore[operator,no-any-return]
    except SystemExit as exc:  # argparse's own usage errors
        return int(exc.code or 0)


SERIAL_CASES = [
    # (argv, stdin, exit status, words the message must contain)
    (["encode", "--max-len", "5"], b"abc", 2, "argument --max-len: must be an integer in 12..9031"),
    (["encode", "--seq", "99"], b"abc", 2, "argument --seq: must be an integer in 0..63"),
    (["encode", "--type", ""], b"abc", 2, "argument --type: must be one printable character"),
    (["encode", "--max-len", "x"], b"abc", 2, "argument --max-len: must be an integer"),
    (
        ["connect", "--window", "0", "/dev/null"],
        b"",
        2,
        "argument --window: must be an integer in 1..31, got '0'",
    ),
    (["connect", "--window", "99", "/dev/null"], b"", 2, "got '99'"),
    (
        ["connect", "--delay", "nan", "/dev/null"],
        b"",
        2,
        "argument --delay: must be a number of seconds in [0, 3600], got 'nan'",
    ),
    (["connect", "--delay", "-1", "/dev/null"], b"", 2, "argument --delay:"),
    (
        ["connect", "--baud", "0", "/dev/null"],
        b"",
        2,
        "argument --baud: must be an integer in 1..100000000",
    ),
    (["connect", "--baud", "nan", "/dev/null"], b"", 2, "argument --baud:"),
    (
        ["connect", "--dead-after", "-1", "/dev/null"],
        b"",
        2,
        "argument --dead-after: must be a number of seconds in (0, 2592000]",
    ),
    (["connect", "--connect-timeout", "0", "/dev/null"], b"", 2, "argument --connect-timeout:"),
    (
        ["connect", "--max-len", "100000", "/dev/null"],
        b"",
        2,
        "argument --max-len: must be an integer in 33..9031",
    ),
    (["connect", "bogus://x"], b"", 2, "argument PORT: unknown URL scheme 'bogus'"),
    (["connect", "/nonexistent/port"], b"", 1, "/nonexistent/port"),
    (["listen", "--bogus-option", "/dev/null"], b"", 2, "unrecognized arguments"),
    (["nosuchcommand"], b"", 2, "invalid choice"),
]


@pytest.mark.parametrize(("argv", "stdin", "status", "words"), SERIAL_CASES)
def test_serialsocket_cli_rejects_bad_options(
    argv: list[str],
    stdin: bytes,
    status: int,
    words: str,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert _run(serial_cli.main, argv, stdin, monkeypatch) == status
    err = capsys.readouterr().err
    assert words in err
    assert "Traceback" not in err


def test_serialsocket_decode_hex_rejects_non_hex_input(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _run(serial_cli.main, ["decode", "--hex"], b"zz not hex\n", monkeypatch) == 2
    assert "hex" in capsys.readouterr().err


def test_serialsocket_decode_reports_garbage_as_records_not_errors(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    status = _run(serial_cli.main, ["decode"], b"\x01garbage\x01#\x00" * 100, monkeypatch)
    out = capsys.readouterr().out.splitlines()
    assert status == 0
    assert len(out) == 200  # one record per damaged packet (two MARKs per copy)
    assert all('"rejected"' in line for line in out)


def test_serialsocket_decode_refuses_oversized_input(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    limit = serial_cli._READ_LIMIT
    assert _run(serial_cli.main, ["decode"], b"x" * (limit + 1), monkeypatch) == 2
    assert f"larger than {limit}" in capsys.readouterr().err


def _bad_toml(tmp: pathlib.Path) -> pathlib.Path:
    path = tmp / "bad.toml"
    path.write_text("nope = [")
    return path


LINKSIM_CASES = [
    (["--rate", "nan"], "argument --rate: must be a number of bit/s in (0, 1000000000], got 'nan'"),
    (["--rate", "-9600"], "argument --rate:"),
    (["--delay", "-1"], "argument --delay: must be a number of seconds in [0, 3600]"),
    (["--delay", "inf"], "argument --delay:"),
    (["--loss", "2"], "argument --loss: must be a number in [0, 1], got '2'"),
    (["--noise", "-0.1"], "argument --noise:"),
    (["--bits", "0"], "argument --bits: must be an integer in 1..64"),
    (["--burst", "x:y"], "--burst wants"),
    (["--preset", "nope"], "invalid choice"),
    (["--preset", "moon", "--config", "{bad}"], "not both"),
    (["--config", "{bad}"], "invalid TOML"),
    (["--config", "{missing}"], "missing.toml"),
    (["--config", "{dir}"], "cannot read"),
]


@pytest.mark.parametrize(("options", "words"), LINKSIM_CASES)
def test_linksim_relay_rejects_bad_options_before_opening_anything(
    options: list[str],
    words: str,
    tmp_path: pathlib.Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    names = {"bad": str(_bad_toml(tmp_path)), "missing": str(tmp_path / "missing.toml")}
    names["dir"] = str(tmp_path)
    argv = ["relay", *(o.format(**names) for o in options), "--duration", "0.1"]
    assert _run(linksim_cli.main, argv, b"", monkeypatch) == 2
    err = capsys.readouterr().err
    assert words in err
    assert "Traceback" not in err


CONFIG_TEXTS = [
    ("nope = [", "invalid TOML"),
    ("colour = 1", "unknown top-level key"),
    ("[both]\nspeed = 3", "unknown key(s) in [both]: speed"),
    ('[both]\nrate = "fast"', "rate must be a finite number"),
    ("[both]\nrate = inf", "rate must be a finite number"),
    ("[both]\ndelay = nan", "delay must be a finite number"),
    ("[both]\ndelay = -1.0", "delay must be a finite number"),
    ("[both]\ndelay = true", "delay must be a finite number"),
    ("[both]\nloss = 2.0", "loss must be a probability"),
    ("[both]\nloss = true", "loss must be a probability"),
    ("[both]\nbits_per_char = 0", "bits_per_char must be an integer"),
    ("[both]\nbits_per_char = true", "bits_per_char must be an integer"),
    ("[both]\noutages = [[5.0, 1.0]]", "outage.end must be > outage.start"),
    ('[both]\noutages = "x"', "list of [start, end] pairs"),
    ("[both]\noutages = [[1.0]]", "list of [start, end] pairs"),
    ('preset = "nope"', "preset must be one of"),
    ('seed = "x"', "seed must be an integer"),
    ("seed = 1.5", "seed must be an integer"),
    ("seed = true", "seed must be an integer"),
    ("both = 3", "[both] must be a table"),
    ("[both.burst]\nzz = 2.0", "[both.burst] takes only"),
    ('[[both.faults]]\naction = "explode"', "action must be drop, corrupt or insert"),
    ('[[both.faults]]\naction = "drop"', "fault needs exactly one target"),
]


@pytest.mark.parametrize(("text", "words"), CONFIG_TEXTS)
def test_link_config_files_reject_nonsense_with_a_config_error(text: str, words: str) -> None:
    with pytest.raises(ConfigError) as info:
        LinkConfig.from_toml(text)
    assert words in str(info.value)


def test_unreadable_config_files_are_config_errors(tmp_path: pathlib.Path) -> None:
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\xff\xfe[both]\n")
    for path in (tmp_path / "missing.toml", tmp_path, binary):
        with pytest.raises(ConfigError, match="cannot read"):
            LinkConfig.from_toml(path)
