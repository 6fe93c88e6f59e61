"""Cancellation at *every* await of the serial socket's context managers unwinds cleanly.

``open_serial_socket``, ``listen`` (with ``accept``), ``serve`` and ``aclose``
are run over an in-memory line on virtual time while an instrument counts the
scheduling steps of every task and cancels the scope around them all just
before step 1, 2, 3, ... until a run completes before the cancellation
lands.  Every await of opening, using and closing, in the client's task and
in the server's, is thus interrupted in turn (a deadline sweep only reaches
the awaits where virtual time passes).  Each run must end in the cancelled
scope -- no "Cancel scope stack corrupted", no other exception -- and leave
no task behind (the drivers' tasks and any system task included).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable

import pytest
import trio
import trio.lowlevel
import trio.testing

from linksim import DirectionConfig, LinkConfig, endpoint_config_for, open_impaired_link
from serialsocket import SerialSocket, listen, open_serial_socket, serve

LINE = LinkConfig.symmetric(DirectionConfig(rate=9600, delay=0.05), seed=1)
CONFIG = endpoint_config_for(LINE)
PAYLOAD = b"MOVE 0.3 0.1 0.5"
"""A short exchange: every await is still reached; longer data only repeats them."""
MAX_STEPS = 20_000
"""Far more steps than one run takes (a few hundred): a bound, not a guess."""


class CancelAtStep(trio.abc.Instrument):
    """Cancels ``scope`` just before the ``at``-th task step of the run; tracks live tasks."""

    def __init__(self, scope: trio.CancelScope, at: int) -> None:
        self.scope, self.at = scope, at
        self.steps = 0
        self.fired = False
        self.live: set[trio.lowlevel.Task] = set()

    def before_task_step(self, task: trio.lowlevel.Task) -> None:
        self.steps += 1
        if self.steps == self.at:
            self.scope.cancel()
            self.fired = True

    def task_spawned(self, task: trio.lowlevel.Task) -> None:
        self.live.add(task)

    def task_exited(self, task: trio.lowlevel.Task) -> None:
        self.live.discard(task)


async def _read_all(sock: SerialSocket) -> bytes:
    got = bytearray()
    while chunk := await sock.receive_some():
        got += chunk
    return bytes(got)


async def _client(port: trio.abc.Stream) -> None:
    async with open_serial_socket(port, CONFIG) as sock:
        await sock.send_all(PAYLOAD)
        await sock.send_eof()
        assert await _read_all(sock) == PAYLOAD


async def _echo(sock: SerialSocket) -> None:
    data = await _read_all(sock)
    await sock.send_all(data)
    await sock.send_eof()


async def with_listen(port_a: trio.abc.Stream, port_b: trio.abc.Stream) -> None:
    """The main task owns both context managers: ``listen`` and ``open_serial_socket``."""
    async with listen(port_b, CONFIG) as listener, trio.open_nursery() as nursery:

        async def serve_one() -> None:
            sock = await listener.accept()
            try:
                await _echo(sock)
            finally:
                await sock.aclose()

        nursery.start_soon(serve_one)
        await _client(port_a)


async def with_serve(port_a: trio.abc.Stream, port_b: trio.abc.Stream) -> None:
    """The main task runs ``serve`` (through ``nursery.start``) and the client."""
    async with trio.open_nursery() as nursery:
        await nursery.start(serve, port_b, _echo, CONFIG)
        await _client(port_a)
        nursery.cancel_scope.cancel()  # serve runs forever


Scenario = Callable[[trio.abc.Stream, trio.abc.Stream], Awaitable[None]]


def _run_cancelled_at(scenario: Scenario, at: int) -> CancelAtStep:
    """One whole run on a fresh line, cancelled at the main task's ``at``-th step."""
    holder: list[CancelAtStep] = []

    async def main() -> None:
        async with open_impaired_link(LINE) as (port_a, port_b):
            scope = trio.CancelScope()
            instrument = CancelAtStep(scope, at)
            holder.append(instrument)
            trio.lowlevel.add_instrument(instrument)
            try:
                with scope:
                    await scenario(port_a, port_b)
            finally:
                trio.lowlevel.remove_instrument(instrument)
            # Whatever the run started has ended with it (no system task either).
            assert not instrument.live, instrument.live

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    return holder[0]


@pytest.mark.parametrize("scenario", [with_listen, with_serve], ids=["listen", "serve"])
def test_cancellation_at_every_step_of_open_use_and_close_unwinds(scenario: Scenario) -> None:
    whole = _run_cancelled_at(scenario, MAX_STEPS)
    assert not whole.fired
    # Step 1, 2, 3, ... until the run ends before the cancellation would land.
    # (trio may order a batch of ready tasks either way, so a run's step count
    # can vary by a few; the sweep ends at the first run shorter than ``at``.)
    at = 1
    while _run_cancelled_at(scenario, at).fired:
        at += 1
    assert at > whole.steps * 0.9, (at, whole.steps)
