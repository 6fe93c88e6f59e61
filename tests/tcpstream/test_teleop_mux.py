"""The stream mux: two trio streams over one, commands ahead of samples."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator

import pytest
import trio
import trio.testing

from tcpstream.teleop import MuxChannel, StreamMux, open_mux


@contextlib.asynccontextmanager
async def _pair() -> AsyncIterator[tuple[StreamMux, StreamMux]]:
    a, b = trio.testing.memory_stream_pair()
    async with open_mux(a) as ma, open_mux(b) as mb:
        yield ma, mb


@pytest.mark.parametrize("channel", ["commands", "teleop"])
def test_each_channel_is_a_conforming_two_way_stream(channel: str) -> None:
    async def main() -> None:
        async with trio.open_nursery() as nursery:

            async def make() -> tuple[MuxChannel, MuxChannel]:
                a, b = trio.testing.memory_stream_pair()
                ma, mb = StreamMux(a), StreamMux(b)
                await nursery.start(ma.run)
                await nursery.start(mb.run)
                return getattr(ma, channel), getattr(mb, channel)

            await trio.testing.check_two_way_stream(make, None)
            nursery.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))


def test_commands_go_ahead_of_queued_samples() -> None:
    async def main() -> None:
        async with _pair() as (ma, mb):
            await ma.teleop.send_all(b"s" * 5000)  # five frames of samples waiting
            await ma.commands.send_all(b"STOP")
            order: list[str] = []

            async def read(ch: MuxChannel, name: str, n: int) -> None:
                got = 0
                while got < n:
                    got += len(await ch.receive_some())
                    order.append(name)

            async with trio.open_nursery() as nursery:
                nursery.start_soon(read, mb.commands, "command", 4)
                nursery.start_soon(read, mb.teleop, "samples", 5000)
            # The writer was already writing the first sample frame; the command is next.
            assert order.index("command") <= 1
            assert ma.frames_out == [1, 5]

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))


def test_backlog_counts_commands_ahead_of_samples() -> None:
    async def main() -> None:
        a, _b = trio.testing.memory_stream_pair()
        mux = StreamMux(a)  # not running: nothing leaves
        await mux.commands.send_all(b"c" * 10)
        await mux.teleop.send_all(b"t" * 56)
        assert mux.backlog(0) == 10
        assert mux.backlog(1) == 66

    trio.run(main)
