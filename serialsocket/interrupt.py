"""Ctrl-C as a cancellation: a command-line run ends through its own cleanup.

Public for the command-line programs built on this stack (serialsocket's,
linksim's, a user's own controller): ``run_interruptibly(main)`` in place of
``trio.run(main)``.

trio's default turns SIGINT into a KeyboardInterrupt raised wherever the
main thread happens to be.  Raised between entering a nursery and guarding
it (an ``__aenter__`` half done, as when Ctrl-C lands while a client is still
connecting), it corrupts trio's cancel-scope stack: the run ends in a
``RuntimeError: Cancel scope stack corrupted`` traceback instead of the
one-line "interrupted" and status 130 the commands promise, and no
``finally`` is sure to have run.

:func:`run_interruptibly` receives the signal as a message instead: it
cancels the whole run at its next checkpoint, so every ``finally`` and
``__aexit__`` runs as for any other cancellation (a client says goodbye, a
capture file is closed), and only then does KeyboardInterrupt leave the run
for the caller's ``except KeyboardInterrupt`` to report.  No task is added,
so a virtual-clock run schedules exactly as it did (its figures do not move).
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Awaitable, Callable
from types import FrameType
from typing import TypeVar

import trio

__all__ = ["run_interruptibly"]

T = TypeVar("T")


def run_interruptibly(
    fn: Callable[..., Awaitable[T]],
    *args: object,
    clock: trio.abc.Clock | None = None,
) -> T:
    """``trio.run(fn, *args, clock=clock)``, with SIGINT cancelling ``fn``.

    Returns what ``fn`` returns.  After a SIGINT, raises KeyboardInterrupt
    once ``fn`` has unwound, whether it then returned, raised Cancelled or
    raised something else because it was cancelled (that exception becomes
    the ``__cause__``).  Cleanup is bounded by ``fn``'s own bounded waits; a
    second SIGINT while it runs changes nothing.  Off the main thread (where
    no signal handler can be set) this is plain ``trio.run``.
    """
    if threading.current_thread() is not threading.main_thread():
        return trio.run(fn, *args, clock=clock)
    return trio.run(_guarded, fn, args, clock=clock)


async def _guarded(fn: Callable[..., Awaitable[T]], args: tuple[object, ...]) -> T:
    token = trio.lowlevel.current_trio_token()
    interrupted = False
    with trio.CancelScope() as scope:

        def on_sigint(_signum: int, _frame: FrameType | None) -> None:
            nonlocal interrupted
            interrupted = True
            # A signal handler may not touch trio's state directly; this is
            # how trio's own signal receiver hands a signal to the run.
            token.run_sync_soon(scope.cancel, idempotent=True)

        previous = signal.signal(signal.SIGINT, on_sigint)
        try:
            result = await fn(*args)
        except BaseException as exc:
            if interrupted:
                raise KeyboardInterrupt from exc
            raise
        finally:
            signal.signal(signal.SIGINT, previous)
    if interrupted:
        raise KeyboardInterrupt
    return result
