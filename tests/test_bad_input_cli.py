"""The bad-input matrix (issue 11), command lines and config files.

Every bad option or file must end in a one-line message naming the problem and
a non-zero exit status (2: the user's input is wrong; 1: the environment
failed, such as a missing port) -- never a traceback.  The commands run
in-process through their ``main(argv)``; those that would open a port or a pty
fail during option checking, before any I/O.
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import pathlib
import subprocess
import sys
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from linksim import ConfigError, DirectionConfig, LinkConfig
from linksim.cli import _args as link_args
from linksim.cli import _bench as bench_cli
from linksim.cli import _link as link_options
from linksim.cli import _main as linksim_cli
from linksim.cli import _proxy as proxy_cli
from serialsocket import EndpointConfig
from serialsocket import _cli as serial_cli
from serialsocket import argtypes as serial_args
from serialsocket.kermit import KermitConfig
from tcpstream import _cli as tcp_cli

ROOT = pathlib.Path(__file__).resolve().parents[1]


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
        "argument --max-len: must be an integer in 38..9031",
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
    captured = capsys.readouterr()
    out = captured.out.splitlines()
    assert status == 1  # records, not a traceback; but not "everything decoded" either
    assert len(out) == 200  # one record per damaged packet (two MARKs per copy)
    assert all('"rejected"' in line for line in out)
    assert "200 rejected" in captured.err


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
    (["--burst", "x:y"], "burst wants"),
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
    ("[both]\nspeed = 3", "unknown key 'speed' in [both]"),
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


# -- the option matrix: every option of every command, generated from the parsers ------------
#
# The cases are not written by hand: the parsers are walked (subcommands and
# all) and each option's ``type=`` says which values lie outside it.  An option
# whose type the generator does not know fails test_every_option_is_classified
# until it gets a range-checked converter (linksim/cli/_args.py,
# serialsocket/argtypes.py) or a line in FREE_TEXT saying where it is checked.

Main = Callable[[list[str]], int]

COMMANDS: list[tuple[str, Callable[[], argparse.ArgumentParser], Main]] = [
    ("linksim", linksim_cli.build_parser, linksim_cli.main),
    ("serialsocket", serial_cli._parser, serial_cli.main),
    ("tcpstream", tcp_cli._parser, tcp_cli.main),
]

PARSER_MODULES = {
    # Modules that build an ArgumentParser, and the command above that reaches
    # their options; a new command line must be added to COMMANDS.
    # (linksim's subcommands, the soak and the benchmarks among them, add their
    # options in other linksim/cli/ modules; only _main.py builds the parser.)
    "linksim/cli/_main.py": "linksim",
    "serialsocket/_cli.py": "serialsocket",
    "tcpstream/_cli.py": "tcpstream",
}

FLAGS = (
    argparse._HelpAction,
    argparse._StoreTrueAction,
    argparse._StoreFalseAction,
    argparse._StoreConstAction,
    argparse._AppendConstAction,
    argparse._CountAction,
    argparse._VersionAction,
)

FREE_TEXT = {
    # dest: where a bad value is caught (the runtime cases below try several)
    "config": "LinkConfig.from_toml: exit 2 (LINKSIM_CASES)",
    "world": "WorldConfig.from_toml before anything runs: exit 2",
    "key_file": "read before anything runs: exit 2",
    "host": "a name or address: resolved when connecting, exit 1",
    "dial": "a phone number: the modem answers BUSY/NO CARRIER, exit 1",
    "busy": "a phone number the emulated modem answers BUSY",
    "no_answer": "a phone number the emulated modem never answers",
    "files": "kermit send: each opened before the transfer, exit 2",
    "file": "serialsocket decode FILE (- for stdin): opened first, exit 2",
    "key": "tcpstream decode --key HEX: checked before reading, exit 2",
    "directory": "kermit receive/server/get: checked before the transfer, exit 2",
    "spec": "kermit get REMOTE_FILE: the server resolves it (E packet: exit 1)",
    "argument": "kermit remote ARG: the server resolves it (E packet: exit 1)",
    "log": "a file written (console --log) or read (plot FILE), exit 1 or 2",
    "out": "plot --out: the PNG written, exit 1",
    "pairs": "bench kermit: SENDER->RECEIVER checked by main, exit 2",
    "cprofile": "bench pty --cprofile: a file written",
    "from_json": "bench goodput: a file read",
    "output": "bench goodput: a file written",
    "plot": "bench goodput: a PNG written; a folder that is not there: one line, exit 2",
    "plot_delay": "bench goodput: a PNG written (as --plot)",
    "plot_ber": "bench goodput: a PNG written (as --plot)",
    "plot_delay_range": "bench goodput: a PNG written (as --plot)",
    "write_config": "relay --write-config: a file written (never over one), exit 1",
    "write_world": "arm-server --write-world: a file written (never over one), exit 1",
    "capture": "relay/listen/connect/arm-server --capture: a pcapng file written, exit 1",
    "task": "console/control --task rock|FILE: parsed and previewed before anything runs, "
    "exit 2 (tests/linksim/test_taskfile.py)",
    "compare_plot": "teleop --compare-plot: a PNG written after the runs, exit 1",
}

INT_RANGES = (link_args.IntRange, serial_args.IntRange)
FLOAT_RANGES = (link_args.FloatRange, serial_args.FloatRange)
PORT_NAMES = (link_args.SerialPortName, serial_args.SerialPortName)

CUSTOM: dict[object, list[str]] = {
    # Hand-written converters and the values they must refuse.
    link_options._burst: ["x:y", "0.1", "0.1:0.2:0.3:0.4:0.5", "2:0.5", "nan:0.5", "0.1:inf"],
    link_options._outage: ["x", "5:1", "-1:2", "1:2:3", "nan:1", "1:inf"],
    bench_cli._length: ["x", "5", "100000", "nan", ""],
    serial_cli._check: ["0", "4", "x", ""],
    proxy_cli._listen: ["x", "70000", "-1", "host:", ""],
    proxy_cli._target: ["x", "127.0.0.1:0", "127.0.0.1:70000", ":x", ""],
    proxy_cli._cut: ["sideways:10", "up:-1", "up", "down:x", ""],
}

CUSTOM_GOOD: dict[object, str] = {
    # A value the hand-written converters accept (for required options).
    proxy_cli._listen: "0",
    proxy_cli._target: "127.0.0.1:9",
    proxy_cli._cut: "up:10",
}


def _bad_values(action: argparse.Action) -> list[str] | None:
    """Values the option must refuse; None: the generator does not know its type."""
    conv = action.type
    if action.choices is not None:
        return ["no-such-choice", "", "99"]
    if isinstance(conv, INT_RANGES):
        bad = [str(conv.lo - 1), "nan", "inf", "1.5", "x", "", "0x10", "1e3"]
        if conv.hi is not None:
            bad += [str(conv.hi + 1), "9" * 40]
        return bad
    if isinstance(conv, FLOAT_RANGES):
        below = conv.lo if conv.lo_open else conv.lo - 1
        return [repr(below), repr(conv.hi * 2 + 1), "nan", "inf", "-inf", "1e999", "x", ""]
    if isinstance(conv, PORT_NAMES):
        return ["", "bogus://x", "nul\0byte"]
    if isinstance(conv, serial_args.PacketTypeLetter):
        return ["", "DD", " ", "\x7f"]
    if conv in CUSTOM:
        return CUSTOM[conv]
    if (conv is None or conv is pathlib.Path) and action.dest in FREE_TEXT:
        return []
    return None


def _good_value(action: argparse.Action) -> str:
    conv = action.type
    if action.choices is not None:
        return str(next(iter(action.choices)))
    if isinstance(conv, INT_RANGES):
        return str(conv.lo)
    if isinstance(conv, FLOAT_RANGES):
        return repr(conv.hi)
    if isinstance(conv, PORT_NAMES):
        return "loop://"
    return CUSTOM_GOOD.get(conv, "x")


def _walk(
    parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _walk(sub, (*path, name))


def _options() -> Iterator[tuple[str, tuple[str, ...], argparse.ArgumentParser, argparse.Action]]:
    """Every option and positional of every command that takes a value."""
    for command, build, _ in COMMANDS:
        for path, parser in _walk(build()):
            for action in parser._actions:
                if not isinstance(action, FLAGS) and action.nargs != 0:
                    yield command, path, parser, action


def _argv(
    path: tuple[str, ...], parser: argparse.ArgumentParser, target: argparse.Action, value: str
) -> list[str]:
    """The subcommand path, the required arguments filled with good values, and
    ``value`` for ``target`` (``--opt=VALUE`` so a leading '-' stays a value)."""
    if isinstance(target, argparse._SubParsersAction):
        return [*path, value]
    options: list[str] = []
    positionals: list[str] = []
    for action in parser._actions:
        if isinstance(action, (*FLAGS, argparse._SubParsersAction)):
            continue
        required = action.required or (not action.option_strings and action.nargs not in ("?", "*"))
        if action is not target and not required:
            continue
        given = value if action is target else _good_value(action)
        if action.option_strings:
            name = max(action.option_strings, key=len)
            options.append(f"{name}={given}")
        else:
            positionals.append(given)
    return [*path, *options, *(["--", *positionals] if positionals else [])]


class _Accepted(Exception):
    """parse_args returned: the command would have run."""


@pytest.fixture
def parse_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """main() stops right after parsing: an accepted value never opens or runs anything."""
    original = argparse.ArgumentParser.parse_args

    def parse_args(self: argparse.ArgumentParser, *args: Any, **kwargs: Any) -> Any:
        raise _Accepted(original(self, *args, **kwargs))

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", parse_args)


def _matrix() -> list[Any]:
    mains = {command: main for command, _, main in COMMANDS}
    cases = []
    for command, path, parser, action in _options():
        name = argparse._get_action_name(action)
        for value in _bad_values(action) or []:
            argv = _argv(path, parser, action, value)
            case_id = f"{command} {' '.join(path)} {name}={value!r}"
            cases.append(pytest.param(mains[command], argv, parser.prog, name, id=case_id))
    return cases


MATRIX = _matrix()


def test_every_option_is_classified() -> None:
    unknown = [
        f"{command} {' '.join(path)} {argparse._get_action_name(action)} (type {action.type!r})"
        for command, path, _, action in _options()
        if _bad_values(action) is None
    ]
    assert not unknown, (
        "options with no range-checked converter: give them one from serialsocket.argtypes "
        "(or, for free text, a FREE_TEXT line saying where it is checked): " + "; ".join(unknown)
    )


def test_every_command_line_is_in_the_matrix() -> None:
    builders = {
        str(path.relative_to(ROOT))
        for package in ("serialsocket", "tcpstream", "linksim")
        for path in (ROOT / package).rglob("*.py")
        if "ArgumentParser(" in path.read_text()
    }
    assert builders == set(PARSER_MODULES)
    assert len(MATRIX) > 500  # every option of every command, several values each


@pytest.mark.usefixtures("parse_only")
@pytest.mark.parametrize(("main", "argv", "prog", "name"), MATRIX)
def test_bad_value_is_one_argparse_error_naming_the_option(
    main: Main,
    argv: list[str],
    prog: str,
    name: str,
    capsys: pytest.CaptureFixture[str],
) -> None:
    try:
        main(argv)
    except SystemExit as exc:
        status = exc.code
    except _Accepted:
        pytest.fail(f"{argv} was accepted")
    err = capsys.readouterr().err
    assert status == 2, err
    assert "Traceback" not in err
    lines = err.splitlines()
    assert lines[0].startswith("usage: ")
    assert all(line.startswith(" ") for line in lines[1:-1]), err  # the usage, then one line
    last = lines[-1]
    assert last.startswith(f"{prog}: error: argument {name}: "), err
    assert len(last) < 400


def test_range_edges_and_defaults_are_accepted(parse_only: None) -> None:
    """The converters are not narrower than the commands: their bounds and every
    option's default parse (a default outside its own range would be a typo)."""
    checked = 0
    for _, _, parser, action in _options():
        conv = action.type
        good: list[str] = []
        if isinstance(conv, INT_RANGES):
            good = [str(conv.lo)] + ([str(conv.hi)] if conv.hi is not None else [])
        elif isinstance(conv, FLOAT_RANGES):
            good = [repr(conv.hi), repr(conv.lo + 1e-9 if conv.lo_open else conv.lo)]
        if isinstance(conv, (*INT_RANGES, *FLOAT_RANGES)) and isinstance(
            action.default, int | float
        ):
            good.append(repr(action.default))
        for value in good:
            argv = _argv((), parser, action, value)
            try:
                parser.parse_args(argv)
            except SystemExit:
                pytest.fail(f"{parser.prog} {argv} was refused")
            except _Accepted:
                checked += 1
    assert checked > 150


def test_converter_bounds_are_what_the_library_takes() -> None:
    """Each range's ends are accepted by the config the value goes to, and linksim's
    copy of the converters agrees with serialsocket's."""
    pairs = [
        (link_args.WINDOW, serial_args.WINDOW),
        (link_args.ENDPOINT_LENGTH, serial_args.ENDPOINT_LENGTH),
        (link_args.KERMIT_LENGTH, serial_args.KERMIT_LENGTH),
        (link_args.BAUD, serial_args.BAUD),
    ]
    for a, b in pairs:
        assert (a.lo, a.hi) == (b.lo, b.hi)
    for a, b in [(link_args.DELAY, serial_args.DELAY), (link_args.SECONDS, serial_args.SECONDS)]:
        assert dataclasses.astuple(a) == dataclasses.astuple(b)
    length, window = serial_args.ENDPOINT_LENGTH, serial_args.WINDOW
    for n in (length.lo, length.hi):
        EndpointConfig(max_packet_length=n, window=window.lo, one_way_delay=serial_args.DELAY.hi)
    EndpointConfig(window=window.hi, line_rate=serial_args.BAUD.hi)
    with pytest.raises(serial_cli.LocalProtocolError):
        EndpointConfig(max_packet_length=length.lo - 1)
    kermit = serial_args.KERMIT_LENGTH
    for n in (kermit.lo, kermit.hi):
        KermitConfig(max_packet_length=n, window=serial_args.KERMIT_WINDOW.hi)
    KermitConfig(timeout=serial_args.KERMIT_TIMEOUT.hi, retry_limit=serial_args.RETRIES.hi)
    with pytest.raises(serial_cli.LocalProtocolError):
        KermitConfig(max_packet_length=kermit.lo - 1)
    bits = link_args.BITS_PER_CHAR
    for n in (bits.lo, bits.hi):
        DirectionConfig(rate=link_args.BIT_RATE.hi, bits_per_char=n, delay=link_args.DELAY.hi)


# -- values that look right but fail when used: one line, exit 1 or 2, in a real process -----

RUNTIME_CASES = [
    # (command line, exit status, words the one line must contain, whether argparse's usage
    # comes first).  Each run is bounded by a timeout; none starts a server that stays up.
    (["serialsocket", "connect", "bogus://x"], 2, "argument PORT: unknown URL scheme", True),
    (["linksim", "arm-server", "--transport", "tcp", "--tcp-port", "99999"], 2, "0..65535", True),
    (["linksim", "relay", "--duration", "-1"], 2, "argument --duration:", True),
    (["serialsocket", "connect", "/nonexistent/tty"], 1, "/nonexistent/tty", False),
    (["serialsocket", "kermit", "receive", "--port", "/nonexistent/tty"], 2, "/nonexistent", False),
    (
        ["linksim", "arm-server", "--port", "/nonexistent/tty", "--sessions", "1"],
        1,
        "linksim arm-server: [Errno 2] cannot open '/nonexistent/tty'",
        False,
    ),
    (
        ["linksim", "relay", "--device", "/nonexistent/a", "--device", "/nonexistent/b"],
        1,
        "linksim relay: [Errno 2]",
        False,
    ),
    (["linksim", "demo", "--virtual", "--world", "/nonexistent.toml"], 2, "nonexistent", False),
    (["linksim", "control", "--virtual", "--task", "/no/such.toml"], 2, "/no/such.toml", False),
    (["linksim", "console", "--virtual", "--task", "wave"], 2, "ends in .toml or .json", False),
    # Options that would be ignored are refused with the reason.
    (["linksim", "demo", "--virtual", "--dial", "5551234"], 2, "cannot run with --virtual", False),
    (["linksim", "demo", "--transport", "tcp", "--dial", "5551234"], 2, "serial transport", False),
    (["linksim", "demo", "--transport", "tcp", "--window", "4"], 2, "tcp transport has", False),
    (["linksim", "demo", "--transport", "tcp", "--max-len", "90"], 2, "tcp transport has", False),
    (
        ["linksim", "bench", "latency", "--client", "asyncio", "--server", "loop"],
        2,
        "--server loop needs the trio client",
        False,
    ),
    (["linksim", "relay", "--device", "/dev/null"], 1, "give exactly two devices", False),
    (
        ["linksim", "relay", "--device", "loop://", "--device", "/dev/ptmx"],
        1,
        "loop://: the relay attaches to ttys by path, or to a TCP serial server",
        False,
    ),
    (
        ["linksim", "relay", "--device", "socket://nohost", "--device", "/dev/ptmx"],
        1,
        "a TCP serial server is socket://HOST:PORT",
        False,
    ),
    (
        ["linksim", "relay", "--device", "socket://127.0.0.1:1", "--device", "/dev/ptmx"],
        1,
        "Connection refused",
        False,
    ),
    (["linksim", "relay", "--device", "/dev/null", "--device", "/dev/null"], 1, "both", False),
    (["linksim", "relay", "--device", "/dev/null", "--device", "/dev/zero"], 1, "terminal", False),
    (["linksim", "teleop", "--virtual", "--key-file", "/nonexistent"], 2, "nonexistent", False),
]


@pytest.mark.parametrize(("argv", "status", "words", "usage"), RUNTIME_CASES)
def test_runtime_failure_is_one_line_not_a_traceback(
    argv: list[str], status: int, words: str, usage: bool
) -> None:
    done = subprocess.run(
        [sys.executable, "-m", *argv],
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == status, done.stderr
    assert "Traceback" not in done.stderr
    lines = done.stderr.splitlines()
    if usage:
        assert lines[0].startswith("usage: ")
        lines = [line for line in lines if not line.startswith(("usage: ", " "))]
    assert len(lines) == 1, done.stderr
    assert words in lines[0]
