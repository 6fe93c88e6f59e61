"""The console's telemetry log: every state record and command event, one JSON object a line.

Seed 004 section 4: the arm state is "logged for later analysis".  Layout
(schema :data:`SCHEMA`), every line an object with ``type`` and ``t`` (s on
the run's clock, from the start of the log):

* ``header`` (first line): ``schema``, ``world`` (TOML text), ``title``;
* ``state``: ``source`` (``telemetry`` | ``completion`` | ``predicted``) and
  the arm state (:func:`linksim.control._control.feedback_record`'s fields);
* ``command``: ``index``, ``code``, ``label``, ``event`` (``sent`` |
  ``accepted`` | ``completed`` | ``failed``), ``reason`` for a failure;
* ``divergence``: a :class:`~linksim.control._predict.Divergence` record;
* ``preview``: the plan preview's summary.

JSON lines survive a crash mid-run (every line is complete on its own) and
read with any tool; :func:`read_log` refuses other schemas.
"""

from __future__ import annotations

import json
import pathlib
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import IO, Any

from tcpstream import Feedback

from ._control import feedback_record

__all__ = ["SCHEMA", "LogContents", "TelemetryLog", "parse_log", "read_log"]

SCHEMA = 1
"""Bumped when a record changes meaning; readers refuse what they do not know."""


class TelemetryLog:
    """Appends records to a JSON-lines file.  Use as a context manager (or :meth:`close`).

    ``origin`` is the clock reading that becomes ``t = 0``.  Lines are
    flushed as written so a log of a run that dies is readable to its end.
    """

    def __init__(
        self, path: str | pathlib.Path, *, origin: float, title: str = "", world: str = ""
    ) -> None:
        self.path = pathlib.Path(path)
        self._origin = origin
        self._file: IO[str] | None = self.path.open("w", encoding="utf-8")
        self.lines = 0
        self._write({"type": "header", "t": 0.0, "schema": SCHEMA, "title": title, "world": world})

    def __enter__(self) -> TelemetryLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def state(self, now: float, source: str, feedback: Feedback) -> None:
        """An arm state: reported (``telemetry``, ``completion``) or ``predicted``."""
        self._write(
            {"type": "state", "t": self._t(now), "source": source} | feedback_record(feedback)
        )

    def command(
        self, now: float, index: int, code: str, label: str, event: str, reason: str | None = None
    ) -> None:
        """A command's step: sent, accepted, completed or failed (with the reason's name)."""
        record: dict[str, Any] = {
            "type": "command",
            "t": self._t(now),
            "index": index,
            "code": code,
            "label": label,
            "event": event,
        }
        if reason is not None:
            record["reason"] = reason
        self._write(record)

    def record(self, now: float, kind: str, data: dict[str, Any]) -> None:
        """Any other record (``divergence``, ``preview``).

        Its ``t`` is the log's, from ``origin``, whatever ``data`` holds: a
        divergence carries the clock reading it was taken at, and letting it
        win put the model's end poses of a real-time run hours off the plot's
        time axis (a virtual clock starts near 0, which hid it)."""
        self._write({**data, "type": kind, "t": self._t(now)})

    def _t(self, now: float) -> float:
        return round(now - self._origin, 4)

    def _write(self, record: dict[str, Any]) -> None:
        if self._file is None:
            raise ValueError("the telemetry log is closed")
        self._file.write(json.dumps(record, separators=(",", ":")) + "\n")
        self._file.flush()
        self.lines += 1


@dataclass(slots=True)
class LogContents:
    """A log read back: the header and the records by type, in file order."""

    header: dict[str, Any]
    states: list[dict[str, Any]] = field(default_factory=list)
    commands: list[dict[str, Any]] = field(default_factory=list)
    other: list[dict[str, Any]] = field(default_factory=list)

    def reported(self) -> list[dict[str, Any]]:
        """State records the arm reported (telemetry and completions), in time order."""
        return [s for s in self.states if s["source"] != "predicted"]


def read_log(path: str | pathlib.Path) -> LogContents:
    """Read a log; raises ``ValueError`` naming the line for anything malformed."""
    with pathlib.Path(path).open(encoding="utf-8") as f:
        return parse_log(f, str(path))


def parse_log(lines: Iterable[str], path: str = "<log>") -> LogContents:
    """Read a log from its lines (a file, stdin); ``path`` names it in errors."""
    contents: LogContents | None = None
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}:{number}: not JSON ({exc})") from None
        if not isinstance(record, dict) or "type" not in record or "t" not in record:
            raise ValueError(f"{path}:{number}: a record needs 'type' and 't'")
        kind = record["type"]
        if contents is None:
            if kind != "header":
                raise ValueError(f"{path}:{number}: the first record must be the header")
            if record.get("schema") != SCHEMA:
                raise ValueError(
                    f"{path}: schema {record.get('schema')!r}, this reader knows {SCHEMA}"
                )
            contents = LogContents(record)
        elif kind == "state":
            contents.states.append(record)
        elif kind == "command":
            contents.commands.append(record)
        else:
            contents.other.append(record)
    if contents is None:
        raise ValueError(f"{path}: empty log (no header)")
    return contents
