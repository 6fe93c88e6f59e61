"""Task files: your own command lists for ``linksim console`` and ``linksim control``.

A task file is TOML or JSON (by its extension).  ``commands`` lists the
commands in the operator's language (:mod:`~linksim.control._vocabulary`),
each either a line or a table::

    name = "wave"
    description = "joint 1 waves left and right, then home"
    commands = [
        "speed 80%",
        "move_joint 1 30deg",
        { command = "move_joint", joint = 1, by = "-60deg" },
        "reinitialize",
    ]

JSON is the same object (or just the list).  Every entry is parsed and
range-checked before anything is sent; the first bad one raises a
:class:`~linksim.control._vocabulary.CommandSyntaxError` whose ``where`` names
the file, the line and the entry (``wave.toml line 7, entry 3``).  A file that
is not a task file raises :class:`TaskFileError`.  ``--task rock`` still
names the built-in rock task (:func:`resolve_task`).
"""

from __future__ import annotations

import json
import pathlib
import re
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from linksim._errors import ConfigError
from linksim.arm import WorldConfig, rock_task
from tcpstream import Command

from ._vocabulary import VERBS, CommandSyntaxError, format_command, parse_command, parse_entry

__all__ = ["BUILTIN_TASKS", "TaskFile", "TaskFileError", "load_task", "parse_task", "resolve_task"]

MAX_TASK_BYTES = 1 << 20
"""A task file is read whole: a mebibyte is thousands of commands, more is not a task file."""

MAX_COMMANDS = 500
"""Commands in one task: every one is previewed (a fraction of a second each)
and tracked on the console; the rock task has eleven."""

BUILTIN_TASKS = ("rock",)
"""Names ``--task`` takes besides a file."""

_KEYS = frozenset({"name", "description", "commands"})


class TaskFileError(ConfigError):
    """A file that is not a task file (unreadable, not TOML/JSON, no ``commands`` list)."""


@dataclass(frozen=True, slots=True)
class TaskFile:
    """A parsed task: its commands, and where each came from (for messages)."""

    name: str
    commands: tuple[Command, ...]
    source: str
    """The file's name as given (``-`` for stdin; ``rock`` for the built-in)."""
    lines: tuple[int | None, ...] = ()
    """The line of each command in the file (None where it could not be found)."""
    description: str = ""

    def where(self, index: int) -> str:
        """``wave.toml line 7, entry 3`` for the command numbered ``index`` (from 1)."""
        line = self.lines[index - 1] if index - 1 < len(self.lines) else None
        at = f" line {line}," if line is not None else ""
        return f"{self.source}{at} entry {index}"

    def as_lines(self) -> list[str]:
        """The commands in the operator's language (a task file's ``commands``)."""
        return [format_command(c) for c in self.commands]


def _locate(text: str, entries: Sequence[object]) -> list[int | None]:
    """The line where each entry starts, found by scanning ``text`` in order.

    tomllib and json keep no positions; the entries appear in the file in
    order, so each is searched for after the previous one.  An entry that
    cannot be found (unusual escapes) gets None: its message names the entry
    number alone."""
    start = text.find("commands")
    cursor = max(start, 0)
    out: list[int | None] = []
    for entry in entries:
        pattern: str | None = None
        if isinstance(entry, str):
            pattern = "[\"']" + re.escape(entry) + "[\"']"
        elif isinstance(entry, dict) and isinstance(entry.get("command"), str):
            pattern = r"[\"']?command[\"']?\s*[=:]\s*[\"']" + re.escape(entry["command"])
        match = re.compile(pattern).search(text, cursor) if pattern else None
        if match is None:
            out.append(None)
            continue
        out.append(text.count("\n", 0, match.start()) + 1)
        cursor = match.end()
    return out


def _decode(text: str, source: str, fmt: str) -> Any:
    if fmt == "json":
        try:
            return json.loads(text)
        except json.JSONDecodeError as exc:
            raise TaskFileError(f"{source} line {exc.lineno}: invalid JSON: {exc.msg}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise TaskFileError(f"{source}: invalid TOML: {exc}") from None


def parse_task(text: str, source: str = "<task>", fmt: str = "toml") -> TaskFile:
    """A task from its text (``fmt`` ``toml`` or ``json``); see the module docstring."""
    data = _decode(text, source, fmt)
    if isinstance(data, list):
        data = {"commands": data}
    if not isinstance(data, dict):
        raise TaskFileError(f"{source}: a task file is a table with a commands list")
    unknown = sorted(set(data) - _KEYS)
    if unknown:
        raise TaskFileError(
            f"{source}: unknown key {unknown[0]!r} (a task file has name, description, commands)"
        )
    entries = data.get("commands")
    if not isinstance(entries, list) or not entries:
        raise TaskFileError(f"{source}: needs a non-empty commands list")
    if len(entries) > MAX_COMMANDS:
        raise TaskFileError(f"{source}: {len(entries)} commands; a task has at most {MAX_COMMANDS}")
    for key in ("name", "description"):
        if not isinstance(data.get(key, ""), str):
            raise TaskFileError(f"{source}: {key} must be a string")
    lines = _locate(text, entries)
    task = TaskFile(
        name=data.get("name") or pathlib.PurePath(source).stem,
        commands=(),
        source=source,
        lines=tuple(lines),
        description=data.get("description", ""),
    )
    commands: list[Command] = []
    for index, entry in enumerate(entries, start=1):
        try:
            if isinstance(entry, str):
                command = parse_command(entry)
            elif isinstance(entry, dict):
                command = parse_entry(entry)
            else:
                raise CommandSyntaxError(
                    f"an entry is a command line (a string) or a table, got {entry!r}"
                )
            name = entry if isinstance(entry, str) else str(entry.get("command"))
            verb = VERBS.get(name.split()[0] if name.split() else "")
            if verb is not None and not verb.in_files:
                raise CommandSyntaxError(
                    f"{verb.name} is immediate (it bypasses the queue); a task file lists "
                    "queued commands -- type it at the console instead"
                )
        except CommandSyntaxError as exc:
            exc.where = task.where(index)
            raise
        commands.append(command)
    return TaskFile(task.name, tuple(commands), source, tuple(lines), task.description)


def load_task(path: str | pathlib.Path, stdin: str | None = None) -> TaskFile:
    """Read and parse a task file (``.toml`` or ``.json``; ``-`` reads ``stdin``'s text,
    JSON when it starts with ``[`` or ``{``, else TOML)."""
    name = str(path)
    if name == "-":
        text = stdin or ""
        fmt = "json" if text.lstrip()[:1] in ("[", "{") else "toml"
        return parse_task(text, "<stdin>", fmt)
    suffix = pathlib.PurePath(name).suffix.lower()
    if suffix not in (".toml", ".json"):
        raise TaskFileError(
            f"{name}: a task file ends in .toml or .json (or give one of the built-in tasks: "
            f"{', '.join(BUILTIN_TASKS)})"
        )
    try:
        with open(name, "rb") as f:
            raw = f.read(MAX_TASK_BYTES + 1)
    except OSError as exc:
        raise TaskFileError(f"cannot read task file {name}: {exc.strerror or exc}") from None
    if len(raw) > MAX_TASK_BYTES:
        raise TaskFileError(f"{name}: larger than {MAX_TASK_BYTES} bytes; not a task file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise TaskFileError(f"{name}: not UTF-8 text") from None
    return parse_task(text, name, suffix[1:])


def resolve_task(spec: str, world: WorldConfig, stdin: str | None = None) -> TaskFile:
    """``--task``: a built-in task by name (``rock``) or a task file."""
    if spec == "rock":
        return TaskFile("rock task", rock_task(world).commands, "rock")
    return load_task(spec, stdin)
