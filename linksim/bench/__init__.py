"""Benchmarks and the soak: they measure; they are not tests.

Each benchmark is a typed function returning its record (what
``linksim bench NAME --json`` prints); :mod:`linksim.cli` owns the options
and the text output.

* ``codec``: :func:`run_codec`; ``relay``: :func:`measure_relay`; ``pty``:
  :func:`run_bench_pty`; ``latency``: :func:`run_latency`; ``flood``:
  :func:`run_flood`; ``kermit``: :func:`run_bench_kermit` and
  :func:`run_kermit_table` (:class:`TransferSetup`,
  :func:`run_kermit_transfer`, also the interop tests' entry point).
* ``goodput``: :func:`run_goodput_transfer` (one transfer); :func:`standard_grid` /
  :func:`custom_grid` choose the points, :func:`run_grid` runs them (:func:`run_point`
  one), :func:`summarize` and :func:`plot_both` / :func:`plot_delay` / :func:`plot_ber`
  present the rows.
* ``transfer``: :func:`run_transfer_table` runs issue 21's real-time table
  (:data:`TRANSFER_ROWS`, a :class:`TransferRow` each; :func:`parse_transfer_row`
  reads one from its number or its line), the netcat through ``linksim relay``.
* The soak: :func:`run_soak` and its verdict :func:`check_soak`.
"""

from __future__ import annotations

from ._codec import run as run_codec
from ._flood import run as run_flood
from ._goodput import custom_grid, missing_row_keys, standard_grid
from ._goodput import run_transfer as run_goodput_transfer
from ._grid import SWEEPS, Point, auto_packet_length, cpu_count, run_grid, run_point
from ._kermit import DEFAULT_PAIRS as KERMIT_PAIRS
from ._kermit import TransferSetup, bad_pairing, run_bench_kermit, run_kermit_table
from ._kermit import run_transfer as run_kermit_transfer
from ._latency import TRANSPORTS as LATENCY_TRANSPORTS
from ._latency import run as run_latency
from ._line_table import ROWS as TRANSFER_ROWS
from ._line_table import TransferRow
from ._line_table import parse_row as parse_transfer_row
from ._line_table import run_table as run_transfer_table
from ._plot import plot_ber, plot_both, plot_delay, plot_delay_range
from ._pty import DEFAULT_LENGTHS as PTY_LENGTHS
from ._pty import PORTS as PTY_PORTS
from ._pty import run_bench_pty
from ._relay import measure as measure_relay
from ._soak import SoakReport, run_soak
from ._soak import check as check_soak
from ._summary import summarize
from ._transfer import HINTS as GOODPUT_HINTS
from ._transfer import PROFILES as GOODPUT_PROFILES

__all__ = [
    "GOODPUT_HINTS",
    "GOODPUT_PROFILES",
    "KERMIT_PAIRS",
    "LATENCY_TRANSPORTS",
    "PTY_LENGTHS",
    "PTY_PORTS",
    "SWEEPS",
    "TRANSFER_ROWS",
    "Point",
    "SoakReport",
    "TransferRow",
    "TransferSetup",
    "auto_packet_length",
    "bad_pairing",
    "check_soak",
    "cpu_count",
    "custom_grid",
    "measure_relay",
    "missing_row_keys",
    "parse_transfer_row",
    "plot_ber",
    "plot_both",
    "plot_delay",
    "plot_delay_range",
    "run_bench_kermit",
    "run_bench_pty",
    "run_codec",
    "run_flood",
    "run_goodput_transfer",
    "run_grid",
    "run_kermit_table",
    "run_kermit_transfer",
    "run_latency",
    "run_point",
    "run_soak",
    "run_transfer_table",
    "standard_grid",
    "summarize",
]
