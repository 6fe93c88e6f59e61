"""``linksim bench transfer``: issue 21's real-time table, the netcat through ``linksim relay``.

For each row (a line: bit/s, one-way delay, byte corruption; and a profile)
a ``linksim relay`` subprocess makes the impaired line between two ptys, and
``python -m serialsocket listen`` / ``connect`` move a file of random binary
(8 KiB at 2400 bit/s, 32 KiB faster; ``size`` overrides) from connect to
listen, as a user runs them: the netcat's defaults (``--profile auto``: the
relay's pty is 8N1, so the 8-bit profile, the dense encodings offered), with
or without the line's hints (``--baud`` and ``--delay`` on both ends).

The figure is the issue's: file bytes over the wall time from starting the
sender to both exits, as a share of the line (bit/s / 10 bytes a second).  A
row delivered when both ends exited 0 and the listener wrote exactly the file.

Beside it, the theoretical limit of that line as a share, with the
definitions of :mod:`linksim.bench._transfer` (``limit = carried / wire x
(1 - P(packet hit))``, on the row's own payload), for what two netcat ends
agree on: the data encoding of a real init exchange between two endpoints
configured as the netcat configures them (the escape code on an 8-bit line,
the radix-91 packing on a printable one), the block check it agrees, and the
packet length the netcat derives (128, or longer on a fast long line when
hinted); without long sequence numbers, as there (their two characters are
a cost of the protocol's choice, like its ACKs).

Wall-clock: the shares depend on the machine and its load; rows run at once
by default, each waiting on its own line almost all the time, but each row
is three Python processes and they compete for a small machine's CPU.  Every
wait is bounded (:data:`GUARD`), and every subprocess is reaped: the relay
terminated, the ends killed if still running; on an error or Ctrl-C in the
caller, every child of the table is killed at once.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import random
import select
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import IO, Any

from serialsocket import EndpointConfig
from serialsocket.packets import (
    EIGHT_BIT_CLEAN,
    PRINTABLE,
    Encoding,
    EscapeEncoding,
    Negotiated,
    Packet,
    Radix91Encoding,
    build_corrected,
    build_packet,
    data_capacity,
)

from ._transfer import BITS_PER_CHAR, agree, packet_error_probability

__all__ = [
    "GUARD",
    "PROFILES",
    "ROWS",
    "LineLimit",
    "TransferRow",
    "line_limit",
    "netcat_config",
    "parse_row",
    "run_row",
    "run_table",
]

GUARD = 900.0
"""Seconds one row may take from starting the sender to both exits (at
least; longer for a ``size`` whose line time is over a twentieth of it):
the slowest issue row needs about 80 s, so only a hung end reaches it."""

_START_LIMIT = 120.0
"""Seconds the relay may take to report its ptys, and the listener to open
its pty: a Python start-up, slow only on a machine loaded by the other rows."""

_RELAY_STOP = 30.0
"""Seconds a terminated relay may take to exit before it is killed."""

_FAILED_GRACE = 60.0
"""Seconds the receiver may take to exit once the sender failed (it may be
waiting for a peer that is gone; the row has failed anyway)."""

_TAIL = 1500
"""Characters of an end's stderr kept in a failed row."""

PROFILES: dict[str, Encoding] = {
    "auto": EIGHT_BIT_CLEAN,
    "8bit": EIGHT_BIT_CLEAN,
    "printable": PRINTABLE,
}
"""The netcat's ``--profile`` values and the prefix profile each means on the
relay's ptys (``auto``: from the port's format, 8N1 there, so 8-bit)."""


def _number(x: float) -> str:
    """``x`` as the issue writes it: ``0``, ``1.3``, ``1e-4``."""
    if x != 0 and abs(x) < 1e-2:
        mantissa, exponent = f"{x:e}".split("e")
        return f"{mantissa.rstrip('0').rstrip('.')}e{int(exponent)}"
    return f"{x:g}"


@dataclass(frozen=True, slots=True)
class TransferRow:
    """One line of the table.

    Attributes:
        rate: line rate, bit/s (8N1: 10 bits a byte), both directions.
        delay: one-way delay, s.
        ber: probability that a byte is corrupted, each direction.
        profile: the netcat's ``--profile``: ``auto`` (its default),
            ``8bit`` or ``printable``.
        target: the issue's target share of the line, or None for a line
            that is not one of the issue's rows.
    """

    rate: int
    delay: float
    ber: float
    profile: str = "auto"
    target: float | None = None

    @property
    def spec(self) -> str:
        """``RATE/DELAY/BER/PROFILE``, as :func:`parse_row` reads it back."""
        return f"{self.rate}/{_number(self.delay)}/{_number(self.ber)}/{self.profile}"

    @property
    def default_size(self) -> int:
        """The issue's file: 8 KiB at 2400 bit/s or slower, 32 KiB faster."""
        return 8192 if self.rate <= 2400 else 32768


ROWS: tuple[TransferRow, ...] = (
    TransferRow(2400, 0.0, 0.0, "auto", 0.93),
    TransferRow(2400, 1.3, 0.0, "auto", 0.85),
    TransferRow(2400, 1.3, 1e-4, "auto", 0.80),
    TransferRow(2400, 1.3, 1e-3, "auto", 0.65),
    TransferRow(9600, 1.3, 1e-3, "auto", 0.60),
    TransferRow(2400, 1.3, 1e-4, "printable", 0.70),
)
"""Issue 21's rows and targets, numbered 1.. in this order."""


def parse_row(text: str) -> TransferRow:
    """A row from its number in :data:`ROWS` (1-based) or ``RATE/DELAY/BER[/PROFILE]``.

    A spec that names one of the issue's lines (numbers compared as values:
    ``1e-4`` and ``0.0001`` are one) is that row, with its target; any other
    well-formed line is a row of its own with no target.  PROFILE defaults to
    ``auto``.

    Raises:
        ValueError: the text is neither; the message says what is accepted.
    """
    text = text.strip()
    usage = f"give a row number 1..{len(ROWS)} or RATE/DELAY/BER[/PROFILE], e.g. 2400/1.3/1e-4/auto"
    if text.isdigit():
        index = int(text)
        if not 1 <= index <= len(ROWS):
            raise ValueError(f"no row {text}: {usage}")
        return ROWS[index - 1]
    parts = text.split("/")
    if len(parts) not in (3, 4):
        raise ValueError(f"{text!r}: {usage}")
    profile = parts[3] if len(parts) == 4 else "auto"
    if profile not in PROFILES:
        raise ValueError(f"{text!r}: PROFILE must be one of {', '.join(PROFILES)}")
    try:
        rate, delay, ber = int(parts[0]), float(parts[1]), float(parts[2])
    except ValueError:
        raise ValueError(f"{text!r}: {usage}") from None
    if not 1 <= rate <= 100_000_000:
        raise ValueError(f"{text!r}: RATE must be bit/s in 1..100000000")
    if not (math.isfinite(delay) and 0 <= delay <= 3600):
        raise ValueError(f"{text!r}: DELAY must be seconds in 0..3600")
    if not 0 <= ber <= 1:
        raise ValueError(f"{text!r}: BER must be a probability in 0..1")
    row = TransferRow(rate, delay, ber, profile)
    for known in ROWS:
        if replace(known, target=None) == row:
            return known
    return row


# -- the theoretical limit -----------------------------------------------------------


@dataclass(frozen=True, slots=True)
class LineLimit:
    """The theoretical limit of a row's line for what the two ends agree on.

    Attributes:
        max_packet_length: the packet length of the limit, MARK through CHECK: the
            best of those the sender may choose (serialsocket/PROTOCOL.md 4.7).
        encoding: the agreed data encoding: ``escape``, ``radix-91`` or
            ``prefix`` (classic Kermit prefixing, a peer without ``dense``).
        check: the agreed block check (``CRC16``, ``CRC32``, ...).
        carried: mean payload bytes a full data packet carries.
        wire: mean line bytes it occupies (MARK through CHECK, and the EOL).
        packet_error: probability that a full packet has a damaged byte.
        share: the limit as a share of the line,
            ``carried / wire x (1 - packet_error)``.
    """

    max_packet_length: int
    encoding: str
    check: str
    carried: float
    wire: float
    packet_error: float
    share: float


def netcat_config(
    row: TransferRow, *, hints: bool, dense: bool = True, correction: bool = True
) -> EndpointConfig:
    """The configuration ``serialsocket listen``/``connect`` builds for ``row``
    on a relay pty: the netcat's defaults (window, packet length derived from
    the hints), its profile as the pty resolves it (:data:`PROFILES`), the
    dense encodings offered unless ``dense`` is False (``--no-dense``), a
    first flight sent, corrected data packets offered unless ``correction``
    is False, and with ``hints`` the line's rate and delay."""
    return EndpointConfig(
        encoding=PROFILES[row.profile],
        dense=dense,
        one_way_delay=row.delay if hints else 0.0,
        line_rate=float(row.rate) if hints else None,
        max_packet_time=None,  # the netcat's default: no cap for a byte stream
        first_flight=True,  # as the netcat sends it
        correction=correction,  # likewise
    )


def _encoding_name(agreed: Negotiated) -> str:
    if isinstance(agreed.encoding, EscapeEncoding):
        return "escape"
    if isinstance(agreed.encoding, Radix91Encoding):
        return "radix-91"
    return "prefix"


def line_limit(
    row: TransferRow,
    payload: bytes,
    *,
    hints: bool = False,
    dense: bool = True,
    correction: bool = True,
) -> LineLimit:
    """The theoretical limit of ``row`` for ``payload`` (module docstring).

    The payload is cut into data fields exactly as the sender cuts it with
    the agreed encoding, check and length; the last (possibly short) packet
    is left out unless it is the only one, and errors are independent
    (:func:`~linksim.bench._transfer.packet_error_probability`), as in
    :func:`~linksim.bench._transfer.limit_goodput`, which gives the same
    figure for a classic peer (``dense=False, correction=False``).  With
    corrected data packets agreed (``correction``, as the netcat offers
    them) each length is also tried as ``d`` packets: their sums' characters
    come out of the data, and a packet is lost only to damage the sums cannot
    repair (:func:`_unrepaired`).

    Raises:
        ValueError: ``payload`` is empty.
    """
    if not payload:
        raise ValueError("the limit is measured on a payload: it cannot be empty")
    config = netcat_config(row, hints=hints, dense=dense, correction=correction)
    # The sender measures its packet length (serialsocket/PROTOCOL.md 4.7):
    # the limit is the best of the lengths it may choose.
    # With corrected data packets agreed it chooses the form too (15.5).
    forms = (False, True) if agree(config).correction else (False,)
    return max(
        (
            _limit_at(row, payload, config, length, sums=sums)
            for length in config.packet_lengths()
            for sums in forms
        ),
        key=lambda limit: limit.share,
    )


def _limit_at(
    row: TransferRow, payload: bytes, config: EndpointConfig, length: int, *, sums: bool
) -> LineLimit:
    agreed = agree(replace(config, max_packet_length=length, long_window=None))
    capacity = data_capacity(agreed.send_max_length, agreed.check)
    if sums:
        # The sums' characters come out of the data (PROTOCOL.md 15.2).
        capacity -= len(build_corrected(0, b"x" * capacity, agreed.check)) - length - 1
    fields = agreed.encoding.encode_fields(payload, capacity, 1 << 30)
    full = fields[:-1] or fields
    carried = sum(used for _, used in full) / len(full)
    if sums:
        packets = [build_corrected(0, field, agreed.check) for field, _ in full]
    else:
        packets = [build_packet(Packet(seq=0, type="D", data=f), agreed.check) for f, _ in full]
    wire = sum(len(p) for p in packets) / len(packets)
    if sums:
        p_hit = sum(_unrepaired(p, int(agreed.check), row.ber) for p in packets) / len(packets)
    else:
        p_hit = packet_error_probability(wire, row.ber)
    return LineLimit(
        max_packet_length=agreed.send_max_length,
        encoding=_encoding_name(agreed) + ("+sums" if sums else ""),
        check=agreed.check.name,
        carried=carried,
        wire=wire,
        packet_error=p_hit,
        share=carried / wire * (1.0 - p_hit),
    )


def _unrepaired(wire: bytes, check_length: int, q: float) -> float:
    """Probability that the ``d`` packet ``wire`` (MARK through CR) is lost at
    independent byte damage ``q``: damage to MARK, the header, the check or
    the CR, or two damaged characters in one block of the rest (the sums'
    blocks, PROTOCOL.md 15.2: character ``i`` of LEN onwards in block ``i mod
    m``; the sums' own characters spread over the blocks likewise)."""
    header = 7 if wire[1] == 32 else 4
    fixed = header + check_length + 1
    rest = len(wire) - fixed
    m = max(1, -(-(len(wire) - 2 - check_length) // 258))
    intact = 1.0 - q
    survive = intact**fixed
    for j in range(m):
        n = rest // m + (1 if j < rest % m else 0)
        survive *= intact**n + n * q * intact ** max(n - 1, 0)
    return 1.0 - survive


# -- running a row ------------------------------------------------------------------------


class _RowFailed(Exception):
    """This row could not run to the end (a start-up failure, a hung end, a cancel)."""


class _Children:
    """Every subprocess the table started and has not reaped, so that an error
    or a Ctrl-C in the caller can kill them all at once; after :meth:`kill_all`
    no new one starts."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._live: set[subprocess.Popen[bytes]] = set()
        self._closed = False

    def start(self, argv: list[str], **kwargs: Any) -> subprocess.Popen[bytes]:
        """Start ``argv`` (``subprocess.Popen`` keywords); it stays registered until
        :meth:`reap`.  Raises ``_RowFailed`` once the table is being torn down."""
        with self._lock:
            if self._closed:
                raise _RowFailed("cancelled")
            proc: subprocess.Popen[bytes] = subprocess.Popen(argv, **kwargs)
            self._live.add(proc)
            return proc

    def reap(self, proc: subprocess.Popen[bytes], *, terminate: bool = False) -> None:
        """End ``proc`` if it still runs (SIGTERM first with ``terminate``, then
        SIGKILL), wait for it and forget it."""
        if proc.poll() is None:
            if terminate:
                proc.terminate()
                with contextlib.suppress(subprocess.TimeoutExpired):
                    proc.wait(timeout=_RELAY_STOP)
            if proc.poll() is None:
                proc.kill()
        proc.wait()
        with self._lock:
            self._live.discard(proc)

    def kill_all(self) -> None:
        """Kill every live child now; refuse new ones from here on."""
        with self._lock:
            self._closed = True
            for proc in self._live:
                with contextlib.suppress(OSError):
                    proc.kill()


def _python(*args: str) -> list[str]:
    return [sys.executable, "-m", *args]


def _ptys(relay: subprocess.Popen[bytes], deadline: float) -> dict[str, str]:
    """The relay's ``{"a": PATH, "b": PATH}`` line, read by then at the latest."""
    assert relay.stdout is not None
    fd = relay.stdout.fileno()
    got = b""
    while b"\n" not in got:
        left = deadline - time.monotonic()
        if left <= 0:
            raise _RowFailed(f"the relay did not report its ptys within {_START_LIMIT:.0f} s")
        readable, _, _ = select.select([fd], [], [], min(left, 1.0))
        if readable:
            chunk = os.read(fd, 4096)
            if not chunk:
                raise _RowFailed(f"the relay exited (status {relay.wait()}) before its ptys")
            got += chunk
    paths = json.loads(got.split(b"\n", 1)[0])
    if not isinstance(paths, dict) or not {"a", "b"} <= paths.keys():
        raise _RowFailed(f"the relay reported {paths!r}, not its two ptys")
    return {"a": str(paths["a"]), "b": str(paths["b"])}


def _wait_until_open(proc: subprocess.Popen[bytes], path: str, deadline: float) -> None:
    """Return once ``proc`` has the tty ``path`` open (Linux's /proc), so the
    clock starts with a listener that is there."""
    target = os.path.realpath(path)
    fds = Path(f"/proc/{proc.pid}/fd")
    while time.monotonic() < deadline and proc.poll() is None:
        with contextlib.suppress(OSError):
            if any(os.path.realpath(fd) == target for fd in fds.iterdir()):
                return
        time.sleep(0.01)
    status = proc.poll()
    why = f"exited with status {status}" if status is not None else "timed out"
    raise _RowFailed(f"the listener did not open {path} ({why})")


def _wait(proc: subprocess.Popen[bytes], name: str, deadline: float, guard: float) -> int:
    try:
        return proc.wait(timeout=max(deadline - time.monotonic(), 0.0))
    except subprocess.TimeoutExpired:
        raise _RowFailed(f"{name} still running after {guard:.0f} s") from None


def _text(path: Path) -> str:
    with contextlib.suppress(OSError):
        return path.read_bytes().decode(errors="replace")
    return ""


def _connect_stats(path: Path) -> dict[str, Any]:
    """The sender's ``--json`` counters (its last JSON line on stderr), or {}."""
    for line in reversed(_text(path).splitlines()):
        if line.startswith("{"):
            with contextlib.suppress(ValueError):
                record = json.loads(line)
                if isinstance(record, dict):
                    return record
    return {}


def _guard(row: TransferRow, size: int) -> float:
    return max(GUARD, 20 * size / (row.rate / BITS_PER_CHAR))


def _transfer(
    row: TransferRow,
    seed: int,
    *,
    hints: bool,
    size: int,
    work: Path,
    children: _Children,
) -> tuple[float, int, int]:
    """One transfer of ``work/src`` into ``work/out``: ``(seconds, connect exit,
    listen exit)``; every process it started is reaped on the way out."""
    options = [] if row.profile == "auto" else ["--profile", row.profile]  # auto: the default
    if hints:
        options += ["--baud", str(row.rate), "--delay", repr(row.delay)]
    guard = _guard(row, size)
    relay_argv = _python("linksim", "relay", "--json", "--seed", str(seed))
    relay_argv += ["--rate", str(row.rate), "--delay", repr(row.delay), "--ber", repr(row.ber)]
    with contextlib.ExitStack() as stack:

        def opened(name: str, mode: str) -> IO[bytes]:
            return stack.enter_context(open(work / name, mode))

        relay_err, listen_err, connect_err = (
            opened(n, "wb") for n in ("relay", "listen", "connect")
        )
        source, sink, empty = opened("src", "rb"), opened("out", "wb"), opened("empty", "wb+")
        relay = children.start(
            relay_argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=relay_err
        )
        assert relay.stdout is not None
        stack.callback(relay.stdout.close)  # after the relay is reaped (last in, first out)
        stack.callback(children.reap, relay, terminate=True)
        paths = _ptys(relay, time.monotonic() + _START_LIMIT)
        listener = children.start(
            _python("serialsocket", "listen", paths["b"], *options),
            stdin=empty,
            stdout=sink,
            stderr=listen_err,
        )
        stack.callback(children.reap, listener)
        _wait_until_open(listener, paths["b"], time.monotonic() + _START_LIMIT)
        start = time.monotonic()
        connect = children.start(
            _python("serialsocket", "connect", paths["a"], *options, "--json"),
            stdin=source,
            stdout=subprocess.DEVNULL,
            stderr=connect_err,
        )
        stack.callback(children.reap, connect)
        deadline = start + guard
        connect_exit = _wait(connect, "the sender (connect)", deadline, guard)
        if connect_exit != 0:
            deadline = min(deadline, time.monotonic() + _FAILED_GRACE)
        listen_exit = _wait(listener, "the receiver (listen)", deadline, guard)
        return time.monotonic() - start, connect_exit, listen_exit


def _record(
    row: TransferRow, seed: int, *, hints: bool, size: int, index: int | None, limit: LineLimit
) -> dict[str, Any]:
    """A row's record before it runs: what it is, its limit, nothing measured."""
    return {
        "row": index,
        "spec": row.spec,
        "rate": row.rate,
        "delay": row.delay,
        "ber": row.ber,
        "profile": row.profile,
        "seed": seed,
        "hints": hints,
        "bytes": size,
        "ok": False,
        "seconds": None,
        "line_share": None,
        "limit_share": round(limit.share, 4),
        "ratio_to_limit": None,
        "target": row.target,
        "meets_target": False if row.target is not None else None,
        "max_packet_len": limit.max_packet_length,
        "encoding": limit.encoding,
        "check": limit.check,
        "packet_error_probability": round(limit.packet_error, 6),
        "connect_exit": None,
        "listen_exit": None,
    }


def run_row(
    row: TransferRow,
    seed: int,
    *,
    hints: bool = False,
    size: int | None = None,
    index: int | None = None,
) -> dict[str, Any]:
    """Run one transfer of the table and return its JSON record.

    Args:
        row: the line and profile.
        seed: seeds the file's bytes and the relay's impairments.
        hints: give both ends ``--baud`` and ``--delay``.
        size: file bytes (default :attr:`TransferRow.default_size`).
        index: the row's number in the table, recorded as ``row``.

    Returns:
        The row's line, profile, seed, ``bytes``; ``ok`` (delivered: both
        ends exited 0 and the file arrived byte-exact); ``seconds`` (sender
        start to both exits; None if it did not run to the end),
        ``line_share`` and ``ratio_to_limit`` (None unless ok),
        ``limit_share`` and the agreement it assumes, ``target`` and
        ``meets_target``, the ends' exit statuses and the sender's
        counters; a failed row also has ``error`` and the ends' stderr.
    """
    return _run_row(row, seed, hints=hints, size=size, index=index, children=_Children())


def _run_row(
    row: TransferRow,
    seed: int,
    *,
    hints: bool,
    size: int | None,
    index: int | None,
    children: _Children,
) -> dict[str, Any]:
    """:func:`run_row` with the table's registry of children."""
    size = row.default_size if size is None else size
    data = random.Random(seed).randbytes(size)
    limit = line_limit(row, data, hints=hints)
    record = _record(row, seed, hints=hints, size=size, index=index, limit=limit)
    with tempfile.TemporaryDirectory(prefix="linksim-transfer-") as tmp:
        work = Path(tmp)
        (work / "src").write_bytes(data)
        try:
            seconds, connect_exit, listen_exit = _transfer(
                row, seed, hints=hints, size=size, work=work, children=children
            )
        except (_RowFailed, OSError) as exc:
            record["error"] = str(exc)
        else:
            got = (work / "out").read_bytes()
            ok = got == data and connect_exit == 0 and listen_exit == 0
            share = size / seconds / (row.rate / BITS_PER_CHAR)
            record.update(
                ok=ok,
                seconds=round(seconds, 1),
                connect_exit=connect_exit,
                listen_exit=listen_exit,
            )
            if ok:
                record.update(
                    line_share=round(share, 3),
                    ratio_to_limit=round(share / limit.share, 3),
                    meets_target=None if row.target is None else share >= row.target,
                )
            else:
                record["error"] = (
                    f"exits {connect_exit} (connect) and {listen_exit} (listen), "
                    f"{len(got)} of {size} bytes written"
                    + ("" if got == data[: len(got)] else ", not the file's")
                )
        stats = _connect_stats(work / "connect")
        for key in (
            "retransmissions",
            "timeouts",
            "wire_bytes_sent",
            "packets_sent",
            "corrected_sent",
            "repairs_sent",
        ):
            record[key] = stats.get(key)
        if not record["ok"]:
            record["connect_stderr"] = _text(work / "connect")[-_TAIL:]
            record["listen_stderr"] = _text(work / "listen")[-_TAIL:]
            record["relay_stderr"] = _text(work / "relay")[-_TAIL:]
    return record


def run_table(
    rows: Sequence[tuple[int | None, TransferRow]],
    seeds: Sequence[int],
    *,
    hints: bool = False,
    size: int | None = None,
    jobs: int | None = None,
    on_row: Callable[[dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """Run every row with every seed, ``jobs`` transfers at a time (default: all).

    Args:
        rows: ``(number in the table or None, row)`` pairs.
        on_row: called with each record in table order (rows, then seeds),
            as soon as it and those before it are done.

    Returns:
        The records of :func:`run_row`, in the same order.

    On any exception in the caller's thread (Ctrl-C included), every
    subprocess still running is killed, the running rows end, the queued
    ones never start, and the exception propagates.
    """
    runs = [(index, row, seed) for index, row in rows for seed in seeds]
    if not runs:
        return []
    children = _Children()
    pool = ThreadPoolExecutor(
        max_workers=min(jobs or len(runs), len(runs)), thread_name_prefix="linksim-transfer"
    )
    records: list[dict[str, Any]] = []
    try:
        for record in pool.map(
            lambda run: _run_row(
                run[1], run[2], hints=hints, size=size, index=run[0], children=children
            ),
            runs,
        ):
            records.append(record)
            if on_row is not None:
                on_row(record)
    except BaseException:
        children.kill_all()
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    return records
