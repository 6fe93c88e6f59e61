"""The goodput grid: points, payloads, steady-state sizing, named sweeps, rows.

The full cross product of the issue's factors is about 11 000 points, most of
which answer no question.  The grid is instead a set of *named sweeps*, each
answering one (see :data:`SWEEPS`); a point that several sweeps share runs once
and its row lists every sweep it belongs to.  The base point is the paper's
line with the stack's defaults: 2400 bit/s, 1.3 s one way, byte error rate
1e-4, the default window, 128-byte packets, random binary, printable profile.

Each point transfers enough data to reach steady state (:func:`steady_size`):
at least 50 round trips (the pipe fills within one, so the start-up costs at
most ~2 %), at least 40 expected packet errors (so the recovery cost is
averaged over many losses, not one or two lucky ones), at least 400 packets;
and at most about 600 kB on the line (at least 100 packets), which bounds the
CPU time of a point to a few seconds.
"""

from __future__ import annotations

import hashlib
import hmac
import math
import multiprocessing
import os
import random
import struct
import sys
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace
from typing import Any

from linksim.link import GilbertElliott
from serialsocket import EndpointConfig

from ._codec import sample_payload
from ._transfer import (
    BENCH_BURST,
    BITS_PER_CHAR,
    HINTS,
    PROFILES,
    hinted,
    limit_goodput,
    mean_byte_error_rate,
    packet_error_probability,
    packet_sizes,
    simulate,
)

__all__ = [
    "BASE",
    "DEFAULT_SWEEPS",
    "QUICK",
    "ROW_KEYS",
    "SWEEPS",
    "Point",
    "auto_packet_length",
    "build_grid",
    "command_records",
    "default_window",
    "make_payload",
    "run_grid",
    "run_point",
    "steady_size",
]

RATES = (1200, 2400, 9600, 19200)
DELAYS = (0.0, 0.27, 1.3, 2.5)
BERS = (0.0, 1e-5, 1e-4, 1e-3)
WINDOWS = (1, 4, 8, 16, 31)
LENGTHS = (94, 128, 512, 2048)
LENGTHS_FINE = (94, 128, 256, 512, 1024, 2048)
"""The issue's lengths plus 256 and 1024: the best length at 1e-4 and 1e-5
falls between them, and the packet-length sweep must show where."""
PAYLOADS = ("binary", "text", "commands")

ROW_KEYS = (
    "baud",
    "one_way_delay_s",
    "byte_error_rate",
    "burst",
    "window",
    "max_packet_len",
    "payload",
    "payload_bytes",
    "seconds",
    "goodput_Bps",
    "line_Bps",
    "efficiency",
    "limit_efficiency",
    "ratio_to_limit",
)
"""The keys every row has, in this order (the issue's contract); extras follow."""

COMMAND_RECORD = 216
"""Bytes per command record (see :func:`command_records`)."""

_WIRE_BUDGET = 600_000
"""Most line bytes (at the limit rate) one point is sized for: ~2 s of CPU."""


def default_window() -> int:
    """The window an :class:`~serialsocket.EndpointConfig` uses when none is given."""
    return EndpointConfig().window


@dataclass(frozen=True, slots=True)
class Point:
    """One configuration to measure.

    Attributes:
        baud: line rate, bit/s (8N1, 10 bits per byte).
        delay: one-way delay, s (both directions).
        ber: independent byte error rate, both directions.
        burst: add the Gilbert-Elliott burst case (:data:`BENCH_BURST`).
        window: configured window (both ends).
        max_len: maximum packet length, MARK through CHECK (both ends).
        payload: ``binary`` (uniform random), ``text`` or ``commands``.
        profile: ``printable`` or ``8bit``.
        auto_len: ``max_len`` was chosen by :func:`auto_packet_length`.
        size: payload bytes, or None for :func:`steady_size`.
        seed: seeds the payload and the line's impairments.
        hints: what both ends are told about the line (:data:`HINTS`):
            ``exact``, ``none`` or one value 10x off.
        dense: both ends offer the dense encodings (serialsocket/PROTOCOL.md
            section 10, as the netcat does; the library's default is not to).
        derived_len: the user's default: no length is configured, the
            endpoints measure it (serialsocket/PROTOCOL.md 4.7) starting
            from ``max_len``, the length they derive from their hints, and
            the limit is that of the best length they may choose.
    """

    baud: int
    delay: float
    ber: float
    burst: bool
    window: int
    max_len: int
    payload: str = "binary"
    profile: str = "printable"
    auto_len: bool = False
    size: int | None = None
    seed: int = 1
    hints: str = "exact"
    derived_len: bool = False
    dense: bool = False


# -- payloads --------------------------------------------------------------------


def command_records(size: int, seed: int = 1) -> bytes:
    """A stream of fixed-size manipulator command records (``size`` bytes, cut to fit).

    Each 216-byte record, big-endian, is what a controller streams to the arm
    (seed 000's command and eighteen-word argument array): a 16-byte header
    (magic ``TLCP``, version, kind, command code, request id, counter), a
    float64 timestamp, eighteen float64 arguments (six joint angles on a slow
    random walk, gripper opening, position P, approach S and A vectors, speed
    fraction, mode), a 16-byte feedback block (status, error, tactile bits)
    and a 32-byte HMAC-SHA256 tag.  The floats and the tag make it mostly
    binary with long runs of near-constant high bytes, unlike uniform noise.
    """
    rng = random.Random(seed)
    key = rng.randbytes(32)
    joints = [rng.uniform(-math.pi, math.pi) for _ in range(6)]
    out = bytearray()
    n = 0
    while len(out) < size:
        joints = [j + rng.gauss(0.0, 0.002) for j in joints]
        grip = 0.04 + 0.03 * math.sin(n / 50)
        pos = [0.4 + 0.1 * math.cos(joints[0]), 0.1 * math.sin(joints[1]), 0.5 + 0.01 * n % 0.2]
        s_vec = [math.cos(joints[3]), math.sin(joints[3]), 0.0]
        a_vec = [0.0, 0.0, -1.0]
        args = [*joints, grip, *pos, *s_vec, *a_vec, 0.25, float(n % 3)]
        header = struct.pack(">4sBBHII", b"TLCP", 1, 1, 10 + n % 7, 1000 + n, n)
        body = header + struct.pack(">d18d", 0.05 * n, *args)
        body += struct.pack(">IIQ", 0, 0, rng.getrandbits(6))
        body += hmac.new(key, body, hashlib.sha256).digest()
        assert len(body) == COMMAND_RECORD
        out += body
        n += 1
    return bytes(out[:size])


def make_payload(kind: str, size: int, seed: int = 1) -> bytes:
    """Deterministic payload of a kind: ``binary``, ``text`` or ``commands``."""
    if kind == "commands":
        return command_records(size, seed)
    return sample_payload(kind, size, seed)


# -- sizing and the packet-length policy -------------------------------------------


def _round_trip(baud: float, delay: float, max_len: int) -> float:
    """Physical round trip of a full packet and its 10-byte ACK, s."""
    return 2 * delay + (max_len + 1 + 10) * BITS_PER_CHAR / baud


def steady_size(point: Point) -> int:
    """Payload bytes that bring this point to steady state (module docstring)."""
    sample = make_payload(point.payload, 32 * 1024, point.seed)
    carried, wire = packet_sizes(sample, PROFILES[point.profile], point.max_len)
    p_hit = packet_error_probability(wire, point.ber, BENCH_BURST if point.burst else None)
    tx = wire * BITS_PER_CHAR / point.baud
    packets = max(400.0, 50 * _round_trip(point.baud, point.delay, point.max_len) / tx)
    if p_hit > 0:
        packets = max(packets, 40 / p_hit)
    packets = min(packets, max(100.0, _WIRE_BUDGET / wire / max(1 - p_hit, 0.05)))
    return int(packets * carried)


def auto_packet_length(
    baud: float,
    delay: float,
    ber: float,
    *,
    window: int,
    profile: str = "printable",
    burst: bool = False,
    lengths: Sequence[int] = LENGTHS_FINE,
) -> int:
    """The packet length a user should configure for this line: model-predicted best.

    For each candidate length the predicted goodput is the theoretical limit
    (header overhead against the chance of a hit, on random binary) times the
    share of time the window keeps the line busy:

    * the window must cover one round trip, or the line idles: share
      ``window x tx / rtt``;
    * selective repeat repairs a loss in about two round trips plus the two
      packets queued ahead of the resend (the NAK comes back after one round
      trip, the resend is acknowledged after another); a window shorter than
      that stalls for the difference, once per lost packet.

    Short packets win when errors are frequent (less to resend, fewer hits);
    long packets win when the window, capped at 31 packets, is short of the
    repair horizon in time, i.e. on fast long-delay lines.
    """
    sample = sample_payload("binary", 16 * 1024, 1)
    best_len, best = lengths[0], -1.0
    for length in lengths:
        carried, wire = packet_sizes(sample, PROFILES[profile], length)
        p_hit = packet_error_probability(wire, ber, BENCH_BURST if burst else None)
        tx = wire * BITS_PER_CHAR / baud
        rtt = _round_trip(baud, delay, length)
        busy = min(1.0, window * tx / rtt)
        stall = max(0.0, 2 * rtt + 2 * tx - window * tx)
        predicted = carried / wire * (1 - p_hit) * busy / (1 + p_hit * stall / tx)
        if predicted > best * 1.01:  # prefer the shorter length on a near-tie
            best_len, best = length, predicted
    return best_len


# -- the grid ------------------------------------------------------------------------


def _base() -> Point:
    return Point(baud=2400, delay=1.3, ber=1e-4, burst=False, window=default_window(), max_len=128)


BASE = _base()
"""The base point (module docstring), with the window default of this build."""

_ERRORS: tuple[tuple[float, bool], ...] = (*((b, False) for b in BERS), (0.0, True))
"""The error axis: the independent byte error rates, then the burst case."""


def _windows() -> tuple[int, ...]:
    d = default_window()
    return WINDOWS if d in WINDOWS else (*WINDOWS, d)


def _auto(p: Point) -> Point:
    length = auto_packet_length(
        p.baud, p.delay, p.ber, window=p.window, profile=p.profile, burst=p.burst
    )
    return replace(p, max_len=length, auto_len=True)


def _sweep_ofat() -> Iterable[Point]:
    """One factor at a time around the base point."""
    b = BASE
    yield b
    yield from (replace(b, baud=r) for r in RATES)
    yield from (replace(b, delay=d) for d in DELAYS)
    yield from (replace(b, ber=e, burst=g) for e, g in _ERRORS)
    yield from (replace(b, window=w) for w in _windows())
    yield from (replace(b, max_len=n) for n in LENGTHS)


def _sweep_delay_window() -> Iterable[Point]:
    """The delay plot: delay x window at 2400 and 9600 bit/s, 1e-4."""
    for r in (2400, 9600):
        for w in _windows():
            for d in DELAYS:
                yield replace(BASE, baud=r, delay=d, window=w)
        for d in DELAYS:
            yield _auto(replace(BASE, baud=r, delay=d, window=31))


def _sweep_ber_window() -> Iterable[Point]:
    """The error-rate plot: error rate x window at 2400 and 9600 bit/s, 1.3 s."""
    for r in (2400, 9600):
        for w in _windows():
            for e, g in _ERRORS:
                yield replace(BASE, baud=r, ber=e, burst=g, window=w)
        for e, g in _ERRORS:
            yield _auto(replace(BASE, baud=r, ber=e, burst=g, window=31))


def _sweep_targets() -> Iterable[Point]:
    """The issue's target rows (delay <= 1.3 s, BER <= 1e-4, 2400 and 9600, default
    window, 128), then the same rows with window 31 and with window 31 and the
    automatic packet length, to show what each change buys."""
    rows = [
        replace(BASE, baud=r, delay=d, ber=e)
        for r in (2400, 9600)
        for d in (0.0, 0.27, 1.3)
        for e in (0.0, 1e-5, 1e-4)
    ]
    yield from rows
    yield from (replace(p, window=31) for p in rows)
    yield from (_auto(replace(p, window=31)) for p in rows)


def _sweep_paper() -> Iterable[Point]:
    """The paper's configuration (stop-and-wait, 128) over delay and error rate."""
    for r in (2400, 9600):
        for d in DELAYS:
            for e, g in _ERRORS:
                yield replace(BASE, baud=r, delay=d, ber=e, burst=g, window=1)


def _sweep_length_ber() -> Iterable[Point]:
    """Packet length x error rate at window 31 (so the window does not hide the
    length's own cost), 1.3 s, at every rate: decides the length policy."""
    for r in RATES:
        for e, g in _ERRORS:
            for n in LENGTHS_FINE:
                yield replace(BASE, baud=r, ber=e, burst=g, window=31, max_len=n)
            yield _auto(replace(BASE, baud=r, ber=e, burst=g, window=31))


def _sweep_profile_payload() -> Iterable[Point]:
    """Both profiles x every payload kind at the base point, default window and 31."""
    for w in (default_window(), 31):
        for prof in PROFILES:
            for kind in PAYLOADS:
                yield replace(BASE, window=w, profile=prof, payload=kind)


PEER_SEEDS = 8
"""Seeds per configuration of the peers sweep: an 8 KiB file is only 10 to 60
packets, so one or two unlucky losses swing a single run by 20 %; the summary
averages the seeds."""


def _sweep_peers() -> Iterable[Point]:
    """The real-peer reference line (2400, 1.3 s, 1e-4, 8 KiB random binary files),
    both profiles, at the default window, window 31 and C-Kermit's choices, each
    over :data:`PEER_SEEDS` seeds."""
    for prof in PROFILES:
        for w, n in ((default_window(), 128), (31, 128), (2, 1000), (31, 256), (31, 512)):
            for seed in range(1, PEER_SEEDS + 1):
                yield replace(BASE, window=w, max_len=n, profile=prof, size=8192, seed=seed)


def _sweep_rate_window() -> Iterable[Point]:
    """Window x rate at 1.3 s, 1e-4: where the window runs out as the line speeds up."""
    for r in RATES:
        for w in _windows():
            yield replace(BASE, baud=r, window=w)
        yield _auto(replace(BASE, baud=r, window=31))


def _user_config(point: Point) -> EndpointConfig:
    """The configuration of a user who gives nothing but the hints."""
    delay, rate = hinted(point.hints, point.delay, point.baud)
    return EndpointConfig(
        one_way_delay=delay,
        line_rate=rate,
        bits_per_char=BITS_PER_CHAR,
        window=point.window,
        encoding=PROFILES[point.profile],
        dense=point.dense,
    )


def derived_point(point: Point) -> Point:
    """``point`` as a user who configures nothing but the hints runs it: the
    packet length measured, starting where the hints put it."""
    cfg = _user_config(point)
    return replace(point, max_len=cfg.derived_max_packet_length(), derived_len=True)


def _best_limit(
    point: Point, payload: bytes, burst: GilbertElliott | None
) -> tuple[float, float, int]:
    """``(limit, packet error probability, length)`` at the length a measuring
    sender may choose whose limit is highest (the peer's receive limit, and
    ``max_packet_time`` at the line's real rate, bound the candidates)."""
    lengths = _user_config(point).packet_lengths(rate=point.baud / BITS_PER_CHAR)
    return max(
        (
            (
                *limit_goodput(
                    payload,
                    rate=point.baud,
                    max_len=n,
                    encoding=PROFILES[point.profile],
                    byte_error_rate=point.ber,
                    burst=burst,
                    dense=point.dense,
                ),
                n,
            )
            for n in lengths
        ),
        key=lambda best: best[0],
    )


RANGE_DELAYS = (0.0, 1.3, 5.0, 20.0, 60.0, 300.0, 1200.0)
"""One-way delays of the delay-range sweep: a room, the Moon, far relays, Mars."""

_RANGE_ROUND_TRIPS = 20
"""Round trips of line time a delay-range point moves (at least): at long
delays the last byte's own delay and the repair of the last losses are a
round trip or two, so a transfer of a few round trips measures them, not
the line."""

_RANGE_MAX_BYTES = 24_000_000
"""Most payload bytes of one delay-range point (CPU: about six minutes).
Only 9600 bit/s at 1200 s one way reaches it: its 20 round trips are 23 MB.
At 12 MB it moved 10, and the last losses' repair (a round trip: a packet
lost in the last window is known lost a round trip after it left) weighed
twice as much: 0.883 of the limit at 1e-4, 0.934 at 24 MB."""


def _range_size(point: Point) -> int:
    rtt = 2 * point.delay + 1.0
    want = int(_RANGE_ROUND_TRIPS * rtt * point.baud / BITS_PER_CHAR / 2)
    return max(steady_size(point), min(want, _RANGE_MAX_BYTES))


def _sweep_delay_range() -> Iterable[Point]:
    """The issue's delay range at the defaults (window 31, derived packet length)."""
    for baud in (2400, 9600):
        for delay in RANGE_DELAYS:
            for ber, burst in ((0.0, False), (1e-4, False), (1e-4, True)):
                p = derived_point(replace(BASE, baud=baud, delay=delay, ber=ber, burst=burst))
                yield replace(p, size=_range_size(p))


HINT_DELAYS = (1.3, 20.0, 300.0)
"""Delays of the hints sweep (2400 bit/s, 1e-4): the Moon, far, very far."""


def _sweep_hints() -> Iterable[Point]:
    """Every hint mode of :data:`HINTS` at the defaults: told the truth,
    nothing, or one value 10x off."""
    for delay in HINT_DELAYS:
        for hints in HINTS:
            p = derived_point(replace(BASE, delay=delay, hints=hints))
            yield replace(p, size=_range_size(p))


SWEEPS: dict[str, tuple[str, Callable[[], Iterable[Point]]]] = {
    "ofat": ("one factor at a time around the base point", _sweep_ofat),
    "delay-window": ("delay x window at 2400 and 9600 (the delay plot)", _sweep_delay_window),
    "ber-window": ("error rate x window at 2400 and 9600 (the BER plot)", _sweep_ber_window),
    "targets": ("the issue's target rows, then window 31, then auto length", _sweep_targets),
    "paper": ("window 1, 128 over delay x error rate (the baseline)", _sweep_paper),
    "length-ber": ("packet length x error rate at window 31", _sweep_length_ber),
    "profile-payload": ("both profiles x payload kinds at the base point", _sweep_profile_payload),
    "peers": ("8 KiB files on the real-peer reference line", _sweep_peers),
    "rate-window": ("line rate x window at 1.3 s, 1e-4", _sweep_rate_window),
    "delay-range": (
        "delay 0..1200 s at 2400 and 9600, errors 0 / 1e-4 / bursts, defaults",
        _sweep_delay_range,
    ),
    "hints": ("exact, no and wrong hints at 1.3, 20 and 300 s (2400, 1e-4)", _sweep_hints),
}
"""Named sweeps: name -> (what it answers, generator of its points)."""

DEFAULT_SWEEPS = tuple(s for s in SWEEPS if s not in ("delay-range", "hints"))
"""The designed grid (``--full``); ``delay-range`` and ``hints`` move tens of
megabytes a point and run by name (``--sweep delay-range --sweep hints``)."""


def _sweep_quick() -> Iterable[Point]:
    """A small grid for a smoke run: the base row and its closest neighbours."""
    yield BASE
    yield replace(BASE, window=1)
    yield replace(BASE, window=31)
    yield replace(BASE, profile="8bit")
    yield replace(BASE, baud=9600)
    yield _auto(replace(BASE, baud=9600, window=31))
    yield replace(BASE, ber=1e-3)
    yield replace(BASE, delay=0.27)


QUICK: tuple[str, Callable[[], Iterable[Point]]] = ("the base row and neighbours", _sweep_quick)


def build_grid(
    sweeps: Sequence[tuple[str, Callable[[], Iterable[Point]]]] | Sequence[str],
    *,
    size: int | None = None,
    seed: int = 1,
) -> list[tuple[Point, list[str]]]:
    """The unique points of the named sweeps, in first-seen order, with their sweeps.

    Args:
        sweeps: names from :data:`SWEEPS`, or ``(name, generator)`` pairs.
        size: fix every point's payload size (a point's own ``size`` wins),
            instead of :func:`steady_size`.
        seed: the run's seed; a point's own seed (1 unless a sweep sets
            several) is offset by it, so ``seed=1`` keeps every point's own.
    """
    pairs = [(s, SWEEPS[s][1]) if isinstance(s, str) else s for s in sweeps]
    grid: dict[Point, list[str]] = {}
    for name, gen in pairs:
        for p in gen():
            p = replace(p, seed=seed + p.seed - 1, size=p.size if p.size is not None else size)
            grid.setdefault(p, [])
            if name not in grid[p]:
                grid[p].append(name)
    return list(grid.items())


# -- running ---------------------------------------------------------------------------


def run_point(point: Point, sweeps: Sequence[str] = ()) -> dict[str, Any]:
    """Measure one point and return its JSON row (keys :data:`ROW_KEYS`, then extras)."""
    size = point.size if point.size is not None else steady_size(point)
    payload = make_payload(point.payload, size, point.seed)
    encoding = PROFILES[point.profile]
    burst = BENCH_BURST if point.burst else None
    if point.derived_len:
        limit, p_hit, limit_len = _best_limit(point, payload, burst)
    else:
        limit_len = point.max_len
        limit, p_hit = limit_goodput(
            payload,
            rate=point.baud,
            max_len=point.max_len,
            encoding=encoding,
            byte_error_rate=point.ber,
            burst=burst,
            dense=point.dense,
        )
    line_bps = point.baud / BITS_PER_CHAR
    # Cap virtual time at 5x the time at the limit, or at 4 stop-and-wait
    # round trips per packet, whichever is longer: a configuration that cannot
    # finish inside that is reported as such, with the goodput it reached.
    packets = size / packet_sizes(payload, encoding, point.max_len, point.dense)[0]
    rtt = _round_trip(point.baud, point.delay, point.max_len)
    cap = max(5 * size / limit if limit > 0 else math.inf, 4 * packets * rtt) + 60
    m = simulate(
        payload,
        rate=point.baud,
        delay=point.delay,
        byte_error_rate=point.ber,
        burst=burst,
        window=point.window,
        max_len=None if point.derived_len else point.max_len,
        encoding=encoding,
        seed=point.seed,
        time_cap=cap,
        hints=point.hints,
        dense=point.dense,
    )
    goodput = m.goodput
    efficiency = goodput / line_bps
    limit_eff = limit / line_bps
    return {
        "baud": point.baud,
        "one_way_delay_s": point.delay,
        "byte_error_rate": point.ber,
        "burst": None
        if burst is None
        else {
            "p_good_to_bad": burst.p_good_to_bad,
            "p_bad_to_good": burst.p_bad_to_good,
            "error_good": burst.error_good,
            "error_bad": burst.error_bad,
        },
        "window": point.window,
        "max_packet_len": limit_len,
        "payload": point.payload,
        "payload_bytes": size,
        "seconds": round(m.seconds, 3),
        "goodput_Bps": round(goodput, 3),
        "line_Bps": line_bps,
        "efficiency": round(efficiency, 4),
        "limit_efficiency": round(limit_eff, 4),
        "ratio_to_limit": round(efficiency / limit_eff, 4) if limit_eff > 0 else 0.0,
        # Extras.
        "profile": point.profile,
        "default_window": point.window == default_window(),
        "length_policy": "auto" if point.auto_len else "measured" if point.derived_len else "fixed",
        "start_packet_len": point.max_len,
        "hints": point.hints,
        "dense": point.dense,
        "time_to_first_byte_s": None
        if m.first_byte_seconds is None
        else round(m.first_byte_seconds, 3),
        "long_sequence": m.long_sequence,
        "early_bytes": m.early_bytes,
        "mean_byte_error_rate": mean_byte_error_rate(point.ber, burst),
        "packet_error_rate": round(p_hit, 6),
        "limit_Bps": round(limit, 3),
        "connect_seconds": round(m.connect_seconds, 3),
        "retransmissions": m.retransmissions,
        "timeouts": m.timeouts,
        "naks": m.naks,
        "fast_retransmits": m.fast_retransmits,
        "smoothed_rtt_s": None if m.smoothed_rtt is None else round(m.smoothed_rtt, 4),
        "effective_window": m.effective_window,
        "complete": m.complete,
        "end": m.end,
        "ok": m.ok,
        "seed": point.seed,
        "sweeps": list(sweeps),
    }


def _run_item(item: tuple[int, Point, list[str]]) -> tuple[int, dict[str, Any]]:
    index, point, sweeps = item
    return index, run_point(point, sweeps)


def run_grid(
    grid: Sequence[tuple[Point, list[str]]],
    *,
    jobs: int = 1,
    progress: bool = False,
) -> list[dict[str, Any]]:
    """Measure every point, ``jobs`` processes at a time; rows in grid order.

    Points are independent and deterministic, so running them in parallel
    changes nothing but the wall-clock time.  Costly points (long transfers)
    are started first so the last minutes are not spent on one straggler.
    """
    items = [(i, p, s) for i, (p, s) in enumerate(grid)]
    rows: list[dict[str, Any] | None] = [None] * len(items)
    if jobs <= 1 or len(items) <= 1:
        results: Iterable[tuple[int, dict[str, Any]]] = map(_run_item, items)
        pool = None
    else:
        # fork would copy the parent's state cheaply but is unsafe once threads
        # exist; spawn/forkserver re-import the module, which is all we need.
        method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else None
        pool = multiprocessing.get_context(method).Pool(jobs)
        items.sort(key=lambda it: -_cost(it[1]))
        results = pool.imap_unordered(_run_item, items, chunksize=1)
    try:
        for done, (index, row) in enumerate(results, 1):
            rows[index] = row
            if progress:
                print(f"\r{done}/{len(items)} points", end="", file=sys.stderr, flush=True)
    finally:
        if pool is not None:
            pool.close()
            pool.join()
    if progress:
        print(file=sys.stderr)
    return [r for r in rows if r is not None]


def _cost(point: Point) -> float:
    """A rough CPU cost of a point: its wire bytes (the loop wakes per 16 bytes)."""
    if point.size is not None:
        return point.size * (1 + point.ber * point.max_len)
    return _WIRE_BUDGET * (1 + 100 * point.ber * point.max_len / 128)


def cpu_count() -> int:
    """CPUs this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1
