"""A view of a port that does not close it (test helper).

A serial socket owns the port it runs on and closes it with itself; tests
that run several sockets in turn over one port (or keep a modem call up
after the socket) lend it through this wrapper instead.
"""

from __future__ import annotations

import trio


class Borrowed(trio.abc.Stream):
    """Forwards everything to ``inner`` except ``aclose``, which leaves it open."""

    def __init__(self, inner: trio.abc.Stream) -> None:
        self.inner = inner

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        await self.inner.send_all(data)

    async def wait_send_all_might_not_block(self) -> None:
        await self.inner.wait_send_all_might_not_block()

    async def receive_some(self, max_bytes: int | None = None) -> bytes | bytearray:
        return await self.inner.receive_some(max_bytes)

    async def aclose(self) -> None:
        await trio.lowlevel.checkpoint()
