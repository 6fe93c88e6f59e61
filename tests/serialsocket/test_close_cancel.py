"""Cancellation at any await of the serial socket's context managers unwinds cleanly
(issue 17, finding 4, the serial half): a deadline swept over the whole life of a
pair -- connect, accept, transfer, close -- never corrupts trio's scope stack,
never leaks a task, and the next pair on a fresh line works."""

from __future__ import annotations

import trio
import trio.testing

from linksim import DirectionConfig, LinkConfig, serial_socket_pair

LINE = LinkConfig.symmetric(DirectionConfig(rate=9600, delay=0.05), seed=1)


def test_a_deadline_anywhere_in_open_use_and_close_unwinds() -> None:
    landed = 0
    deadlines = [i * 0.02 for i in range(60)]

    async def main() -> None:
        nonlocal landed
        for deadline in deadlines:
            with trio.move_on_after(deadline) as scope:
                async with serial_socket_pair(LINE) as (client, server):
                    await client.send_all(b"x" * 300)
                    got = b""
                    while len(got) < 300:
                        got += await server.receive_some()
                    await client.send_eof()
                    assert await server.receive_some() == b""
            landed += scope.cancelled_caught
        # Still usable afterwards: a whole exchange on a new pair.
        async with serial_socket_pair(LINE) as (client, server):
            await client.send_all(b"after")
            assert await server.receive_some() == b"after"

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    assert landed >= len(deadlines) // 3  # most deadlines land inside; the last ones do not
