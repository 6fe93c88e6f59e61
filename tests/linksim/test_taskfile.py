"""Task files and the command language they share with the console's command line."""

from __future__ import annotations

import json
import math
import pathlib

import pytest

from linksim import DEFAULT_WORLD, rock_task
from linksim.cli import _console as console_cli
from linksim.cli import main
from linksim.control import (
    CommandSyntaxError,
    TaskFileError,
    format_command,
    load_task,
    parse_command,
    preview,
    resolve_task,
)
from linksim.control._taskfile import MAX_COMMANDS, parse_task
from linksim.control._vocabulary import BadArgument, UnknownCommand, complete
from tcpstream import Command, CommandCode
from tcpstream.commands import CommandFlags

ROOT = pathlib.Path(__file__).resolve().parents[2]
TASKS = ROOT / "examples" / "tasks"
DEG = math.pi / 180

# -- the language ------------------------------------------------------------------------

LINES = [
    ("move_joint 1 20deg", Command(CommandCode.MOVE_JOINT, (1.0, 20 * DEG))),
    ("move_joint 6 -0.5rad", Command(CommandCode.MOVE_JOINT, (6.0, -0.5))),
    ("move_joint 2 20 deg", Command(CommandCode.MOVE_JOINT, (2.0, 20 * DEG))),
    ("move_joint joint=3 by=-45°", Command(CommandCode.MOVE_JOINT, (3.0, -45 * DEG))),
    (
        "move_joints 0,90,-200,0,-70,0deg",
        Command(CommandCode.MOVE_JOINTS, DEFAULT_WORLD.initial_joints),
    ),
    ("move_to 550,150,-150mm", Command(CommandCode.MOVE_TO_POSITION, (0.55, 0.15, -0.15))),
    ("move_to (55, 15, -15) cm", Command(CommandCode.MOVE_TO_POSITION, (0.55, 0.15, -0.15))),
    (
        "move_to 0.5,0,0m s=0,1,0 a=0,0,-1",
        Command(
            CommandCode.MOVE_TO_POSITION,
            (0.5, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0),
            CommandFlags.SPECIFIED_ORIENTATION,
        ),
    ),
    ("move_by 0,0,-120mm", Command(CommandCode.MOVE_CARTESIAN_DELTA, (0, 0, -0.12, 0, 0, 0))),
    (
        "move_by 0, 0, 10 mm rot=0,0,90deg pose_change",
        Command(
            CommandCode.MOVE_CARTESIAN_DELTA,
            (0, 0, 0.01, 0, 0, 90 * DEG),
            CommandFlags.POSE_CHANGE,
        ),
    ),
    (
        "path 550,150,-100mm 550,150,-200mm blend=1500ms",
        Command(CommandCode.MOVE_PATH, (2.0, 1.5, 0.55, 0.15, -0.1, 0.55, 0.15, -0.2)),
    ),
    ("path 0.5,0,0m", Command(CommandCode.MOVE_PATH, (1.0, 0.0, 0.5, 0.0, 0.0))),
    ("open_fingers", Command(CommandCode.OPEN_FINGERS, (0.0,))),
    ("open_fingers 6cm", Command(CommandCode.OPEN_FINGERS, (0.06,))),
    ("close_fingers", Command(CommandCode.CLOSE_FINGERS)),
    ("center_fingers", Command(CommandCode.CENTER_FINGERS)),
    ("squeeze 20N", Command(CommandCode.SQUEEZE, (20.0,))),
    ("weigh", Command(CommandCode.WEIGH)),
    ("speed 50%", Command(CommandCode.CHANGE_SPEED, (0.5,))),
    ("speed 0.25", Command(CommandCode.CHANGE_SPEED, (0.25,))),
    (
        "add_obstacle 600,-100,-350mm 700,0,-250mm",
        Command(CommandCode.ADD_OBSTACLE, (0.6, -0.1, -0.35, 0.7, 0.0, -0.25)),
    ),
    ("query", Command(CommandCode.STATUS)),
    ("reinitialize", Command(CommandCode.REINITIALIZE)),
    ("terminate", Command(CommandCode.TERMINATE)),
    ("estop", Command(CommandCode.EMERGENCY_STOP)),
]


def _same(a: Command, b: Command) -> bool:
    return (
        a.code is b.code
        and a.flags == b.flags
        and len(a.args) == len(b.args)
        and all(math.isclose(x, y, abs_tol=1e-12) for x, y in zip(a.args, b.args, strict=True))
    )


@pytest.mark.parametrize(("line", "command"), LINES, ids=[line for line, _ in LINES])
def test_a_line_makes_the_command_in_si_units(line: str, command: Command) -> None:
    assert _same(parse_command(line), command)


@pytest.mark.parametrize(("line", "command"), LINES, ids=[line for line, _ in LINES])
def test_format_reads_back(line: str, command: Command) -> None:
    assert _same(parse_command(format_command(command)), command)


def test_the_rock_task_in_the_language() -> None:
    commands = rock_task(DEFAULT_WORLD).commands
    lines = [format_command(c) for c in commands]
    assert lines[:3] == [
        "open_fingers",
        "path 570,135,-65mm 570,135,-195mm",
        "center_fingers",
    ]
    assert lines[-1] == "move_joints 0,90,-200,0,-70,0deg"
    for line, command in zip(lines, commands, strict=True):
        back = parse_command(line)
        assert back.code is command.code
        assert back.args == pytest.approx(command.args, abs=1e-9)


BAD_LINES = [
    # (line, error type, words the message must contain)
    ("move_joint 1 20", BadArgument, "move_joint: by (angle): '20' needs a unit (deg, °, rad)"),
    ("move_joint 7 20deg", BadArgument, "move_joint: joint (joint): a joint number is 1..6"),
    ("move_joint 1.5 20deg", BadArgument, "a joint number is 1..6, got '1.5'"),
    ("move_joint 1 20furlong", BadArgument, "unknown unit 'furlong'; use 'deg', '°', 'rad'"),
    ("move_joint 1 20mm", BadArgument, "unknown unit 'mm'"),
    ("move_joint 1", BadArgument, "move_joint: missing by: a number in deg|°|rad"),
    ("move_joint 1 2deg 3deg", BadArgument, "too many arguments: '3deg'"),
    ("move_joint 1 by=2deg by=3deg", BadArgument, "by= is given twice"),
    ("move_joint 1 speed=2", BadArgument, "unknown argument speed= (it takes joint=, by=)"),
    ("move_joint x 2deg", BadArgument, "cannot read 'x' as a quantity (example: 1)"),
    ("move_to 550,150mm", BadArgument, "needs 3 numbers joined by commas, got 2"),
    ("move_to 1,2,3mm s=0,1,0", BadArgument, "give both S and A"),
    ("move_to 1,2,3mm s=0,2,0 a=0,0,1", BadArgument, "S must be a unit vector"),
    ("path", BadArgument, "path: needs 1..5 via points, got 0"),
    ("path " + "1,1,1mm " * 6, BadArgument, "needs 1..5 via points, got 6"),
    ("path 1,1,1mm blend=-1s", BadArgument, "blend time must be >= 0"),
    ("speed 200%", BadArgument, "speed fraction must be in (0, 1], got 2.0"),
    ("speed 0", BadArgument, "speed fraction must be in (0, 1]"),
    ("squeeze -1N", BadArgument, "grip force must be > 0 N"),
    ("squeeze 20", BadArgument, "needs a unit (N)"),
    ("open_fingers -5mm", BadArgument, "finger opening must be >= 0"),
    ("add_obstacle 1,1,1m 0,0,0m", BadArgument, "box maximum must exceed its minimum"),
    ("move_joint 1 1e400deg", BadArgument, "is not a finite number"),
    ("movejoint 1 20deg", UnknownCommand, "unknown command 'movejoint'; did you mean move_joint"),
    ("status", UnknownCommand, "the arm's STATUS command is 'query'"),
    ("", BadArgument, "empty command"),
    ("weigh " + "x" * 1000, BadArgument, "at most 1000 characters"),
]


@pytest.mark.parametrize(("line", "kind", "words"), BAD_LINES, ids=[b[0][:30] for b in BAD_LINES])
def test_a_bad_line_is_a_typed_error_naming_the_argument(
    line: str, kind: type[CommandSyntaxError], words: str
) -> None:
    with pytest.raises(kind) as info:
        parse_command(line)
    assert words in str(info.value)
    assert isinstance(info.value, ValueError)


def test_completion_of_names_keywords_and_units() -> None:
    assert complete("mo") == ["move_by", "move_joint", "move_joints", "move_to"]
    assert complete("st", extra=("status", "history")) == ["status"]
    assert complete("move_by ") == ["dp=", "pose_change", "rot="]
    assert complete("move_by 0,0,1 r") == ["rot="]
    assert complete("move_joint 1 20d") == ["20deg"]
    assert complete("nosuch ") == []


# -- files -----------------------------------------------------------------------------------


def test_the_example_task_files_parse_with_their_lines() -> None:
    wave = load_task(TASKS / "wave.toml")
    assert wave.name == "wave"
    assert len(wave.commands) == 9
    assert wave.lines == tuple(range(8, 17))
    assert wave.where(2) == f"{TASKS / 'wave.toml'} line 9, entry 2"
    pebble = load_task(TASKS / "pick_pebble.toml")
    assert pebble.commands[3] == Command(
        CommandCode.MOVE_CARTESIAN_DELTA, (0.0, 0.0, -0.1, 0.0, 0.0, 0.0)
    )
    assert pebble.lines[3] == 10  # the inline table's line
    far = load_task(TASKS / "reach_too_far.json")
    assert far.lines == (5, 6, 7)


def test_the_examples_preview_as_their_descriptions_say() -> None:
    for name in ("wave.toml", "pick_pebble.toml"):
        assert preview(load_task(TASKS / name).commands, DEFAULT_WORLD).ok, name
    report = preview(load_task(TASKS / "reach_too_far.json").commands, DEFAULT_WORLD)
    refusal = report.first_refusal
    assert refusal is not None
    assert (refusal.index, refusal.reason.name) == (2, "JOINT_LIMIT")
    pebble = preview(load_task(TASKS / "pick_pebble.toml").commands, DEFAULT_WORLD)
    assert pebble.outcomes[6].aux[0] == pytest.approx(0.12, abs=0.01)  # weighed the pebble


BAD_FILES = [
    # (file name, text, error type, words)
    ("t.toml", "commands = [", TaskFileError, "t.toml: invalid TOML"),
    ("t.json", '{"commands": [}', TaskFileError, "t.json line 1: invalid JSON"),
    ("t.toml", 'name = "x"', TaskFileError, "t.toml: needs a non-empty commands list"),
    ("t.toml", "commands = []", TaskFileError, "t.toml: needs a non-empty commands list"),
    ("t.toml", 'commands = ["weigh"]\ncolour = 1', TaskFileError, "t.toml: unknown key 'colour'"),
    ("t.json", '"weigh"', TaskFileError, "t.json: a task file is a table with a commands list"),
    ("t.toml", 'name = 3\ncommands = ["weigh"]', TaskFileError, "t.toml: name must be a string"),
    (
        "t.toml",
        'commands = [\n  "weigh",\n  "move_joint 1 20",\n]',
        BadArgument,
        "t.toml line 3, entry 2: move_joint: by (angle): '20' needs a unit",
    ),
    (
        "t.json",
        '{"commands": [\n"weigh",\n{"command": "move_joint", "joint": 9, "by": "2deg"}\n]}',
        BadArgument,
        "t.json line 3, entry 2: move_joint: joint (joint): a joint number is 1..6",
    ),
    ("t.json", '["weigh", 3]', CommandSyntaxError, "t.json entry 2: an entry is a command"),
    ("t.json", '["estop"]', CommandSyntaxError, "entry 1: estop is immediate"),
    ("t.toml", "commands = [{ joint = 1 }]", BadArgument, 'needs command = "NAME"'),
    (
        "t.toml",
        'commands = [{ command = "move_by", dp = "0,0,1mm", pose_change = 1 }]',
        BadArgument,
        "pose_change is true or false",
    ),
    (
        "t.toml",
        'commands = [{ command = "move_joint", joint = 1, by = 20 }]',
        BadArgument,
        "'20' needs a unit",
    ),
    ("t.toml", 'commands = [{ command = "jump" }]', UnknownCommand, "unknown command 'jump'"),
    ("t.yaml", "commands: [weigh]", TaskFileError, "t.yaml: a task file ends in .toml or .json"),
]


@pytest.mark.parametrize(
    ("name", "text", "kind", "words"), BAD_FILES, ids=[b[3][:40] for b in BAD_FILES]
)
def test_a_bad_task_file_says_where_and_what(
    name: str, text: str, kind: type[Exception], words: str, tmp_path: pathlib.Path
) -> None:
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(kind) as info:
        load_task(path)
    assert str(info.value).replace(str(tmp_path) + "/", "").startswith(name)
    assert words in str(info.value).replace(str(tmp_path) + "/", "")


def test_unreadable_oversized_and_overlong_files(tmp_path: pathlib.Path) -> None:
    with pytest.raises(TaskFileError, match="cannot read task file"):
        load_task(tmp_path / "missing.toml")
    big = tmp_path / "big.toml"
    big.write_bytes(b"#" * ((1 << 20) + 1))
    with pytest.raises(TaskFileError, match="larger than"):
        load_task(big)
    binary = tmp_path / "bin.toml"
    binary.write_bytes(b"\xff\xfe")
    with pytest.raises(TaskFileError, match="not UTF-8"):
        load_task(binary)
    with pytest.raises(TaskFileError, match=f"at most {MAX_COMMANDS}"):
        parse_task(json.dumps(["weigh"] * (MAX_COMMANDS + 1)), "x.json", "json")


def test_stdin_and_the_builtin_rock_task() -> None:
    assert resolve_task("-", DEFAULT_WORLD, '["weigh"]').commands == (Command(CommandCode.WEIGH),)
    assert resolve_task("-", DEFAULT_WORLD, 'commands = ["weigh"]').source == "<stdin>"
    rock = resolve_task("rock", DEFAULT_WORLD)
    assert rock.commands == rock_task(DEFAULT_WORLD).commands
    assert rock.name == "rock task"


# -- the command lines -----------------------------------------------------------------------


def test_control_virtual_runs_a_task_file_deterministically(
    capsys: pytest.CaptureFixture[str],
) -> None:
    argv = ["control", "--virtual", "--task", str(TASKS / "wave.toml"), "--json", "--quiet"]
    assert main(argv) == 0
    first = capsys.readouterr().out
    assert main(argv) == 0
    assert capsys.readouterr().out == first
    report = json.loads(first)
    assert report["ok"] is True
    assert report["commands"] == {"sent": 9, "completed": 9, "failed": 0, "total": 9}
    assert [c["label"] for c in report["command_log"]][:2] == [
        "speed 80 %",
        "move joint 1 by +30.0 deg",
    ]
    assert report["arm"]["joints_deg"] == [0.0, 90.0, -200.0, 0.0, -70.0, 0.0]


def test_control_refuses_a_task_file_the_preview_refuses_unless_forced(
    capsys: pytest.CaptureFixture[str],
) -> None:
    far = str(TASKS / "reach_too_far.json")
    assert main(["control", "--virtual", "--task", far, "--quiet"]) == 1
    out, err = capsys.readouterr()
    assert out == ""
    assert err == (
        f"linksim control: {far} line 6, entry 2 (move joint 1 by +90.0 deg) would be refused "
        "by the arm: JOINT_LIMIT: joint 1 would be at 180.0 deg, outside its range -160..160 "
        "deg; nothing was sent (--force sends it anyway)\n"
    )
    assert main(["control", "--virtual", "--task", far, "--quiet", "--force", "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    assert report["commands"] == {"sent": 3, "completed": 1, "failed": 2, "total": 3}
    assert report["command_log"][1]["reason"] == "JOINT_LIMIT"


def test_console_drives_a_task_file_and_flags_nothing(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["console", "--virtual", "--plain", "--json", "--task", str(TASKS / "pick_pebble.toml")]
    assert main(argv) == 0
    out, err = capsys.readouterr()
    summary = json.loads(out)
    assert [c["state"] for c in summary["commands"]] == ["completed"] * 12
    assert summary["model"]["flagged"] == 0
    assert "telelink console: pick the pebble over serial (noisy-moon, virtual time)" in err
    assert "force: weighed 0.12" in err


def test_console_refuses_a_refused_task_file_before_sending(
    capsys: pytest.CaptureFixture[str],
) -> None:
    far = str(TASKS / "reach_too_far.json")
    assert main(["console", "--virtual", "--plain", "--json", "--task", far]) == 1
    summary = json.loads(capsys.readouterr().out)
    assert all(c["sent_s"] is None for c in summary["commands"])
    assert summary["error"] == (
        f"preview refused command #2 ({far} line 6, entry 2) (move joint 1 by +90.0 deg): "
        "JOINT_LIMIT: joint 1 would be at 180.0 deg, outside its range -160..160 deg; "
        "nothing was sent (--force sends it anyway)"
    )
    assert main(["console", "--preview-only", "--task", far]) == 1
    assert "#2    2.95 s + 0.00 s  move joint 1 by +90.0 deg: JOINT_LIMIT" in (
        capsys.readouterr().out
    )


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["control", "--virtual", "--task", "nope.toml"], "cannot read task file nope.toml"),
        (["control", "--virtual", "--task", "wave"], "wave: a task file ends in .toml or .json"),
        (["control", "--virtual", "--port", "/dev/null"], "not with --virtual"),
        (["control", "--virtual", "--tcp-port", "7011"], "not with --virtual"),
        (["control"], "--port PATH is needed for the serial transport"),
        (["control", "--virtual", "--transport", "tcp", "--window", "4"], "tcp transport has"),
        (["control", "--transport", "tcp", "--dial", "555"], "needs the serial transport"),
        (["console", "--preview-only", "--task", "-", "--world", "-"], "cannot both read stdin"),
        (["console", "--virtual", "--force", "--require-preview"], "contradict"),
        (["console", "--observer", "--task", "x.toml"], "--observer sends nothing"),
    ],
)
def test_bad_task_options_are_one_line_exit_2(
    argv: list[str],
    words: str,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(TASKS)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1, err
    assert words in err


def test_a_bad_entry_in_a_task_file_is_one_line_naming_it(
    tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "typo.toml"
    path.write_text('commands = [\n  "open_fingers",\n  "move_joint 1 20",\n]\n')
    assert main(["control", "--virtual", "--task", str(path)]) == 2
    assert capsys.readouterr().err == (
        f"linksim control: {path} line 3, entry 2: move_joint: by (angle): '20' needs a unit "
        "(deg, °, rad), for example 20deg\n"
    )


REFUSED_EXAMPLES = {"reach_too_far.json"}
"""Example task files written to show the preview's refusal."""


@pytest.mark.parametrize("path", sorted(TASKS.iterdir()), ids=lambda p: p.name)
def test_every_example_task_file_parses_and_previews_as_it_says(path: pathlib.Path) -> None:
    task = load_task(path)
    assert task.description, f"{path.name} says what it does"
    report = preview(task.commands, DEFAULT_WORLD)
    assert report.ok is (path.name not in REFUSED_EXAMPLES)


def test_ctrl_c_during_control_is_one_line_and_130(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(console_cli, "run_virtual", interrupted)
    assert main(["control", "--virtual", "--task", str(TASKS / "wave.toml")]) == 130
    assert capsys.readouterr().err == "linksim control: interrupted\n"


def test_the_rock_task_file_is_the_builtin_rock_task() -> None:
    task = load_task(TASKS / "rock.toml")
    builtin = rock_task(DEFAULT_WORLD).commands
    assert [c.code for c in task.commands] == [c.code for c in builtin]
    for mine, theirs in zip(task.commands, builtin, strict=True):
        assert mine.args == pytest.approx(theirs.args, abs=1e-12)
