"""Ctrl-C cancels a command-line run; it is never raised mid-statement.

trio's default raises KeyboardInterrupt wherever the main thread is; raised
inside a half-entered nursery it corrupted the cancel-scope stack, and
``linksim console`` interrupted while connecting ended in a RuntimeError
traceback instead of "interrupted", 130 (a CI run caught it).
"""

from __future__ import annotations

import os
import pty
import select
import signal
import subprocess
import sys
import tty
from pathlib import Path

import pytest
import trio
import trio.testing

from serialsocket.interrupt import run_interruptibly

LIMIT = 60.0


def test_sigint_is_a_cancellation_at_the_next_checkpoint() -> None:
    reached: list[str] = []

    async def body() -> None:
        try:
            signal.raise_signal(signal.SIGINT)
            # Under plain trio.run the KeyboardInterrupt is raised here, in
            # the middle of synchronous code.
            reached.append("statement after the signal")
            await trio.sleep(3600)
            reached.append("never: the sleep is cancelled")
        finally:
            reached.append("finally ran")

    with pytest.raises(KeyboardInterrupt):
        run_interruptibly(body, clock=trio.testing.MockClock(autojump_threshold=0))
    assert reached == ["statement after the signal", "finally ran"]


def test_a_half_entered_nursery_survives_the_signal() -> None:
    """The shape of the bug: an ``__aenter__`` that enters a nursery by hand."""

    async def body() -> None:
        manager = trio.open_nursery()
        nursery = await manager.__aenter__()
        signal.raise_signal(signal.SIGINT)
        nursery.start_soon(trio.sleep_forever)
        try:
            await trio.sleep_forever()
        except BaseException as exc:
            await manager.__aexit__(type(exc), exc, exc.__traceback__)
            raise

    with pytest.raises(KeyboardInterrupt):
        run_interruptibly(body)


def test_an_error_raised_because_of_the_cancel_is_reported_as_the_interrupt() -> None:
    async def body() -> None:
        signal.raise_signal(signal.SIGINT)
        try:
            await trio.sleep(3600)
        except trio.Cancelled:
            raise ConnectionError("the link was torn down") from None

    with pytest.raises(KeyboardInterrupt) as info:
        run_interruptibly(body, clock=trio.testing.MockClock(autojump_threshold=0))
    assert isinstance(info.value.__cause__, ConnectionError)


def test_a_result_a_failure_and_the_handler_are_unchanged_without_a_signal() -> None:
    before = signal.getsignal(signal.SIGINT)

    async def answer(x: int) -> int:
        await trio.sleep(1)
        return x + 1

    async def fail() -> None:
        raise ValueError("plain failure")

    assert run_interruptibly(answer, 41, clock=trio.testing.MockClock(autojump_threshold=0)) == 42
    with pytest.raises(ValueError, match="plain failure"):
        run_interruptibly(fail)
    assert signal.getsignal(signal.SIGINT) is before


def _interrupt_once_on_the_line(
    argv: list[str], tmp_path: Path
) -> subprocess.CompletedProcess[str]:
    """Start ``python -m serialsocket ARGV PTY`` with no peer on the pty, wait
    for its first bytes on the line (it is connecting), then press Ctrl-C."""
    master, slave = pty.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    proc = subprocess.Popen(
        [sys.executable, "-m", "serialsocket", *argv, path],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        # A test run started in the background inherits SIGINT ignored.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        ready, _, _ = select.select([master], [], [], LIMIT)
        assert ready, "nothing was sent on the line"
        os.read(master, 4096)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=LIMIT)
    finally:
        proc.kill()
        os.close(master)
        os.close(slave)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


@pytest.mark.parametrize(
    "argv",
    [["connect"], ["kermit", "send", "payload.bin", "--port"]],
    ids=["netcat", "kermit"],
)
def test_ctrl_c_while_connecting_exits_130_without_a_traceback(
    argv: list[str], tmp_path: Path
) -> None:
    (tmp_path / "payload.bin").write_bytes(bytes(range(256)) * 8)
    done = _interrupt_once_on_the_line(argv, tmp_path)
    assert done.returncode == 130, done.stderr
    assert "Traceback" not in done.stderr
    assert done.stderr.strip().splitlines()[-1] == f"serialsocket {argv[0]}: interrupted"
