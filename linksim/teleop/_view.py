"""The operator's teleoperation view: mode and buttons, force/torque bars, predicted vs
confirmed hand, setpoint age, the link -- as text lines, redrawn in place.

:func:`render` is pure (a :class:`ViewState` in, lines out), so it is tested
as text; :class:`LiveView` redraws it on a terminal (``linksim teleop --live``).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import TextIO

from tcpstream.teleop import Buttons, ChannelStatistics, ContactFlags, Reply, Sample

__all__ = ["LiveView", "ViewState", "force_bar", "render"]

_BAR = 20
"""Characters per half bar (negative | positive)."""


@dataclass(frozen=True, slots=True)
class ViewState:
    now: float
    sample: Sample | None
    """The newest sample taken (what the operator is doing)."""
    reply: Reply | None
    """The newest reply (what the arm confirmed)."""
    reply_at: float | None
    predicted: tuple[float, float, float] | None
    """Where the operator's own increments put the hand (the local prediction, base frame)."""
    channel: ChannelStatistics | None
    force_limit: float
    one_way_delay: float


def force_bar(value: float, full: float) -> str:
    """``-----|#####``: a signed bar, ``full`` at either end; ``!`` past it."""
    if not math.isfinite(value) or full <= 0:
        return " " * _BAR + "?" + " " * _BAR
    n = min(_BAR, round(abs(value) / full * _BAR))
    over = abs(value) > full
    fill = "!" if over else "#"
    if value < 0:
        return " " * (_BAR - n) + fill * n + "|" + " " * _BAR
    return " " * _BAR + "|" + fill * n + " " * (_BAR - n)


def _buttons(b: Buttons) -> str:
    names = [
        ("ENGAGED", Buttons.ENGAGED, "CLUTCH"),
        ("FORCE-REFL", Buttons.FORCE_REFLECTION, ""),
        ("SHARED", Buttons.SHARED_COMPLIANCE, ""),
        ("POSE-CHANGE", Buttons.POSE_CHANGE, ""),
        ("TOOL", Buttons.TOOL_FRAME, "WORLD"),
    ]
    out = []
    for on, bit, off in names:
        if b & bit:
            out.append(on)
        elif off:
            out.append(off)
    return " ".join(out)


def _flags(f: ContactFlags) -> str:
    return " ".join(flag.name or "" for flag in ContactFlags if f & flag) or "-"


def _xyz(v: tuple[float, ...] | None) -> str:
    if v is None:
        return "      -        -        -"
    return " ".join(f"{x * 1000:8.1f}" for x in v[:3])


def render(v: ViewState) -> list[str]:
    """The view as lines (no colour, no cursor control)."""
    s, r = v.sample, v.reply
    lines = []
    mode = s.mode.name.lower() if s is not None else "-"
    lines.append(
        f"teleop  t={v.now:8.2f} s  mode {mode:<9} buttons {_buttons(s.buttons) if s else '-'}"
        f"  trigger {s.trigger if s else 0:3d}"
    )
    if r is None:
        lines.append("arm     no reply yet")
    else:
        lines.append(
            f"arm     {r.status.name:<11} flags {_flags(r.flags):<24} applied sample "
            f"{r.sample}  gripper {r.gripper:3d}"
        )
    names = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
    force = r.force if r is not None else (0.0,) * 6
    for i, name in enumerate(names):
        full = v.force_limit if i < 3 else v.force_limit * 0.2
        unit = "N " if i < 3 else "Nm"
        lines.append(f"  {name} {force[i]:8.2f} {unit} {force_bar(force[i], full)}")
    lines.append(f"hand mm  predicted {_xyz(v.predicted)}")
    lines.append(f"         commanded {_xyz(r.commanded if r else None)}")
    lines.append(f"         confirmed {_xyz(r.actual if r else None)}")
    if r is not None and v.reply_at is not None and r.sample:
        trip = v.reply_at - r.stamp
        age = trip - r.held - v.one_way_delay  # less the reply's own line time
        lines.append(
            f"age     sample to reply {trip:6.3f} s; at execution about {age:6.3f} s "
            f"(held {r.held:5.3f} s; one way {v.one_way_delay:g} s)"
        )
    else:
        lines.append("age     -")
    c = v.channel
    if c is not None:
        rate = "-" if c.delivery_rate is None else f"{c.delivery_rate:7.0f} B/s"
        rtt = "-" if c.min_rtt is None else f"{c.min_rtt:5.3f} s"
        lines.append(
            f"link    sent {c.samples_sent} coalesced {c.samples_coalesced} replies "
            f"{c.replies_received}  in flight {c.in_flight_bytes} B  rate {rate}  min rtt "
            f"{rtt}  held back {c.held_by_backlog + c.held_by_window}"
        )
    return lines


class LiveView:
    """Redraws :func:`render` in place on a terminal; prints nothing when not a TTY."""

    def __init__(self, out: TextIO = sys.stderr) -> None:
        self._out = out
        self._drawn = 0
        self.enabled = out.isatty()

    def draw(self, v: ViewState) -> None:
        if not self.enabled:
            return
        lines = render(v)
        up = f"\x1b[{self._drawn}F" if self._drawn else ""
        self._out.write(up + "".join(f"\x1b[2K{line}\n" for line in lines))
        self._out.flush()
        self._drawn = len(lines)
