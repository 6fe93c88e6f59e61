"""Markdown summary of goodput rows: the tables bench/results/README.md shows.

``linksim bench goodput --from-json FILE --summary`` regenerates them from a
saved run, so the published tables are derived from the published JSON and
nothing is copied by hand.  Rows are looked up by value; a table whose rows
the run does not hold is left out.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

__all__ = ["REFERENCE_PEERS", "TARGET", "summarize"]

Row = dict[str, Any]

TARGET = 0.9
"""The issue's bar for ratio_to_limit (default window, delay <= 1.3 s, BER <= 1e-4)."""

REFERENCE_PEERS: tuple[tuple[str, float], ...] = (
    ("C-Kermit, window 2, 1000-byte packets", 0.52),
    ("ZMODEM (windowed)", 0.52),
    ("XMODEM-1K", 0.51),
    ("G-Kermit (stop-and-wait)", 0.36),
)
"""Real peers over an impaired pty at 2400 bit/s, 1.3 s one way, 1e-4 bit-flip
probability per byte, 8-bit clean, 8 KiB random binary files (issue 9):
fraction of line capacity, wall-clock, whole file transfer."""


def _find(rows: Sequence[Row], **want: Any) -> Row | None:
    for r in rows:
        if all(_value(r, k) == v for k, v in want.items()):
            return r
    return None


def _value(r: Row, key: str) -> Any:
    if key == "errors":
        return "burst" if r["burst"] is not None else r["byte_error_rate"]
    if key == "auto":
        return r["length_policy"] == "auto"
    if key == "file":
        return r.get("sweeps") == ["peers"]
    return r[key]


def _steady(rows: Sequence[Row], **want: Any) -> Row | None:
    want.setdefault("payload", "binary")
    want.setdefault("profile", "printable")
    want.setdefault("file", False)
    return _find(rows, **want)


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def _headline(rows: Sequence[Row]) -> list[str]:
    base: dict[str, Any] = {"baud": 2400, "one_way_delay_s": 1.3, "errors": 1e-4}
    default = next((r["window"] for r in rows if r["default_window"]), None)
    cases: list[tuple[str, dict[str, Any]]] = [
        ("paper: stop-and-wait, 128 (baseline)", {"window": 1, "max_packet_len": 128}),
        (f"default window ({default}), 128", {"window": default, "max_packet_len": 128}),
        ("window 31, 128", {"window": 31, "max_packet_len": 128, "auto": False}),
        ("window 31, automatic length", {"window": 31, "auto": True}),
        (
            f"default window ({default}), 128, 8-bit clean",
            {"window": default, "max_packet_len": 128, "profile": "8bit"},
        ),
    ]
    out = [
        "| configuration | packet length | goodput (B/s) | efficiency | limit | ratio to limit "
        "| x baseline |",
        "|---|---|---|---|---|---|---|",
    ]
    baseline = _steady(rows, **base, window=1, max_packet_len=128)
    for label, extra in cases:
        r = _steady(rows, **{**base, **extra})
        if r is None:
            continue
        gain = (
            f"{r['goodput_Bps'] / baseline['goodput_Bps']:.2f}x"
            if baseline and baseline["goodput_Bps"]
            else "-"
        )
        out.append(
            f"| {label} | {r['max_packet_len']} | {r['goodput_Bps']:.1f} | "
            f"{_pct(r['efficiency'])} | {_pct(r['limit_efficiency'])} | "
            f"{r['ratio_to_limit']:.3f} | {gain} |"
        )
    return out


def _targets(rows: Sequence[Row]) -> list[str]:
    out = [
        "| bit/s | one-way delay (s) | byte error rate | default window, 128 | window 31, 128 "
        "| window 31, auto length |",
        "|---|---|---|---|---|---|",
    ]
    for baud in (2400, 9600):
        for delay in (0.0, 0.27, 1.3):
            for ber in (0.0, 1e-5, 1e-4):
                key = {"baud": baud, "one_way_delay_s": delay, "errors": ber}
                cells = []
                for extra in (
                    {"default_window": True, "max_packet_len": 128, "auto": False},
                    {"window": 31, "max_packet_len": 128, "auto": False},
                    {"window": 31, "auto": True},
                ):
                    r = _steady(rows, **key, **extra)
                    if r is None:
                        cells.append("-")
                        continue
                    mark = "pass" if r["ratio_to_limit"] >= TARGET else "**miss**"
                    length = f" ({r['max_packet_len']})" if extra.get("auto") else ""
                    cells.append(f"{r['ratio_to_limit']:.3f}{length} {mark}")
                if any(c != "-" for c in cells):
                    out.append(f"| {baud} | {delay:g} | {ber:g} | " + " | ".join(cells) + " |")
    return out


def _lengths(rows: Sequence[Row]) -> list[str]:
    lengths = sorted(
        {r["max_packet_len"] for r in rows if "length-ber" in r.get("sweeps", ())} - {0}
    )
    fixed = [n for n in lengths if _find(rows, max_packet_len=n, auto=False)]
    head = " | ".join(str(n) for n in fixed)
    out = [
        f"| bit/s | errors | {head} | automatic (chosen) |",
        "|---|---|" + "---|" * len(fixed) + "---|",
    ]
    for baud in (1200, 2400, 9600, 19200):
        for errors in (0.0, 1e-5, 1e-4, 1e-3, "burst"):
            key = {"baud": baud, "one_way_delay_s": 1.3, "errors": errors, "window": 31}
            cells = []
            best = max(
                (
                    r["efficiency"]
                    for n in fixed
                    if (r := _steady(rows, **key, max_packet_len=n, auto=False))
                ),
                default=None,
            )
            if best is None:
                continue
            for n in fixed:
                r = _steady(rows, **key, max_packet_len=n, auto=False)
                text = "-" if r is None else f"{r['efficiency']:.3f}"
                cells.append(f"**{text}**" if r is not None and r["efficiency"] == best else text)
            auto = _steady(rows, **key, auto=True)
            cells.append(
                "-" if auto is None else f"{auto['efficiency']:.3f} ({auto['max_packet_len']})"
            )
            label = "GE bursts" if errors == "burst" else f"{errors:g}"
            out.append(f"| {baud} | {label} | " + " | ".join(cells) + " |")
    return out


def _peers(rows: Sequence[Row]) -> list[str]:
    out = [
        "| sender | efficiency, from connect (min-max over seeds) | efficiency, data only |",
        "|---|---|---|",
    ]
    for name, eff in REFERENCE_PEERS:
        out.append(f"| {name} (real peer, wall clock) | {_pct(eff)} | - |")
    default = next((r["window"] for r in rows if r["default_window"]), None)
    for prof in ("8bit", "printable"):
        for window, length in ((default, 128), (31, 256), (31, 512), (2, 1000)):
            runs = [
                r
                for r in rows
                if _value(r, "file")
                and r["profile"] == prof
                and r["window"] == window
                and r["max_packet_len"] == length
            ]
            if not runs:
                continue
            whole = [
                r["payload_bytes"] / (r["seconds"] + r["connect_seconds"]) / r["line_Bps"]
                for r in runs
            ]
            data = sum(r["efficiency"] for r in runs) / len(runs)
            out.append(
                f"| telelink {'8-bit clean' if prof == '8bit' else 'printable'}, "
                f"window {window}, {length} (virtual time, {len(runs)} seeds) | "
                f"{_pct(sum(whole) / len(whole))} ({_pct(min(whole))}-{_pct(max(whole))}) | "
                f"{_pct(data)} |"
            )
    return out


def _payloads(rows: Sequence[Row]) -> list[str]:
    out = [
        "| payload | printable: efficiency / limit / ratio | 8-bit clean: efficiency / limit "
        "/ ratio |",
        "|---|---|---|",
    ]
    for kind in ("binary", "text", "commands"):
        cells = []
        for prof in ("printable", "8bit"):
            r = _steady(
                rows,
                baud=2400,
                one_way_delay_s=1.3,
                errors=1e-4,
                default_window=True,
                max_packet_len=128,
                payload=kind,
                profile=prof,
            )
            cells.append(
                "-"
                if r is None
                else f"{_pct(r['efficiency'])} / {_pct(r['limit_efficiency'])} / "
                f"{r['ratio_to_limit']:.3f}"
            )
        if any(c != "-" for c in cells):
            out.append(f"| {kind} | " + " | ".join(cells) + " |")
    return out


def summarize(rows: Sequence[Row]) -> str:
    """The summary tables as markdown (virtual-time figures unless marked otherwise)."""
    sections = [
        (
            "Base line: 2400 bit/s, 1.3 s one way, byte error rate 1e-4, random binary, "
            "printable profile",
            _headline(rows),
        ),
        (f"Targets: ratio_to_limit >= {TARGET} (random binary, printable)", _targets(rows)),
        (
            "Packet length x error rate: efficiency at window 31, 1.3 s one way "
            "(best fixed length in bold)",
            _lengths(rows),
        ),
        ("Against real peers: 8 KiB random binary, 2400 bit/s, 1.3 s, 1e-4", _peers(rows)),
        ("Payload kinds and profiles at the base point (default window, 128)", _payloads(rows)),
    ]
    parts = []
    for title, lines in sections:
        if len(lines) > 2:
            parts.append(f"#### {title}\n\n" + "\n".join(lines))
    return "\n\n".join(parts) + "\n"
