"""The optional matplotlib loader shared by the goodput plots and the telemetry plot.

matplotlib is an optional extra (``pip install telelink[plot]``): it is
imported only when a plot is drawn, with the non-interactive Agg backend (no
display needed), and its absence is a :class:`PlotUnavailable` with the
install hint, not an ImportError deep in a traceback.  This is the one import
inside a function in linksim (tests/test_architecture.py allows it here only).
"""

from __future__ import annotations

from typing import Any

__all__ = ["PlotUnavailable", "pyplot"]


class PlotUnavailable(RuntimeError):
    """matplotlib is missing, or the rows hold nothing to plot."""


def pyplot() -> Any:
    try:
        import matplotlib
    except ImportError:
        raise PlotUnavailable("plots need matplotlib: pip install 'telelink[plot]'") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt
