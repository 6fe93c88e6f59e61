"""``linksim bench goodput``: ARQ goodput against the line's theoretical limit, on virtual time.

Every figure this command prints is *virtual-time*: two sans-I/O endpoints
exchange bytes through the seeded impairment engine on an explicit clock
(:mod:`linksim.bench._transfer`), so the same arguments give the same rows on
any machine, loaded or idle.  Only the run time of the command itself depends
on the machine.

Modes:

* default / ``--full``: the designed grid, every sweep in
  :data:`~linksim.bench._grid.SWEEPS` (a few minutes on two cores);
* ``--quick``: the base row and a few neighbours (well under a minute);
* ``--sweep NAME``: chosen sweeps;
* any of ``--rate --delay --ber --burst --window --max-len --payload
  --profile --eight-bit``: the cross product of the values given, the base
  point supplying the rest (``--window`` and the others may repeat).

Output: a text table, or ``--json`` (the rows as one JSON array on stdout),
and/or ``--output FILE.json``, or ``--summary`` (the markdown tables of
bench/results/README.md); ``--plot FILE.png`` draws efficiency against
delay and against error rate, one line per window (needs the ``plot`` extra).
The exit status is 1 if any row's delivered data was not exact.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

from ._grid import (
    BASE,
    DEFAULT_SWEEPS,
    QUICK,
    ROW_KEYS,
    Point,
    auto_packet_length,
    build_grid,
    derived_point,
    make_payload,
)
from ._transfer import BENCH_BURST, PROFILES, limit_goodput, simulate

__all__ = [
    "GoodputResult",
    "custom_grid",
    "missing_row_keys",
    "run_transfer",
    "standard_grid",
    "theoretical_goodput",
]


# -- the single-transfer API (kept for callers of the first version) ------------------


@dataclass(frozen=True, slots=True)
class GoodputResult:
    """One measured transfer (the regression tests' view of a point).

    Attributes:
        window, max_len, rate, delay, byte_error_rate, payload, profile: the point.
        bytes: payload size.
        seconds: virtual time from connection to the last byte delivered.
        goodput: payload bytes per virtual second.
        theoretical: the limit for this line, packet size and data, bytes/s.
        efficiency: goodput / theoretical (the rows' ``ratio_to_limit``).
        retransmissions, timeouts, naks: sender-side counters.
        ok: every byte arrived exactly once, in order.
    """

    window: int
    max_len: int
    rate: float
    delay: float
    byte_error_rate: float
    payload: str
    profile: str
    bytes: int
    seconds: float
    goodput: float
    theoretical: float
    efficiency: float
    retransmissions: int
    timeouts: int
    naks: int
    ok: bool


def theoretical_goodput(
    payload: bytes,
    *,
    rate: float,
    bits_per_char: int = 10,
    max_len: int,
    byte_error_rate: float,
    eight_bit: bool = False,
    burst: bool = False,
) -> float:
    """The theoretical limit in payload bytes/s (see :mod:`linksim.bench._transfer`)."""
    limit, _ = limit_goodput(
        payload,
        rate=rate * 10 / bits_per_char,
        max_len=max_len,
        encoding=PROFILES["8bit" if eight_bit else "printable"],
        byte_error_rate=byte_error_rate,
        burst=BENCH_BURST if burst else None,
    )
    return limit


def run_transfer(
    *,
    window: int,
    rate: float,
    delay: float,
    byte_error_rate: float,
    size: int,
    max_len: int = 128,
    payload_kind: str = "binary",
    eight_bit: bool = False,
    seed: int = 1,
    burst: bool = False,
) -> GoodputResult:
    """Send ``size`` bytes one way over an impaired line and measure the goodput.

    ``burst`` adds the grid's Gilbert-Elliott case on top of ``byte_error_rate``.
    The transfer runs to completion (no time cap short of a protocol failure).
    """
    profile = "8bit" if eight_bit else "printable"
    payload = make_payload(payload_kind, size, seed)
    ge = BENCH_BURST if burst else None
    m = simulate(
        payload,
        rate=rate,
        delay=delay,
        byte_error_rate=byte_error_rate,
        burst=ge,
        window=window,
        max_len=max_len,
        encoding=PROFILES[profile],
        seed=seed,
        # A generous bound so that a protocol bug cannot spin forever.
        time_cap=50 * size / (rate / 10) + 1000 * (2 * delay + 1),
    )
    theory, _ = limit_goodput(
        payload,
        rate=rate,
        max_len=max_len,
        encoding=PROFILES[profile],
        byte_error_rate=byte_error_rate,
        burst=ge,
    )
    goodput = m.goodput
    return GoodputResult(
        window=window,
        max_len=max_len,
        rate=rate,
        delay=delay,
        byte_error_rate=byte_error_rate,
        payload=payload_kind,
        profile=profile,
        bytes=size,
        seconds=round(m.seconds, 3),
        goodput=round(goodput, 3),
        theoretical=round(theory, 3),
        efficiency=round(goodput / theory, 4) if theory else 0.0,
        retransmissions=m.retransmissions,
        timeouts=m.timeouts,
        naks=m.naks,
        ok=m.ok and m.complete,
    )


# -- the CLI ------------------------------------------------------------------------------


def custom_grid(
    *,
    rates: Sequence[int] | None = None,
    delays: Sequence[float] | None = None,
    bers: Sequence[float] | None = None,
    burst: bool = False,
    windows: Sequence[int] | None = None,
    lengths: Sequence[int | str | None] | None = None,
    payloads: Sequence[str] | None = None,
    profiles: Sequence[str] | None = None,
    hints: Sequence[str] | None = None,
    size: int | None = None,
    seed: int = 1,
) -> list[tuple[Point, list[str]]] | None:
    """The cross product of the custom point values given, or None if none was given.

    The base point supplies every value not given; a length ``"auto"`` is the
    automatic packet length for the point.
    """
    profiles = list(profiles or [])
    given = (rates, delays, bers, windows, lengths, payloads, hints)
    if not any(given) and not profiles and not burst:
        return None
    points: list[Point] = []
    for rate, delay, ber, window, length, kind, prof, hint in itertools.product(
        rates or [BASE.baud],
        delays or [BASE.delay],
        bers or [BASE.ber],
        windows or [BASE.window],
        lengths or [None],
        payloads or [BASE.payload],
        profiles or [BASE.profile],
        hints or [BASE.hints],
    ):
        p = replace(
            BASE,
            baud=rate,
            delay=delay,
            ber=ber,
            burst=burst,
            window=window,
            payload=kind,
            profile=prof,
            size=size,
            seed=seed,
            hints=hint,
        )
        if length is None and hints:
            # Hints given, no length: the length the endpoints derive from them.
            p = derived_point(p)
        elif length == "auto":
            n = auto_packet_length(rate, delay, ber, window=window, profile=prof, burst=burst)
            p = replace(p, max_len=n, auto_len=True)
        else:
            p = replace(p, max_len=int(length if length is not None else BASE.max_len))
        points.append(p)
    return [(p, ["custom"]) for p in dict.fromkeys(points)]


def standard_grid(
    *,
    quick: bool = False,
    sweeps: Sequence[str] | None = None,
    size: int | None = None,
    seed: int = 1,
) -> list[tuple[Point, list[str]]]:
    """The quick grid, the named sweeps, or (neither given) the whole designed grid."""
    if quick:
        chosen: Sequence[Any] = [("quick", QUICK[1])]
    else:
        chosen = sweeps or list(DEFAULT_SWEEPS)
    return build_grid(chosen, size=size, seed=seed)


def missing_row_keys(rows: Sequence[dict[str, Any]]) -> list[str]:
    """Required keys the rows (say, read from a file) lack."""
    return [k for k in ROW_KEYS if rows and k not in rows[0]]
