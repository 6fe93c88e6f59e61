"""The operator's command language: one line per arm command, with units on every quantity.

Task files (:mod:`~linksim.control._taskfile`) and the console's command line
(:mod:`~linksim.control._command_line`) share it, so a line typed at the
prompt can be pasted into a task file and back.  Examples::

    move_joint 1 20deg                 joint 1 by +20 degrees
    move_joints 0,90,-200,0,-70,0deg   all six joints to these angles
    move_to 550,150,-150mm             the hand to P (orientation kept)
    move_by 0,0,-120mm                 seed 004's incremental move (rot=0,0,10deg too)
    path 550,150,-100mm 550,150,-200mm blend=2s   seed 003's via-point path
    open_fingers 60mm | close_fingers | squeeze 20N | weigh | speed 50%

A quantity is a number, or numbers joined by commas (a vector), followed by
one unit for all of them: lengths in ``m``, ``cm`` or ``mm``; angles in
``deg`` or ``rad``; times in ``s`` or ``ms``; forces in ``N``; speed as a
fraction (``0.5``) or a percentage (``50%``).  A length or an angle without
a unit is refused: ``20`` could be degrees or radians, and a 57-fold mistake
on an arm is not one to guess about.  The commands are those of the README's
command table (tcpstream.commands builds them); ``query`` is its STATUS (the
console's ``status`` shows the console's own view).

Pure: :func:`parse_command` turns a line into a :class:`tcpstream.Command`
(range-checked with :func:`tcpstream.commands.validate_arguments`) or raises a
:class:`CommandSyntaxError` that says what is wrong with which argument;
:func:`format_command` is its inverse; :func:`complete` offers completions.
"""

from __future__ import annotations

import difflib
import enum
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from tcpstream import Command, CommandCode, CommandFailed
from tcpstream.commands import (
    JOINTS,
    MAX_PATH_POINTS,
    add_obstacle,
    center_fingers,
    change_speed,
    close_fingers,
    move_delta,
    move_joint,
    move_joints,
    move_path,
    move_to,
    open_fingers,
    reinitialize,
    squeeze,
    status,
    terminate,
    validate_arguments,
    weigh,
)

__all__ = [
    "VERBS",
    "BadArgument",
    "CommandSyntaxError",
    "Quantity",
    "UnknownCommand",
    "Verb",
    "complete",
    "format_command",
    "parse_command",
    "parse_entry",
]

MAX_LINE = 1000
"""Characters in one command line: the longest real one (a five-point path) is
about 120; a thousand is a pasted file, refused before it is tokenised."""


class CommandSyntaxError(ValueError):
    """A command line or task-file entry that does not make a command (the operator's to fix).

    ``where`` says where it came from (``wave.toml line 7``), prefixed to the
    message when set.
    """

    def __init__(self, message: str, *, where: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.where = where

    def __str__(self) -> str:
        return f"{self.where}: {self.message}" if self.where else self.message


class UnknownCommand(CommandSyntaxError):
    """The first word names no command."""


class BadArgument(CommandSyntaxError):
    """An argument is missing, extra, malformed, in the wrong unit or out of range."""


class Quantity(enum.Enum):
    """What a parameter measures, and the units it takes (factor to SI)."""

    LENGTH = "length"
    ANGLE = "angle"
    TIME = "time"
    FORCE = "force"
    FRACTION = "fraction"
    NUMBER = "number"
    """Unitless (the components of a unit vector)."""
    JOINT = "joint"
    """A joint number 1..6."""

    @property
    def units(self) -> Mapping[str, float]:
        return _UNITS[self]

    @property
    def default_unit(self) -> str:
        """The unit :func:`format_command` writes."""
        return _DEFAULT_UNIT[self]


_UNITS: dict[Quantity, dict[str, float]] = {
    Quantity.LENGTH: {"m": 1.0, "cm": 0.01, "mm": 0.001},
    Quantity.ANGLE: {"deg": math.pi / 180.0, "°": math.pi / 180.0, "rad": 1.0},
    Quantity.TIME: {"s": 1.0, "ms": 0.001},
    Quantity.FORCE: {"N": 1.0},
    Quantity.FRACTION: {"": 1.0, "%": 0.01},
    Quantity.NUMBER: {"": 1.0},
    Quantity.JOINT: {"": 1.0},
}
_DEFAULT_UNIT = {
    Quantity.LENGTH: "mm",
    Quantity.ANGLE: "deg",
    Quantity.TIME: "s",
    Quantity.FORCE: "N",
    Quantity.FRACTION: "%",
    Quantity.NUMBER: "",
    Quantity.JOINT: "",
}
_ALL_UNITS = frozenset(u for units in _UNITS.values() for u in units if u)

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_QUANTITY = re.compile(
    rf"^\(?\s*(?P<values>{_NUMBER}(?:\s*,\s*{_NUMBER})*)\s*\)?\s*(?P<unit>[^\d\s,()+\-.]*)$"
)

Value = tuple[float, ...]


@dataclass(frozen=True, slots=True)
class Param:
    """One argument: ``name`` (also its keyword), what it measures, how many numbers."""

    name: str
    quantity: Quantity
    size: int = 1
    optional: bool = False
    help: str = ""

    def describe(self) -> str:
        units = "|".join(u for u in self.quantity.units if u) or "number"
        shape = f"{self.size} numbers" if self.size > 1 else "a number"
        return f"{self.name}: {shape} in {units}" if units != "number" else f"{self.name}: {shape}"


Builder = Callable[[Mapping[str, Value], Sequence[str], Sequence[Value]], Command]


@dataclass(frozen=True, slots=True)
class Verb:
    """A command of the language: its name, parameters and how it becomes a Command.

    ``repeated``: a parameter given 1..:data:`MAX_PATH_POINTS` times
    (a path's via points), positionally; the other parameters are then
    keywords.  ``flags``: bare words that switch an option on.
    """

    name: str
    code: CommandCode
    params: tuple[Param, ...]
    summary: str
    example: str
    build: Builder
    repeated: Param | None = None
    flags: tuple[str, ...] = ()
    in_files: bool = True
    """False for a command that cannot stand in a queued list (the emergency stop)."""

    def usage(self) -> str:
        parts = [self.name]
        if self.repeated is not None:
            parts.append(f"{self.repeated.name.upper()}... (1..{MAX_PATH_POINTS})")
        for p in self.params:
            text = f"{p.name}=" if self.repeated is not None else ""
            text += p.name.upper()
            parts.append(f"[{text}]" if p.optional else text)
        parts += [f"[{f}]" for f in self.flags]
        return " ".join(parts)


def _one(values: Mapping[str, Value], name: str, default: float | None = None) -> float:
    value = values.get(name)
    if value is None:
        assert default is not None
        return default
    return value[0]


def _verbs() -> dict[str, Verb]:
    L, A = Quantity.LENGTH, Quantity.ANGLE
    verbs = [
        Verb(
            "move_joint",
            CommandCode.MOVE_JOINT,
            (Param("joint", Quantity.JOINT), Param("by", A)),
            "move one joint (1..6) by a signed angle",
            "move_joint 1 20deg",
            lambda v, f, r: move_joint(int(_one(v, "joint")), _one(v, "by")),
        ),
        Verb(
            "move_joints",
            CommandCode.MOVE_JOINTS,
            (Param("to", A, JOINTS),),
            "all six joints to these angles, starting and stopping together",
            "move_joints 0,90,-200,0,-70,0deg",
            lambda v, f, r: move_joints(v["to"]),
        ),
        Verb(
            "move_to",
            CommandCode.MOVE_TO_POSITION,
            (
                Param("p", L, 3),
                Param("s", Quantity.NUMBER, 3, True),
                Param("a", Quantity.NUMBER, 3, True),
            ),
            "the hand to position P (base frame), keeping its orientation unless S and A are given",
            "move_to 550,150,-150mm",
            lambda v, f, r: move_to(v["p"], v.get("s"), v.get("a")),
        ),
        Verb(
            "move_by",
            CommandCode.MOVE_CARTESIAN_DELTA,
            (Param("dp", L, 3), Param("rot", A, 3, True)),
            "seed 004's incremental move: the hand by dP, turned by rot about the base axes",
            "move_by 0,0,-120mm",
            lambda v, f, r: move_delta(
                v["dp"], v.get("rot", (0.0, 0.0, 0.0)), pose_change="pose_change" in f
            ),
            flags=("pose_change",),
        ),
        Verb(
            "path",
            CommandCode.MOVE_PATH,
            (Param("blend", Quantity.TIME, optional=True),),
            "seed 003's Level-2 path through 1..5 via points (orientation held)",
            "path 550,150,-100mm 550,150,-200mm blend=2s",
            lambda v, f, r: move_path(r, _one(v, "blend", 0.0)),
            repeated=Param("point", L, 3),
        ),
        Verb(
            "open_fingers",
            CommandCode.OPEN_FINGERS,
            (Param("opening", L, optional=True),),
            "open the fingers to an opening (fully without one)",
            "open_fingers 60mm",
            lambda v, f, r: open_fingers(_one(v, "opening", 0.0)),
        ),
        Verb(
            "close_fingers",
            CommandCode.CLOSE_FINGERS,
            (),
            "close until both tactile switches touch",
            "close_fingers",
            lambda v, f, r: close_fingers(),
        ),
        Verb(
            "center_fingers",
            CommandCode.CENTER_FINGERS,
            (),
            "centre the hand over the nearest object (proximity sensors)",
            "center_fingers",
            lambda v, f, r: center_fingers(),
        ),
        Verb(
            "squeeze",
            CommandCode.SQUEEZE,
            (Param("force", Quantity.FORCE),),
            "squeeze the grasped object",
            "squeeze 20N",
            lambda v, f, r: squeeze(_one(v, "force")),
        ),
        Verb(
            "weigh",
            CommandCode.WEIGH,
            (),
            "weigh the grasped object",
            "weigh",
            lambda v, f, r: weigh(),
        ),
        Verb(
            "speed",
            CommandCode.CHANGE_SPEED,
            (Param("fraction", Quantity.FRACTION),),
            "use this fraction of the maximum joint velocities",
            "speed 50%",
            lambda v, f, r: change_speed(_one(v, "fraction")),
        ),
        Verb(
            "add_obstacle",
            CommandCode.ADD_OBSTACLE,
            (Param("min", L, 3), Param("max", L, 3)),
            "tell the arm about a box (its minimum and maximum corners)",
            "add_obstacle 600,-100,-350mm 700,0,-250mm",
            lambda v, f, r: add_obstacle(v["min"], v["max"]),
        ),
        Verb(
            "query",
            CommandCode.STATUS,
            (),
            "ask the arm for its state (STATUS; no motion)",
            "query",
            lambda v, f, r: status(),
        ),
        Verb(
            "reinitialize",
            CommandCode.REINITIALIZE,
            (),
            "back to the initial pose and speed",
            "reinitialize",
            lambda v, f, r: reinitialize(),
        ),
        Verb(
            "terminate",
            CommandCode.TERMINATE,
            (),
            "end the session once the queue drains",
            "terminate",
            lambda v, f, r: terminate(),
        ),
        Verb(
            "estop",
            CommandCode.EMERGENCY_STOP,
            (),
            "emergency stop: halt now, bypassing the queue (the queued commands fail)",
            "estop",
            lambda v, f, r: Command(CommandCode.EMERGENCY_STOP),
            in_files=False,
        ),
    ]
    return {v.name: v for v in verbs}


VERBS: Mapping[str, Verb] = _verbs()
"""Every command of the language, by name."""

_BY_CODE = {v.code: v for v in VERBS.values()}


def _tokens(text: str) -> list[str]:
    """Whitespace-separated words, with ``350, 0, 200 mm`` glued back into one quantity."""
    raw = text.split()
    out: list[str] = []
    for word in raw:
        glue = out and (
            out[-1].endswith(",")
            or word.startswith(",")
            or (word in _ALL_UNITS and _QUANTITY.match(out[-1].split("=")[-1] or "x") is not None)
        )
        if glue:
            out[-1] += word
        else:
            out.append(word)
    return out


def parse_quantity(text: str, param: Param) -> Value:
    """``20deg`` -> (0.349...,): ``text`` in SI units; raises :class:`BadArgument`."""
    match = _QUANTITY.match(text.strip())
    what = f"{param.name} ({param.quantity.value})"
    if match is None:
        raise BadArgument(
            f"{what}: cannot read {text!r} as a quantity (example: {_example(param)})"
        )
    numbers = tuple(float(x) for x in match["values"].split(","))
    unit = match["unit"]
    units = param.quantity.units
    if unit not in units:
        if not unit:
            raise BadArgument(
                f"{what}: {text!r} needs a unit ({', '.join(u for u in units if u)}), "
                f"for example {_example(param)}"
            )
        raise BadArgument(
            f"{what}: unknown unit {unit!r}; use "
            + (", ".join(repr(u) for u in units if u) or "a plain number")
        )
    if len(numbers) != param.size:
        raise BadArgument(
            f"{what}: needs {param.size} number{'s' if param.size > 1 else ''} "
            f"joined by commas, got {len(numbers)} in {text!r}"
        )
    if param.quantity is Quantity.JOINT and (
        numbers[0] != int(numbers[0]) or not 1 <= numbers[0] <= JOINTS
    ):
        raise BadArgument(f"{what}: a joint number is 1..{JOINTS}, got {text!r}")
    factor = units[unit]
    return tuple(x * factor for x in numbers)


def _example(param: Param) -> str:
    unit = param.quantity.default_unit
    if param.quantity is Quantity.JOINT:
        return "1"
    if param.quantity is Quantity.FRACTION:
        return "50%"
    numbers = {Quantity.LENGTH: "100", Quantity.ANGLE: "20", Quantity.TIME: "2"}.get(
        param.quantity, "1"
    )
    return ",".join([numbers] * param.size) + unit


def verb_of(name: str) -> Verb:
    """The verb named ``name``; raises :class:`UnknownCommand` with the nearest names."""
    verb = VERBS.get(name)
    if verb is not None:
        return verb
    near = difflib.get_close_matches(name, list(VERBS), n=3, cutoff=0.6)
    hint = f"; did you mean {' or '.join(near)}?" if near else ""
    if name == "status":
        hint = "; the arm's STATUS command is 'query'"
    raise UnknownCommand(f"unknown command {name!r}{hint} (commands: {', '.join(VERBS)})")


def parse_command(text: str) -> Command:
    """One line of the language -> a range-checked :class:`tcpstream.Command`.

    Raises :class:`UnknownCommand` or :class:`BadArgument` (both
    :class:`CommandSyntaxError`, a ``ValueError``).
    """
    if len(text) > MAX_LINE:
        raise BadArgument(f"a command line is at most {MAX_LINE} characters, got {len(text)}")
    words = _tokens(text)
    if not words:
        raise BadArgument("empty command")
    verb = verb_of(words[0])
    positional: list[str] = []
    keywords: dict[str, str] = {}
    flags: list[str] = []
    for word in words[1:]:
        if word in verb.flags:
            flags.append(word)
        elif "=" in word:
            key, _, value = word.partition("=")
            if key in keywords:
                raise BadArgument(f"{verb.name}: {key}= is given twice")
            keywords[key] = value
        else:
            positional.append(word)
    return _build(verb, positional, keywords, flags)


def parse_entry(entry: Mapping[str, object]) -> Command:
    """A task file's table form: ``{command = "move_joint", joint = 1, by = "20deg"}``.

    Numbers stand for unitless values; vectors may be lists of numbers
    (``s = [0, 1, 0]``) or strings with a unit (``p = "550,150,-150mm"``);
    a path's points are ``points = ["550,150,-100mm", ...]``; flags are
    ``pose_change = true``.
    """
    name = entry.get("command")
    if not isinstance(name, str):
        raise BadArgument('an entry needs command = "NAME" (a string)')
    verb = verb_of(name)
    keywords: dict[str, str] = {}
    positional: list[str] = []
    flags: list[str] = []
    for key, value in entry.items():
        if key == "command":
            continue
        if key in verb.flags:
            if not isinstance(value, bool):
                raise BadArgument(f"{verb.name}: {key} is true or false, got {value!r}")
            if value:
                flags.append(key)
        elif verb.repeated is not None and key == "points":
            if not isinstance(value, list) or not all(isinstance(p, str) for p in value):
                raise BadArgument(f'{verb.name}: points is a list of strings like "550,150,-100mm"')
            positional += value
        else:
            keywords[key] = _scalar_text(verb, key, value)
    return _build(verb, positional, keywords, flags)


def _scalar_text(verb: Verb, key: str, value: object) -> str:
    if isinstance(value, bool):
        raise BadArgument(f"{verb.name}: {key} is a quantity, not {value!r}")
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return value
    if (
        isinstance(value, list)
        and value
        and all(isinstance(x, int | float) and not isinstance(x, bool) for x in value)
    ):
        return ",".join(repr(x) for x in value)
    raise BadArgument(f"{verb.name}: {key} = {value!r} is not a quantity")


def _build(
    verb: Verb, positional: list[str], keywords: dict[str, str], flags: list[str]
) -> Command:
    names = {p.name: p for p in verb.params}
    for key in keywords:
        if key not in names:
            takes = ", ".join(f"{n}=" for n in names) or "no keywords"
            raise BadArgument(f"{verb.name}: unknown argument {key}= (it takes {takes})")
    values: dict[str, Value] = {}
    repeated: list[Value] = []
    if verb.repeated is not None:
        if not 1 <= len(positional) <= MAX_PATH_POINTS:
            raise BadArgument(
                f"{verb.name}: needs 1..{MAX_PATH_POINTS} via points, got {len(positional)} "
                f"(usage: {verb.usage()})"
            )
        repeated = [_quantity(verb, t, verb.repeated) for t in positional]
    else:
        free = [p for p in verb.params if p.name not in keywords]
        if len(positional) > len(free):
            raise BadArgument(
                f"{verb.name}: too many arguments: {' '.join(positional[len(free) :])!r} "
                f"(usage: {verb.usage()})"
            )
        for param, word in zip(free, positional, strict=False):
            keywords[param.name] = word
    for param in verb.params:
        given = keywords.get(param.name)
        if given is None:
            if not param.optional:
                raise BadArgument(
                    f"{verb.name}: missing {param.describe()} (usage: {verb.usage()}, "
                    f"example: {verb.example})"
                )
            continue
        values[param.name] = _quantity(verb, given, param)
    try:
        command = verb.build(values, flags, repeated)
        validate_arguments(command)
    except CommandFailed as exc:
        raise BadArgument(f"{verb.name}: {exc.message}") from None
    except ValueError as exc:
        raise BadArgument(f"{verb.name}: {exc}") from None
    return command


def _quantity(verb: Verb, text: str, param: Param) -> Value:
    try:
        return parse_quantity(text, param)
    except BadArgument as exc:
        raise BadArgument(f"{verb.name}: {exc.message}") from None


def _fmt(values: Sequence[float], quantity: Quantity) -> str:
    """``values`` in the quantity's readable unit (mm, deg...) when six digits hold them
    (to 1e-12), else in SI units at full precision: what is read back is what was sent."""
    unit = quantity.default_unit
    factor = quantity.units[unit]
    short = [f"{x / factor:.6g}" for x in values]
    if all(
        math.isclose(float(t) * factor, x, rel_tol=1e-12, abs_tol=1e-12)
        for t, x in zip(short, values, strict=True)
    ):
        return ",".join(short) + unit
    si = next((u for u, f in quantity.units.items() if f == 1.0), "")
    return ",".join(repr(float(x)) for x in values) + si


def format_command(command: Command) -> str:
    """``command`` as a line :func:`parse_command` reads back (mm, deg, s, N, %)."""
    verb = _BY_CODE.get(command.code)
    a = command.args
    if verb is None:  # TRANSFORM: no motion, not part of the language
        return command.code.name.lower()
    code = command.code
    L, A = Quantity.LENGTH, Quantity.ANGLE
    if code is CommandCode.MOVE_JOINT:
        return f"move_joint {int(a[0])} {_fmt(a[1:2], A)}"
    if code is CommandCode.MOVE_JOINTS:
        return f"move_joints {_fmt(a[:6], A)}"
    if code is CommandCode.MOVE_TO_POSITION:
        text = f"move_to {_fmt(a[:3], L)}"
        if len(a) >= 9 and command.flags:
            text += f" s={_fmt(a[3:6], Quantity.NUMBER)} a={_fmt(a[6:9], Quantity.NUMBER)}"
        return text
    if code is CommandCode.MOVE_CARTESIAN_DELTA:
        text = f"move_by {_fmt(a[:3], L)}"
        if any(a[3:6]):
            text += f" rot={_fmt(a[3:6], A)}"
        return text + (" pose_change" if command.flags else "")
    if code is CommandCode.MOVE_PATH:
        n = int(a[0])
        points = " ".join(_fmt(a[2 + 3 * i : 5 + 3 * i], L) for i in range(n))
        return f"path {points}" + (f" blend={_fmt(a[1:2], Quantity.TIME)}" if a[1] else "")
    if code is CommandCode.OPEN_FINGERS:
        return "open_fingers" + (f" {_fmt(a[:1], L)}" if a and a[0] else "")
    if code is CommandCode.SQUEEZE:
        return f"squeeze {_fmt(a[:1], Quantity.FORCE)}"
    if code is CommandCode.CHANGE_SPEED:
        return f"speed {_fmt(a[:1], Quantity.FRACTION)}"
    if code is CommandCode.ADD_OBSTACLE:
        return f"add_obstacle {_fmt(a[:3], L)} {_fmt(a[3:6], L)}"
    return verb.name


def complete(text: str, extra: Sequence[str] = ()) -> list[str]:
    """Completions of the last word of ``text``: a command name (or one of
    ``extra``, the console's own words) first, then its keywords, flags and units."""
    words = text.split()
    partial = "" if text.endswith(" ") or not words else words[-1]
    if len(words) == 0 or (len(words) == 1 and partial):
        return sorted(n for n in (*VERBS, *extra) if n.startswith(partial))
    verb = VERBS.get(words[0])
    if verb is None:
        return []
    options = [f"{p.name}=" for p in verb.params] + list(verb.flags)
    match = re.match(rf"^(.*?{_NUMBER})([A-Za-z%°]*)$", partial)
    if match is not None:  # a number: offer the units of the next parameter
        units = sorted(_ALL_UNITS | {"%"})
        return [match[1] + u for u in units if u.startswith(match[2])]
    return sorted(o for o in options if o.startswith(partial))
