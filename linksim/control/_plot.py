"""``linksim plot``: joint trajectories of a console telemetry log, with command markers.

One panel of the six joint angles (degrees) against time (s from the start
of the log) as the arm reported them (telemetry and completion records),
the model's predictions as dotted steps, and a vertical marker at every
command completion (green) or failure (red), labelled with its number; a
second panel holds the finger opening (mm).  matplotlib is the optional
``plot`` extra, loaded with the Agg backend (no display needed) through
:mod:`linksim.bench._plot`, whose :class:`PlotUnavailable` carries the install hint.
"""

from __future__ import annotations

import math
import pathlib

from linksim._plotting import PlotUnavailable, pyplot

from ._telemetry_log import LogContents, read_log

__all__ = ["plot_log"]


def plot_log(log: str | pathlib.Path | LogContents, out: str | pathlib.Path) -> pathlib.Path:
    """Draw ``log`` (a path or contents read by :func:`read_log`) to the PNG ``out``.

    Raises :class:`PlotUnavailable` without matplotlib or when the log holds
    no reported state, ``ValueError`` for a malformed log.
    """
    contents = log if isinstance(log, LogContents) else read_log(log)
    reported = contents.reported()
    if not reported:
        raise PlotUnavailable("the log holds no reported arm state to plot")
    plt = pyplot()
    fig, (joints_ax, grip_ax) = plt.subplots(
        2, 1, figsize=(10, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]}
    )
    t = [s["t"] for s in reported]
    for j in range(6):
        joints_ax.plot(t, [s["joints_deg"][j] for s in reported], label=f"joint {j + 1}")
    predicted = [s for s in contents.states if s["source"] == "predicted"]
    if predicted:
        pt = [s["t"] for s in predicted]
        for j in range(6):
            joints_ax.step(
                pt,
                [s["joints_deg"][j] for s in predicted],
                where="post",
                linestyle=":",
                color=f"C{j}",
                alpha=0.6,
            )
    grip_ax.plot(t, [s["finger_opening_m"] * 1000 for s in reported], color="k")
    for event in contents.commands:
        if event["event"] not in ("completed", "failed"):
            continue
        colour = "tab:green" if event["event"] == "completed" else "tab:red"
        for ax in (joints_ax, grip_ax):
            ax.axvline(event["t"], color=colour, linewidth=0.7, alpha=0.5)
        joints_ax.annotate(
            f"#{event['index']}",
            (event["t"], 1.0),
            xycoords=("data", "axes fraction"),
            fontsize=7,
            ha="center",
            va="bottom",
            color=colour,
        )
    title = contents.header.get("title") or "telemetry log"
    joints_ax.set_title(f"{title}\n(solid: reported, dotted: predicted; markers: commands done)")
    joints_ax.set_ylabel("joint angle (deg)")
    joints_ax.legend(loc="upper right", fontsize=7, ncols=3)
    joints_ax.grid(alpha=0.3)
    grip_ax.set_ylabel("fingers (mm)")
    grip_ax.set_xlabel("time (s)")
    grip_ax.grid(alpha=0.3)
    span = max(t) - min(t)
    if math.isfinite(span) and span > 0:
        grip_ax.set_xlim(min(t) - 0.02 * span, max(t) + 0.02 * span)
    fig.tight_layout()
    path = pathlib.Path(out)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
