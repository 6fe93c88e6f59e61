"""Test plumbing: virtual time, in-memory streams, a server and clients wired together."""

from __future__ import annotations

import random
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from typing import Any

import trio
import trio.testing

from tcpstream import ArmClient, Server, ServerConfig

KEY = b"0123456789abcdef-test-key"


def trio_scheduler_rng() -> random.Random:
    """The RNG trio uses to order tasks that become runnable together.

    Seed it for a run that must be reproducible to the last task switch (trio
    reverses each batch of runnable tasks at random, and only pins the order
    under hypothesis).  A private name, so kept in this one place.
    """
    rng: random.Random = trio._core._run._r  # type: ignore[attr-defined]
    return rng


def run(fn: Callable[[], Awaitable[None]]) -> None:
    """Run ``fn`` on a virtual clock that jumps whenever every task is asleep."""
    trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


class Wiring:
    """A running server plus a stream factory that serves each new stream.

    ``client_streams`` keeps every controller-side stream handed out, so a test
    can break the current one (a forced disconnect).
    """

    def __init__(self, server: Server, nursery: trio.Nursery) -> None:
        self.server = server
        self._nursery = nursery
        self.client_streams: list[trio.abc.Stream] = []

    async def factory(self) -> trio.abc.Stream:
        client_end, server_end = trio.testing.memory_stream_pair()
        self._nursery.start_soon(self.server.serve_stream, server_end)
        self.client_streams.append(client_end)
        return client_end

    def client(self, **options: Any) -> ArmClient:
        return ArmClient(self.factory, **options)

    async def break_link(self) -> None:
        """Cut the newest connection without a goodbye (both ends see it fail)."""
        await trio.aclose_forcefully(self.client_streams[-1])


@asynccontextmanager
async def wired(executor: Any, config: ServerConfig | None = None) -> AsyncIterator[Wiring]:
    async with Server(executor, config) as server, trio.open_nursery() as nursery:
        wiring = Wiring(server, nursery)
        yield wiring
        nursery.cancel_scope.cancel()


class DeafStream(trio.abc.Stream):
    """A client-side stream that stops hearing the arm once ``deaf`` is set:
    what the controller sends still arrives, every reply is lost (with the
    link, in a cut)."""

    def __init__(self, inner: trio.abc.Stream) -> None:
        self.inner = inner
        self.deaf = False

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        await self.inner.send_all(data)

    async def wait_send_all_might_not_block(self) -> None:
        await self.inner.wait_send_all_might_not_block()

    async def receive_some(self, max_bytes: int | None = None) -> bytes:
        while True:
            data = bytes(await self.inner.receive_some(max_bytes))
            if not self.deaf or not data:
                return data

    async def aclose(self) -> None:
        await self.inner.aclose()


class SlowStream(trio.abc.Stream):
    """A client-side stream whose sends and close take some (virtual) time, as
    TCP's and a serial socket's do: a session can be over before the pump has
    finished with its stream, and a deadline swept in small steps lands on
    each await of open, use and close."""

    def __init__(self, inner: trio.abc.Stream, *, send_delay: float, close_delay: float) -> None:
        self.inner = inner
        self.send_delay = send_delay
        self.close_delay = close_delay

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        await trio.sleep(self.send_delay)
        await self.inner.send_all(data)

    async def wait_send_all_might_not_block(self) -> None:
        await self.inner.wait_send_all_might_not_block()

    async def receive_some(self, max_bytes: int | None = None) -> bytes:
        return await self.inner.receive_some(max_bytes)

    async def aclose(self) -> None:
        try:
            await trio.sleep(self.close_delay)
        finally:
            await trio.aclose_forcefully(self.inner)
