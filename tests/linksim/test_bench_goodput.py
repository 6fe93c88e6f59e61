"""The goodput benchmark runs on a tiny grid and writes valid JSON rows (speed is not asserted).

The figures themselves are virtual-time and exact, but they are the
benchmark's business; these tests check the contract (the row keys, the grid
design, the limit formula, the optional plot) in a few seconds.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from linksim import DirectionConfig
from linksim.bench import SWEEPS, Point, auto_packet_length, run_point
from linksim.bench._grid import (
    BASE,
    DEFAULT_SWEEPS,
    QUICK,
    RANGE_DELAYS,
    ROW_KEYS,
    build_grid,
    command_records,
    default_window,
)
from linksim.bench._transfer import BENCH_BURST, HINTS, packet_error_probability
from linksim.link import GilbertElliott, LinkDirection

TINY = [
    "--rate",
    "9600",
    "--delay",
    "0",
    "--delay",
    "0.27",
    "--ber",
    "0",
    "--ber",
    "1e-3",
    "--window",
    "4",
    "--window",
    "1",
    "--size",
    "2500",
    "--jobs",
    "1",
]


def _bench(*args: str, check: bool = True) -> subprocess.CompletedProcess[bytes]:
    return subprocess.run(
        [sys.executable, "-m", "linksim", "bench", "goodput", *args],
        capture_output=True,
        timeout=120,
        check=check,
    )


def test_json_rows_have_the_issue_keys_and_are_consistent() -> None:
    rows = json.loads(_bench(*TINY, "--json").stdout)
    assert isinstance(rows, list)
    assert len(rows) == 2 * 2 * 2  # delays x error rates x windows
    for r in rows:
        assert list(r)[: len(ROW_KEYS)] == list(ROW_KEYS)
        assert r["ok"]
        assert r["complete"]
        assert r["payload_bytes"] == 2500
        assert r["line_Bps"] == 960.0
        # Early data (in the connection request) came before ``seconds`` began.
        assert 0 <= r["early_bytes"] <= 256
        assert r["goodput_Bps"] == pytest.approx((2500 - r["early_bytes"]) / r["seconds"], rel=1e-3)
        assert r["efficiency"] == pytest.approx(r["goodput_Bps"] / 960.0, abs=1e-4)
        assert r["ratio_to_limit"] == pytest.approx(
            r["efficiency"] / r["limit_efficiency"], abs=1e-3
        )
        assert 0 < r["limit_efficiency"] < 1
        assert r["burst"] is None
    # Errors cost retransmissions; a clean line costs none.
    assert all(r["retransmissions"] == 0 for r in rows if r["byte_error_rate"] == 0)
    # Stop-and-wait over 0.27 s one way is far slower than window 4.
    slow = {(r["window"], r["one_way_delay_s"], r["byte_error_rate"]): r for r in rows}
    assert slow[(4, 0.27, 0.0)]["goodput_Bps"] > 2.5 * slow[(1, 0.27, 0.0)]["goodput_Bps"]


def test_output_file_and_text_table(tmp_path: Path) -> None:
    out = tmp_path / "rows.json"
    text = _bench(*TINY[:4], "--size", "1500", "--jobs", "1", "--output", str(out)).stdout
    assert b"virtual time" in text
    rows = json.loads(out.read_text())
    assert [r["one_way_delay_s"] for r in rows] == [0.0]
    assert rows[0]["window"] == BASE.window
    assert rows[0]["default_window"]
    # The summary tables come from the saved rows: this one is a target row.
    summary = _bench("--from-json", str(out), "--summary").stdout.decode()
    assert "#### Targets" in summary
    ratio = rows[0]["ratio_to_limit"]
    verdict = "pass" if ratio >= 0.9 else "**miss**"
    # The default window is 31, so the row fills both the default and the 31 column.
    cell = f"{ratio:.3f} {verdict}"
    assert f"| 9600 | 0 | 0.0001 | {cell} | {cell} | - |" in summary


def test_plot_writes_png(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    rows = tmp_path / "rows.json"
    rows.write_text(_bench(*TINY, "--json").stdout.decode())
    png = tmp_path / "g.png"
    delay = tmp_path / "d.png"
    _bench("--from-json", str(rows), "--plot", str(png), "--plot-delay", str(delay))
    for path in (png, delay):
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_delay_range_plot_reads_the_sweep_rows(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    rows = json.loads(_bench(*TINY, "--json").stdout.decode())
    sweep = []
    for delay in (0.0, 20.0, 1200.0):
        for ber in (0.0, 1e-4):
            point = {"one_way_delay_s": delay, "byte_error_rate": ber, "sweeps": ["delay-range"]}
            sweep.append({**rows[0], **point})
    saved = tmp_path / "rows.json"
    saved.write_text(json.dumps(sweep))
    png = tmp_path / "r.png"
    _bench("--from-json", str(saved), "--plot-delay-range", str(png))
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # Rows of other sweeps only: a clear error, exit 2.
    saved.write_text(json.dumps(rows))
    failed = _bench("--from-json", str(saved), "--plot-delay-range", str(png), check=False)
    assert failed.returncode == 2
    assert b"--sweep delay-range" in failed.stderr
    # A folder that does not exist: one line saying so, exit 2, no traceback.
    nowhere = tmp_path / "no-such-folder" / "r.png"
    for option in ("--plot", "--plot-delay-range"):
        saved.write_text(json.dumps(sweep))
        failed = _bench("--from-json", str(saved), option, str(nowhere), check=False)
        assert failed.returncode == 2
        assert b"Traceback" not in failed.stderr
        assert b"cannot write the plot" in failed.stderr


def test_plot_without_matplotlib_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    from linksim.bench import _plot as _plot

    monkeypatch.setitem(sys.modules, "matplotlib", None)
    row = run_point(Point(9600, 0.0, 0.0, False, 4, 128, size=500))
    rows = [row, {**row, "one_way_delay_s": 0.27}]
    with pytest.raises(_plot.PlotUnavailable, match=r"telelink\[plot\]"):
        _plot.plot_delay(rows, Path("unused.png"))


def test_grid_design_covers_the_issue() -> None:
    full = build_grid(list(DEFAULT_SWEEPS))
    points = [p for p, _ in full]
    assert len(points) == len(set(points))
    assert BASE in points
    assert "ofat" in dict(full)[BASE]
    assert {p.baud for p in points} == {1200, 2400, 9600, 19200}
    assert {p.delay for p in points} == {0.0, 0.27, 1.3, 2.5}
    assert {(p.ber, p.burst) for p in points} >= {
        (0.0, False),
        (1e-5, False),
        (1e-4, False),
        (1e-3, False),
        (0.0, True),
    }
    assert {p.window for p in points} >= {1, 4, 8, 16, 31, default_window()}
    assert {p.max_len for p in points} >= {94, 128, 512, 2048}
    assert {p.payload for p in points} == {"binary", "text", "commands"}
    assert {p.profile for p in points} == {"printable", "8bit"}
    # The paper's configuration is its own series.
    paper = [p for p, s in full if "paper" in s]
    assert paper
    assert all(p.window == 1 and p.max_len == 128 for p in paper)
    # The quick grid holds the issue's base row.
    assert BASE in [p for p, _ in build_grid([("quick", QUICK[1])])]


def test_delay_range_and_hints_sweeps_cover_issue_20() -> None:
    """The delay-range and hints sweeps (issue 20) run by name, outside --full."""
    assert {"delay-range", "hints"} <= set(SWEEPS)
    assert "delay-range" not in DEFAULT_SWEEPS
    ranged = [p for p, _ in build_grid(["delay-range"])]
    assert {p.delay for p in ranged} == set(RANGE_DELAYS) >= {0.0, 1.3, 5.0, 20.0, 60.0, 1200.0}
    assert {p.baud for p in ranged} == {2400, 9600}
    assert {(p.ber, p.burst) for p in ranged} == {(0.0, False), (1e-4, False), (1e-4, True)}
    assert all(p.derived_len and p.window == default_window() for p in ranged)
    hinted = [p for p, _ in build_grid(["hints"])]
    assert {p.hints for p in hinted} == set(HINTS)


def test_a_point_without_hints_reports_its_hints_and_time_to_first_byte() -> None:
    from linksim.bench import custom_grid

    grid = custom_grid(delays=[0.27], hints=["none", "exact"], size=3000)
    assert grid is not None
    rows = [run_point(p) for p, _ in grid]
    assert [r["hints"] for r in rows] == ["none", "exact"]
    for r in rows:
        assert r["ok"]
        assert r["complete"]
        assert r["length_policy"] == "measured"
        # The first bytes ride in the connection request (early data): one
        # delay, not the handshake's round trip and one more.
        assert 0.27 <= r["time_to_first_byte_s"] < 3 * 0.27
        assert r["early_bytes"] > 0


def test_limit_formula_pieces() -> None:
    # Independent errors: 1 - (1 - p)^n.
    assert packet_error_probability(129, 1e-4) == pytest.approx(1 - (1 - 1e-4) ** 129)
    # A burst chain whose two states hit alike is independent errors.
    same = GilbertElliott(p_good_to_bad=0.01, p_bad_to_good=0.2, error_good=1e-3, error_bad=1e-3)
    assert packet_error_probability(129, 0.0, same) == pytest.approx(1 - (1 - 1e-3) ** 129)
    # The bench's bursts: the formula agrees with the engine's own chain, counted
    # over 20 000 packets of 129 bytes (about 130 hit: a 25 % band is > 3 sigma).
    n, packets = 129, 20_000
    p = packet_error_probability(n, 0.0, BENCH_BURST)
    line = LinkDirection(DirectionConfig(burst=BENCH_BURST), seed=5)
    sent = bytes(n * packets)
    line.send(sent, 0.0)
    got = np.frombuffer(line.receive(1.0), dtype=np.uint8).reshape(packets, n)
    hit = int(got.any(axis=1).sum())
    assert math.isclose(hit / packets, p, rel_tol=0.25), (hit, p * packets)


def test_command_records_are_fixed_size_and_deterministic() -> None:
    data = command_records(216 * 3 + 10, seed=2)
    assert len(data) == 216 * 3 + 10
    assert data[:4] == data[216:220] == b"TLCP"
    assert data == command_records(216 * 3 + 10, seed=2)


def test_auto_packet_length_follows_errors_and_window() -> None:
    # Frequent errors want short packets; a fast long-delay line with a capped
    # window wants long ones.
    assert auto_packet_length(2400, 1.3, 1e-3, window=31) <= 128
    assert auto_packet_length(19200, 1.3, 1e-5, window=31) >= 512


def test_dense_points_measure_the_length_and_take_the_limit_at_the_best_one() -> None:
    """--dense: the ends offer the dense encodings (as the netcat does), the
    limit is computed for the escape code the 8-bit line agrees on, and a
    default point (hints, no length) lets the ends measure the length: its
    limit is the best length they may choose, so the ratio never exceeds 1
    by choosing better than the start."""
    from dataclasses import replace

    from linksim.bench import custom_grid

    grid = custom_grid(rates=[9600], delays=[0.27], bers=[0.0], hints=["exact"], size=40_000)
    assert grid is not None
    [(point, _)] = grid
    plain = run_point(replace(point, profile="8bit"))
    dense = run_point(replace(point, profile="8bit", dense=True))
    assert (plain["dense"], dense["dense"]) == (False, True)
    assert (plain["length_policy"], plain["start_packet_len"]) == ("measured", 128)
    # A clean 9600 bit/s line: the best length within 0.54 s of line is 517.
    assert dense["max_packet_len"] == plain["max_packet_len"] == 517
    assert dense["limit_efficiency"] > plain["limit_efficiency"] + 0.2  # 1.01 vs 1.27 per byte
    for row in (plain, dense):
        assert row["complete"]
        assert 0.9 < row["ratio_to_limit"] <= 1.0
