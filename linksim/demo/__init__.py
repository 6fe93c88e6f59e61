"""Whole-stack programs: the demo, ``linksim control``, the arm server, the console runner.

* :func:`run_demo` (``linksim demo``): a controller commands the simulated arm
  through the whole stack (:class:`DemoOptions` in, :class:`DemoReport` out,
  :func:`print_report`); :func:`run_control` runs the same task against a
  running arm server.
* :func:`serve_arm_serial` / :func:`serve_arm_tcp`: the arm server's loops
  (``linksim arm-server``).
* :func:`run_console` (``linksim console``): :class:`ConsoleOptions` in,
  :class:`ConsoleResult` out.
"""

from __future__ import annotations

from ._armserver import serve_arm_serial, serve_arm_tcp
from ._console_run import ConsoleOptions, ConsoleResult, run_console
from ._control import run_control
from ._demo import run_demo
from ._report import DemoOptions, DemoReport, print_report, run_time_limit

__all__ = [
    "ConsoleOptions",
    "ConsoleResult",
    "DemoOptions",
    "DemoReport",
    "print_report",
    "run_console",
    "run_control",
    "run_demo",
    "run_time_limit",
    "serve_arm_serial",
    "serve_arm_tcp",
]
