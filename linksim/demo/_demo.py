"""``linksim demo``: a controller commands the simulated arm through the whole stack.

Three ways to run it, one report:

* **real time, serial** (the default): two pty pairs joined by the impaired
  relay (``noisy-moon`` unless told otherwise); the arm server runs in its
  own process (``linksim arm-server``) on one pty, the controller in this one
  on the other, optionally dialing through emulated Hayes modems first.
* **real time, TCP**: the arm server in its own process on a loopback port.
* **virtual** (``--virtual``): everything in one process on trio's virtual
  clock over the in-memory impaired link: instant and deterministic.

The controller runs seed 000's rock task (:func:`linksim.arm.rock_task`),
pipelined, and the report says what was sent, completed and failed, what
the link did and where the arm ended.
"""

from __future__ import annotations

import time

from linksim.link import run_virtual
from serialsocket.interrupt import run_interruptibly

from ._real import run_real
from ._report import DemoOptions, DemoReport
from ._stack import run_virtual_demo

__all__ = ["run_demo"]


def run_demo(options: DemoOptions) -> DemoReport:
    """Run the demo to the end and return its report (never raises for a failed run)."""
    if options.virtual:
        return run_virtual(run_virtual_demo, options)
    started = time.monotonic()
    report = run_interruptibly(run_real, options)
    report.seconds = time.monotonic() - started
    return report
