"""Virtual-time runs that are the same run every time.

A ``--virtual`` run is on trio's ``MockClock`` and every random choice of ours
(link noise, nonces, incarnations) comes from a seeded ``random.Random``.  One
source of variation is left: when several tasks become runnable at the same
instant, trio orders each batch with its own module-level RNG, seeded from the
OS (under hypothesis it is pinned; elsewhere it is not).  On a virtual clock
that decides, for example, whether a reply or a heartbeat is written first,
which changes retransmissions and byte counts.  Seeding it makes two runs with
the same arguments byte-identical (issue 19).  Accessing a private trio name
is confined to this module.
"""

from __future__ import annotations

import random
from collections.abc import Awaitable, Callable
from typing import TypeVar

import trio
import trio.testing

from serialsocket.interrupt import run_interruptibly

__all__ = ["run_virtual"]

T = TypeVar("T")

SCHEDULER_SEED = 0
"""Any constant would do; what matters is that it is the same every run."""


def _scheduler_rng() -> random.Random | None:
    core = getattr(trio, "_core", None)
    run_module = getattr(core, "_run", None)
    rng = getattr(run_module, "_r", None)
    return rng if isinstance(rng, random.Random) else None


def run_virtual(
    fn: Callable[..., Awaitable[T]],
    *args: object,
    clock: trio.testing.MockClock | None = None,
) -> T:
    """``trio.run(fn, *args)`` on ``clock`` (default: a virtual clock that jumps
    whenever every task sleeps), with trio's task-ordering RNG seeded.

    If a future trio moves that RNG, runs stay correct but may differ in
    detail; ``tests/linksim/test_virtual.py`` notices.
    """
    rng = _scheduler_rng()
    if rng is not None:
        rng.seed(SCHEDULER_SEED)
    if clock is None:
        clock = trio.testing.MockClock(autojump_threshold=0)
    return run_interruptibly(fn, *args, clock=clock)
