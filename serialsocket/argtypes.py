"""Range-checked ``type=`` converters for command lines of serial-line programs.

Public so that other command lines (linksim's, yours) check their options the
same way: :class:`IntRange`, :class:`FloatRange`, :class:`SerialPortName`,
and the serialsocket command's own ranges.

A converter refuses a bad value with argparse's own error, so a typo ends in
one line naming the option and what it takes, exit status 2, before any port
is opened::

    serialsocket: error: argument --window: must be an integer in 1..31, got '0'

The converters are frozen dataclasses rather than closures so that a test can
read their bounds and try values outside them for every option of every
command (tests/test_bad_input_cli.py).
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import pkgutil
from collections.abc import Sequence
from dataclasses import dataclass

import serial

from ._config import MAX_WINDOW, MIN_ENDPOINT_PACKET_LENGTH
from ._wire import MAX_PACKET_LENGTH, MIN_PACKET_LENGTH, SEQ_MODULUS
from .kermit import MAX_KERMIT_WINDOW

__all__ = [
    "BAUD",
    "DELAY",
    "ENDPOINT_LENGTH",
    "KERMIT_LENGTH",
    "KERMIT_TIMEOUT",
    "KERMIT_WINDOW",
    "PACKET_LENGTH",
    "RETRIES",
    "SECONDS",
    "SEQ",
    "SERIAL_PORT",
    "WINDOW",
    "FloatRange",
    "IntRange",
    "PacketTypeLetter",
    "SerialPortName",
    "parse_args",
    "retype",
]


def _number(x: float) -> str:
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e15 else f"{x:g}"


@dataclass(frozen=True, slots=True)
class IntRange:
    """A decimal integer in ``lo..hi`` (``hi`` None: no upper bound)."""

    lo: int
    hi: int | None = None

    def __call__(self, text: str) -> int:
        try:
            value: int | None = int(text, 10)
        except ValueError:  # not a number, or more digits than int() takes
            value = None
        if value is None or value < self.lo or (self.hi is not None and value > self.hi):
            raise argparse.ArgumentTypeError(
                f"must be an integer in {self.describe()}, got {text!r}"
            )
        return value

    def describe(self) -> str:
        return f"{self.lo}..{self.hi}" if self.hi is not None else f">= {self.lo}"


@dataclass(frozen=True, slots=True)
class FloatRange:
    """A finite number in ``[lo, hi]`` (``(lo, hi]`` when ``lo_open``), in ``unit``."""

    lo: float
    hi: float
    lo_open: bool = False
    unit: str = ""

    def __call__(self, text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        above = value > self.lo if self.lo_open else value >= self.lo
        if not (math.isfinite(value) and above and value <= self.hi):
            what = f"a number of {self.unit}" if self.unit else "a number"
            raise argparse.ArgumentTypeError(f"must be {what} in {self.describe()}, got {text!r}")
        return value

    def describe(self) -> str:
        return f"{'(' if self.lo_open else '['}{_number(self.lo)}, {_number(self.hi)}]"


def _url_schemes() -> list[str]:
    """The URL schemes pyserial's ``serial_for_url`` can open (its protocol_NAME modules)."""
    schemes: list[str] = []
    for package in serial.protocol_handler_packages:
        spec = importlib.util.find_spec(package)
        if spec is None or spec.submodule_search_locations is None:
            continue
        for info in pkgutil.iter_modules(spec.submodule_search_locations):
            if info.name.startswith("protocol_"):
                schemes.append(info.name.removeprefix("protocol_"))
    return sorted(set(schemes))


@dataclass(frozen=True, slots=True)
class SerialPortName:
    """A device path, a pty path or a pyserial URL whose scheme pyserial knows.

    Whether the device exists is found out when it is opened (exit status 1
    or 2 by command, with the errno); this refuses what can never open.
    """

    def __call__(self, text: str) -> str:
        if not text or "\0" in text:
            raise argparse.ArgumentTypeError(
                f"must be a device path, a pty or a pyserial URL (loop://, "
                f"socket://HOST:PORT...), got {text!r}"
            )
        scheme, sep, _ = text.partition("://")
        if sep:
            known = _url_schemes()
            if scheme.lower() not in known:
                raise argparse.ArgumentTypeError(
                    f"unknown URL scheme {scheme!r} in {text!r}: give a device path or one "
                    f"of pyserial's {', '.join(s + '://' for s in known)}"
                )
        return text


@dataclass(frozen=True, slots=True)
class PacketTypeLetter:
    """A Kermit packet type: one printable character, ``!`` through ``~``."""

    def __call__(self, text: str) -> str:
        if len(text) != 1 or not 33 <= ord(text) <= 126:
            raise argparse.ArgumentTypeError(
                f"must be one printable character ! through ~ (D, Y, N...), got {text!r}"
            )
        return text


def parse_args(ap: argparse.ArgumentParser, argv: Sequence[str] | None) -> argparse.Namespace:
    """``ap.parse_args(argv)``, but an unrecognized argument is reported with
    the usage of the (innermost) subcommand it was given to, not the top
    level's: ``linksim bench goodput --bogus`` shows ``usage: linksim bench
    goodput ...``.  Exit status 2, as argparse's own errors."""
    args, extra = ap.parse_known_args(argv)
    if extra:
        parser = ap
        while True:
            subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
            chosen = getattr(args, subs[0].dest, None) if subs and subs[0].dest else None
            if not subs or chosen is None or chosen not in subs[0].choices:
                break
            parser = subs[0].choices[chosen]
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    return args


def retype(ap: argparse.ArgumentParser, types: dict[str, object]) -> None:
    """Give the options ``types`` names (by dest) these converters.

    For options another module defines with a bare ``int``/``float``; every
    name must exist, so a renamed option is noticed at once.
    """
    found = {a.dest for a in ap._actions if a.dest in types}
    missing = set(types) - found
    if missing:
        raise RuntimeError(f"no such options to type: {sorted(missing)}")
    for action in ap._actions:
        if action.dest in types:
            action.type = types[action.dest]  # type: ignore[assignment]


MAX_SECONDS = 30 * 86400.0
"""Longest timeout or duration a command takes: 30 days; more is a typo."""

MAX_DELAY = 3600.0
"""Longest one-way delay: an hour (Mars at conjunction is 22 minutes)."""

BAUD = IntRange(1, 100_000_000)
"""bit/s; far above any UART (FTDI chips top out at 12 Mbaud), so only typos are refused."""

WINDOW = IntRange(1, MAX_WINDOW)
KERMIT_WINDOW = IntRange(1, MAX_KERMIT_WINDOW)
SEQ = IntRange(0, SEQ_MODULUS - 1)
PACKET_LENGTH = IntRange(MIN_PACKET_LENGTH, MAX_PACKET_LENGTH)
"""Any Kermit packet, MARK through CHECK (the inspector's --max-len)."""
KERMIT_LENGTH = PACKET_LENGTH
ENDPOINT_LENGTH = IntRange(MIN_ENDPOINT_PACKET_LENGTH, MAX_PACKET_LENGTH)
"""A serial socket's packet limit: its init packet must fit."""
RETRIES = IntRange(0, 1000)
"""Kermit retries per packet; 0 = no limit."""
SECONDS = FloatRange(0.0, MAX_SECONDS, lo_open=True, unit="seconds")
KERMIT_TIMEOUT = FloatRange(0.0, 86399.0, lo_open=True, unit="seconds")
"""A fixed Kermit packet timeout: KermitConfig takes less than a day."""
DELAY = FloatRange(0.0, MAX_DELAY, unit="seconds")
SERIAL_PORT = SerialPortName()
