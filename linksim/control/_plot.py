"""``linksim plot``: joint trajectories of a console telemetry log, with command markers.

One panel of the six joint angles (degrees) against time (s from the start
of the log) as the arm reported them (telemetry and completion records),
the model's end pose for each command as a cross at that command's
completion (where the console compared them), and a vertical marker at every
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


_LABEL_ROWS = 3
"""Command labels above the panel are staggered over this many rows, so that
completions close in time do not print over each other."""


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
        2,
        1,
        figsize=(10, 6.5),
        sharex=True,
        gridspec_kw={"height_ratios": [3, 1]},
        layout="constrained",
    )
    t = [s["t"] for s in reported]
    for j in range(6):
        # Joints often share a value (1, 4 and 6 all at 0): drawn thickest
        # first, each in its own dash, every line stays visible.
        joints_ax.plot(
            t,
            [s["joints_deg"][j] for s in reported],
            label=f"joint {j + 1}",
            color=f"C{j}",
            linewidth=3.2 - 0.45 * j,
            linestyle=_DASHES[j],
        )
    grip_ax.plot(t, [s["finger_opening_m"] * 1000 for s in reported], color="k")
    # The model's prediction is compared at each command's completion: its end
    # pose for that command.  Drawn there, it sits on the reported line when
    # the arm did what the model said, and off it by the divergence when not.
    predictions = [
        r for r in contents.other if r["type"] == "divergence" and "predicted_joints_deg" in r
    ]
    for j in range(6):
        joints_ax.plot(
            [r["t"] for r in predictions],
            [r["predicted_joints_deg"][j] for r in predictions],
            linestyle="none",
            marker="x",
            markersize=7,
            color=f"C{j}",
            label="model's end pose" if j == 0 else None,
        )
    grip_ax.plot(
        [r["t"] for r in predictions],
        [r["predicted_opening_m"] * 1000 for r in predictions],
        linestyle="none",
        marker="x",
        color="k",
    )
    done = [e for e in contents.commands if e["event"] in ("completed", "failed")]
    for k, event in enumerate(done):
        colour = "tab:green" if event["event"] == "completed" else "tab:red"
        for ax in (joints_ax, grip_ax):
            ax.axvline(event["t"], color=colour, linewidth=0.7, alpha=0.5)
        joints_ax.annotate(
            f"#{event['index']}",
            (event["t"], 1.0),
            xycoords=("data", "axes fraction"),
            xytext=(0, 2 + 9 * (k % _LABEL_ROWS)),
            textcoords="offset points",
            fontsize=7,
            ha="center",
            va="bottom",
            color=colour,
        )
    title = contents.header.get("title") or "telemetry log"
    joints_ax.set_title(
        f"{title}\nlines: reported; x: the model's end pose for each command, at its "
        "completion; markers: green completed, red failed",
        pad=12 + 9 * _LABEL_ROWS,
        fontsize=9,
    )
    joints_ax.set_ylabel("joint angle (deg)")
    joints_ax.legend(loc="best", fontsize=7, ncols=4)
    joints_ax.grid(alpha=0.3)
    grip_ax.set_ylabel("fingers (mm)")
    grip_ax.set_xlabel("time (s)")
    grip_ax.grid(alpha=0.3)
    span = max(t) - min(t)
    if math.isfinite(span) and span > 0:
        grip_ax.set_xlim(min(t) - 0.02 * span, max(t) + 0.02 * span)
    path = pathlib.Path(out)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


_DASHES = ("-", "--", "-.", ":", (0, (5, 1, 1, 1)), (0, (1, 1)))
