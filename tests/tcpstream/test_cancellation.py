"""Cancellation at any await of the client's context manager unwinds cleanly.

Finding 4 of issue 17: inside ``trio.move_on_after(1.0)``, submitting a long
move and leaving ``async with connect_tcp(...)`` killed the program with
"Cancel scope stack corrupted" -- ``aclose()`` was cancelled while waiting for
the command and the client's nursery was never exited.
"""

from __future__ import annotations

from functools import partial

import pytest
import trio
import trio.testing

from tcpstream import ArmClient, CommandCode, FailureReason, Server, connect_tcp, serve_tcp
from tcpstream import commands as cmds

from .fakearm import FakeArm
from .harness import SlowStream, run

GUARD = 30.0
"""Wall-clock guard for the loopback test (a hang fails it instead of hanging CI)."""


def test_a_deadline_around_the_block_over_loopback_tcp() -> None:
    """The review's reproduction, as the README recommends bounding waits."""
    arm = FakeArm(move_time=3.0)

    async def main() -> None:
        with trio.fail_after(GUARD):
            async with trio.open_nursery() as nursery:
                listeners = await nursery.start(partial(serve_tcp, arm, 0))
                port = listeners[0].socket.getsockname()[1]
                with trio.move_on_after(1.0) as scope:
                    async with connect_tcp("127.0.0.1", port) as client:
                        await client.submit(cmds.move_joint(1, 1.5))
                assert scope.cancelled_caught
                # The program goes on: the arm heard our BYE and halted the move.
                with trio.fail_after(5.0):
                    while not arm.halts:
                        await trio.sleep(0.01)
                nursery.cancel_scope.cancel()

    trio.run(main)
    assert arm.count(CommandCode.MOVE_JOINT) == 1
    assert arm.halts[0] is FailureReason.STOPPED


@pytest.mark.parametrize("wait_for_outcome", [False, True])
def test_cancellation_injected_at_every_moment_of_open_use_and_close(
    wait_for_outcome: bool,
) -> None:
    """Sweep a deadline over the whole life of a client, 1 ms apart: whatever
    await it lands on, the block unwinds (no RuntimeError, no exception group,
    no task left behind), and the arm ends up halted or finished, never
    running a command on its own with nobody connected for long."""
    arm = FakeArm(move_time=0.2)
    landed = 0
    deadlines = [i * 0.001 for i in range(320)]

    async def main() -> None:
        nonlocal landed
        async with Server(arm) as server, trio.open_nursery() as nursery:

            async def factory() -> trio.abc.Stream:
                client_end, server_end = trio.testing.memory_stream_pair()
                nursery.start_soon(server.serve_stream, server_end)
                return SlowStream(client_end, send_delay=0.003, close_delay=0.005)

            for deadline in deadlines:
                with trio.move_on_after(deadline) as scope:
                    async with ArmClient(factory, reconnect_attempts=0) as client:
                        handle = await client.submit(cmds.move_joint(1, 0.01))
                        if wait_for_outcome:
                            await handle.completed()
                landed += scope.cancelled_caught
                # Let the arm notice the goodbye before the next client comes.
                await trio.sleep(1.0)
                assert server.statistics().controller is None
            nursery.cancel_scope.cancel()

    run(main)
    # Most deadlines cut somewhere inside; the last ones let the block finish.
    assert landed >= len(deadlines) // 2
    assert 0 < arm.count(CommandCode.MOVE_JOINT) < len(deadlines)


def test_the_bye_says_what_kind_of_ending_not_the_local_exception(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The client's exception text is local detail: it no longer crosses the wire."""
    import logging

    from .harness import wired

    async def main() -> None:
        async with wired(FakeArm()) as w:
            with pytest.raises(ValueError, match="secret"):
                async with w.client():
                    raise ValueError("secret local detail")
            await trio.sleep(1.0)

    with caplog.at_level(logging.INFO, logger="tcpstream._server"):
        run(main)
    ended = [r.getMessage() for r in caplog.records if "session ended" in r.getMessage()]
    assert ended, caplog.text
    assert "controller error (ValueError)" in ended[0]
    assert "secret" not in caplog.text
