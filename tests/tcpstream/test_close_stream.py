"""The session's stream is closed without cutting a close that is still
making progress.

A serial socket's ``aclose`` waits until its backlog is acknowledged and the
peer's EOF has arrived, bounded by itself (no progress for ``close_timeout``,
or a dead link).  The pump gave it five seconds flat, then cancelled it: a
cancelled serial close aborts the connection, so at 2400 bit/s and 1.3 s one
way (a telemetry backlog to drain, a 2.6 s round trip for its ACKs) the arm
server aborted the link under the controller's own close, and ``linksim demo``
exited 1 about one run in three.
"""

from __future__ import annotations

import trio
import trio.testing

from tcpstream import ArmClient, Server, ServerConfig

from .fakearm import FakeArm
from .harness import run


class _SlowClose(trio.abc.HalfCloseableStream):
    """A stream whose close takes ``close_time`` (a serial socket draining)."""

    def __init__(
        self,
        inner: trio.StapledStream[trio.abc.SendStream, trio.abc.ReceiveStream],
        close_time: float,
    ) -> None:
        self.inner = inner
        self.close_time = close_time
        self.outcome = "open"

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        await self.inner.send_all(data)

    async def wait_send_all_might_not_block(self) -> None:
        await self.inner.wait_send_all_might_not_block()

    async def receive_some(self, max_bytes: int | None = None) -> bytes:
        return await self.inner.receive_some(max_bytes)

    async def send_eof(self) -> None:
        await self.inner.send_eof()

    async def aclose(self) -> None:
        if self.outcome != "open":
            await trio.lowlevel.checkpoint()
            return
        self.outcome = "closing"
        try:
            await trio.sleep(self.close_time)
        except trio.Cancelled:
            self.outcome = "cancelled"  # a serial socket aborts the link here
            raise
        finally:
            await trio.aclose_forcefully(self.inner)
        self.outcome = "closed"


def test_a_slow_but_progressing_close_is_not_cancelled() -> None:
    config = ServerConfig(rtt_hint=2.6)  # dead time 10.4 s: the peer is heard within it
    server_side: list[_SlowClose] = []

    async def main() -> None:
        async with Server(FakeArm(), config) as server, trio.open_nursery() as nursery:

            async def factory() -> trio.abc.Stream:
                client_end, server_end = trio.testing.memory_stream_pair()
                server_side.append(_SlowClose(server_end, close_time=8.0))
                nursery.start_soon(server.serve_stream, server_side[-1])
                return client_end

            async with ArmClient(factory, reconnect_attempts=0) as client:
                await client.status()
            with trio.fail_after(60):
                while server_side[0].outcome in ("open", "closing"):
                    await trio.sleep(0.5)
            nursery.cancel_scope.cancel()

    run(main)
    assert server_side[0].outcome == "closed"
