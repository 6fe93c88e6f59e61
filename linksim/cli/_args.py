"""Range-checked ``type=`` converters shared by every ``linksim`` command.

A converter refuses a bad value with argparse's own error, so a typo ends in
one line naming the option and what it takes, exit status 2, before anything
is opened, listened on or run::

    linksim arm-server: error: argument --window: must be an integer in 1..31, got '0'

The converters are frozen dataclasses rather than closures so that a test can
read their bounds and try values outside them for every option of every
command (tests/test_bad_input_cli.py).  The converter classes are
serialsocket's public :mod:`serialsocket.argtypes`; the ranges are linksim's.
"""

from __future__ import annotations

import pathlib
import sys

from linksim.arm import DEFAULT_WORLD, WorldConfig
from serialsocket import MAX_WINDOW
from serialsocket import argtypes as serial_args
from serialsocket.argtypes import FloatRange, IntRange, SerialPortName
from serialsocket.packets import MAX_PACKET_LENGTH
from tcpstream import load_key_file

__all__ = [
    "BAUD",
    "BITS_PER_CHAR",
    "BIT_RATE",
    "COUNT",
    "DELAY",
    "ENDPOINT_LENGTH",
    "JOBS",
    "KERMIT_LENGTH",
    "MAX_DELAY",
    "MAX_SECONDS",
    "PROBABILITY",
    "SECONDS",
    "SECONDS_OR_ZERO",
    "SEED",
    "SERIAL_PORT",
    "SIZE",
    "TCP_PORT",
    "TCP_PORT_OR_ANY",
    "WINDOW",
    "FloatRange",
    "IntRange",
    "SerialPortName",
    "load_world",
    "read_key",
    "write_template",
]


MAX_SECONDS = 30 * 86400.0
"""Longest timeout or duration a command takes: 30 days; more is a typo."""

MAX_DELAY = 3600.0
"""Longest one-way delay: an hour (Mars at conjunction is 22 minutes)."""

BAUD = IntRange(1, 100_000_000)
"""bit/s of a serial port; far above any UART (FTDI chips top out at 12 Mbaud)."""
BIT_RATE = FloatRange(0.0, 1e9, lo_open=True, unit="bit/s")
"""A simulated line's rate: up to 1 Gbit/s."""
BITS_PER_CHAR = IntRange(1, 64)
"""As DirectionConfig takes (8N1 = 10)."""
WINDOW = IntRange(1, MAX_WINDOW)
ENDPOINT_LENGTH = serial_args.ENDPOINT_LENGTH
KERMIT_LENGTH = IntRange(12, MAX_PACKET_LENGTH)
"""A Kermit packet, MARK through CHECK (12: the shortest Send-Init)."""
PROBABILITY = FloatRange(0.0, 1.0)
DELAY = FloatRange(0.0, MAX_DELAY, unit="seconds")
SECONDS = FloatRange(0.0, MAX_SECONDS, lo_open=True, unit="seconds")
SECONDS_OR_ZERO = FloatRange(0.0, MAX_SECONDS, unit="seconds")
SEED = IntRange(0, 2**64 - 1)
"""Seeds are >= 0 (LinkConfig); 64 bits is plenty."""
TCP_PORT = IntRange(1, 65535)
TCP_PORT_OR_ANY = IntRange(0, 65535)
"""A port to listen on; 0 lets the system pick a free one."""
SIZE = IntRange(1, 1 << 34)
"""Bytes of a benchmark payload: up to 16 GiB."""
COUNT = IntRange(1, 1_000_000)
"""Runs, repeats, round trips, sessions."""
JOBS = IntRange(1, 256)
SERIAL_PORT = SerialPortName()


def read_key(path: str) -> bytes:
    """The pre-shared key in ``path``: :func:`tcpstream.load_key_file` (hex digits,
    ``#`` comments; a file others may read is used with a warning)."""
    return load_key_file(path)


def write_template(path: str, text: str, prog: str) -> int:
    """Write a generated configuration file for ``--write-config`` / ``--write-world``.

    ``-`` writes to stdout.  An existing file is never overwritten (it may be
    the user's edited copy).  Returns the exit status: 0 written, 1 not."""
    if path == "-":
        sys.stdout.write(text)
        return 0
    try:
        with open(path, "x", encoding="utf-8") as f:
            f.write(text)
    except FileExistsError:
        print(
            f"{prog}: {path} exists; not overwriting it (remove it, or give another name)",
            file=sys.stderr,
        )
        return 1
    except OSError as exc:
        print(f"{prog}: cannot write {path}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    print(f"{prog}: wrote {path}", file=sys.stderr)
    return 0


def load_world(arg: str | None) -> WorldConfig:
    """``--world FILE`` (``-``: TOML on stdin); the demo's table without one."""
    if arg is None:
        return DEFAULT_WORLD
    if arg == "-":
        return WorldConfig.from_toml(sys.stdin.read())
    return WorldConfig.from_toml(pathlib.Path(arg))
