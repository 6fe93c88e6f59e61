"""The deferred connect through the asyncio adapter (``serialsocket.asyncio.connect(
port, defer=True)``): the request goes out with the first write.  The trio
twin, with the times, is test_deferred_connect.py; asyncio has no virtual
clock, so these assert bytes, counts and errors, never durations."""

from __future__ import annotations

import asyncio

import pytest
import trio

import serialsocket
import serialsocket.asyncio as sa
import tcpstream.asyncio as arm_asyncio
from serialsocket import EndpointConfig, State
from tcpstream import Server, ServerConfig
from tests.tcpstream.fakearm import FakeArm

from .test_asyncio_socket import GUARD, MemoryLine, in_trio_thread, raw_pty, run


def test_the_first_write_rides_in_the_connection_request() -> None:
    async def main() -> None:
        line = MemoryLine()
        client = await sa.connect(line.a, defer=True)
        await asyncio.sleep(0.1)
        assert client.statistics().port_bytes_out == 0  # nothing until the first write
        assert client.endpoint.state is State.IDLE
        assert client.expedited  # asked for; the answer decides
        server_task = asyncio.create_task(sa.accept(line.b))
        client.write(b"STOP ARM")
        server = await server_task
        assert await server.read(100) == b"STOP ARM"
        assert server.statistics().link.early_received == 8
        server.write(b"stopped")
        assert await client.read(100) == b"stopped"
        assert client.statistics().link.early_delivered == 8
        await asyncio.gather(client.aclose(), server.aclose())
        assert (client.close_error, server.close_error) == (None, None)

    run(main)


def test_a_read_alone_sends_the_request_a_moment_later() -> None:
    async def main() -> None:
        line = MemoryLine()
        client = await sa.connect(line.a, defer=True)
        server_task = asyncio.create_task(sa.accept(line.b))
        reading = asyncio.create_task(client.read(100))
        server = await server_task
        server.write(b"arm ready")
        assert await reading == b"arm ready"
        assert client.statistics().link.early_sent == 0
        await asyncio.gather(client.aclose(), server.aclose())

    run(main)


def test_an_unanswered_request_fails_the_next_operations_with_the_connect_error() -> None:
    async def main() -> None:
        line = MemoryLine()  # nobody listens at b
        client = await sa.connect(line.a, EndpointConfig(connect_timeout=0.5), defer=True)
        client.write(b"HELLO")
        with pytest.raises(ConnectionError) as info:
            await client.read(100)
        assert isinstance(info.value.__cause__, TimeoutError)
        assert "no answer to connect within 0.5 s" in str(info.value.__cause__)
        with pytest.raises(ConnectionError) as again:
            client.write(b"more")
        assert isinstance(again.value.__cause__, TimeoutError)
        await client.aclose()
        assert client.close_error is not None
        assert "connecting failed: no answer to connect" in client.close_error

    run(main)


def test_closing_before_the_first_write_sends_nothing() -> None:
    async def main() -> None:
        line = MemoryLine()
        client = await sa.connect(line.a, defer=True)
        await client.aclose()
        assert client.close_error is None
        assert client.statistics().port_bytes_out == 0
        assert line.b._inbox.empty()
        with pytest.raises(RuntimeError, match="closed"):
            client.write(b"late")

    run(main)


def test_a_cancelled_read_waiting_for_the_connection_leaves_the_socket_usable() -> None:
    async def main() -> None:
        line = MemoryLine()
        client = await sa.connect(line.a, defer=True)
        client.write(b"ping")
        with pytest.raises(TimeoutError):
            async with asyncio.timeout(0.2):
                await client.read(100)  # nobody listens yet: the init is resent
        assert client.endpoint.state is State.CONNECTING

        async def echo() -> sa.AsyncioSerialSocket:
            server = await sa.accept(line.b)  # takes the first init, answers the copies
            server.write((await server.read(100)).upper())
            return server

        server_task = asyncio.create_task(echo())
        assert await client.read(100) == b"PING"
        server = await server_task
        await asyncio.gather(client.aclose(), server.aclose())
        assert (client.close_error, server.close_error) == (None, None)
        assert server.statistics().link.early_received == 4  # delivered once

    run(main)


def test_the_asyncio_arm_client_hello_rides_in_the_request() -> None:
    """open_connection(defer=True) under tcpstream's asyncio client: its HELLO is
    the first write, so its head rides in the init (as much as the init takes)."""
    early: list[int] = []

    async def arm_side(stream: trio.lowlevel.FdStream) -> None:
        async with serialsocket.listen(stream) as listener:
            sock = await listener.accept()
            early.append(sock.statistics().link.early_received)
            async with Server(FakeArm(move_time=0.01), ServerConfig(telemetry_every=0)) as server:
                await server.serve_stream(sock)

    async def controller(path: str) -> None:
        async def opener() -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
            return await sa.open_connection(path, baud=115200, defer=True)

        async with arm_asyncio.AsyncioArmClient(opener, identity="aio-deferred") as client:
            assert (await client.status()).feedback.p == (0.5, 0.0, 0.4)

    with raw_pty() as (master, path), in_trio_thread(arm_side, master) as results:
        run(lambda: controller(path))
        outcome = results.get(timeout=GUARD)
    if isinstance(outcome, BaseException):
        raise outcome
    assert len(early) == 1
    assert early[0] > 0
