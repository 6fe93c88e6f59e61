"""Contact force against time for the control schemes of one task (``linksim teleop --plot``)."""

from __future__ import annotations

import pathlib

from linksim._plotting import PlotUnavailable, pyplot

from ._run import TeleopReport

__all__ = ["plot_contact_force"]

_STYLE = {
    ("shared-compliance", True): ("tab:green", "shared compliance (local admittance, 30 N cap)"),
    ("force-reflection", True): ("tab:red", "direct force reflection (arm stops at the limit)"),
    ("force-reflection", False): ("tab:orange", "direct force reflection, no limit stop"),
}


def plot_contact_force(
    reports: list[tuple[TeleopReport, bool]], path: str | pathlib.Path, title: str
) -> None:
    """One curve per (report, force_stop); the force limit as a line.  PNG at ``path``."""
    if not reports or not any(r.force_trace for r, _ in reports):
        raise PlotUnavailable("no force samples to plot")
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 4.5))
    t0 = min(r.force_trace[0][0] for r, _ in reports if r.force_trace)
    for report, stop in reports:
        color, label = _STYLE.get((report.scheme, stop), ("tab:blue", report.scheme))
        ts = [t - t0 for t, _ in report.force_trace]
        fs = [f for _, f in report.force_trace]
        ax.plot(ts, fs, color=color, linewidth=1.2, label=f"{label}: max {max(fs):.0f} N")
    limit = reports[0][0].force_limit_n
    ax.axhline(limit, color="black", linestyle="--", linewidth=1, label=f"force limit {limit:g} N")
    ax.set_xlabel("arm time (s)")
    ax.set_ylabel("contact force |F| (N)")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    fig.savefig(str(path), dpi=110)
    plt.close(fig)
