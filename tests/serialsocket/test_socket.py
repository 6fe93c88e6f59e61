"""SerialSocket: trio's stream conformance checks and end-to-end behaviour, on virtual time."""

from __future__ import annotations

import random
from collections.abc import Awaitable, Callable

import pytest
import trio
import trio.testing

from linksim import DirectionConfig, LinkConfig, Outage, endpoint_config_for, serial_socket_pair
from linksim.link import ImpairedLink
from serialsocket import (
    EndpointConfig,
    LinkDeadError,
    PeerAborted,
    SerialSocket,
    State,
    accept,
    connect,
    listen,
)

from .borrowed import Borrowed


def run(fn: Callable[[], Awaitable[None]]) -> None:
    trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


LINKS = {
    "clean": LinkConfig.preset("clean"),
    "geo": LinkConfig.preset("geo"),
    "moon": LinkConfig.preset("moon"),
    "mars": LinkConfig.preset("mars"),
    # Lossy and fast: byte errors, lost bytes and noise bytes on a 0.1 s line
    # without a rate limit, so trio's 1 MiB duplex check takes seconds.  (The
    # rate-limited lossy presets, phone-2400 and noisy-moon, pass as well, at
    # about 35 s of CPU each; they are not part of the default run.)
    "lossy": LinkConfig.symmetric(
        DirectionConfig(delay=0.1, byte_error_rate=2e-4, loss=1e-4, noise=1e-4), seed=5
    ),
}
# The rate-limited Earth-Moon line: trio's duplex check moves 1 MiB each way
# at 9600 bit/s, about an hour of link time.  check_half_closeable_stream
# runs check_two_way_stream first, so moon and lossy run once, there.
HALF_CLOSEABLE = [
    "clean",
    "geo",
    "lossy",
    pytest.param("moon", marks=pytest.mark.slow),
    # Mars (2400 bit/s, 20 minutes each way): passes, in about three minutes
    # of CPU -- outside the default run; `make test-long` runs it.
    pytest.param("mars", marks=pytest.mark.long),
]


def maker_for(
    link_cfg: LinkConfig, nursery: trio.Nursery
) -> Callable[[], Awaitable[tuple[SerialSocket, SerialSocket]]]:
    cfg = endpoint_config_for(link_cfg)

    async def maker() -> tuple[SerialSocket, SerialSocket]:
        line = ImpairedLink(link_cfg, read_latency=16 * link_cfg.a_to_b.char_time)
        accepted: list[SerialSocket] = []

        async def do_accept() -> None:
            accepted.append(await accept(line.b, cfg, nursery=nursery))

        async with trio.open_nursery() as handshake:
            handshake.start_soon(do_accept)
            client = await connect(line.a, cfg, nursery=nursery)
        return client, accepted[0]

    return maker


@pytest.mark.parametrize("name", HALF_CLOSEABLE)
def test_check_half_closeable_stream(name: str) -> None:
    async def main() -> None:
        async with trio.open_nursery() as nursery:
            await trio.testing.check_half_closeable_stream(maker_for(LINKS[name], nursery), None)
            nursery.cancel_scope.cancel()

    run(main)


@pytest.mark.parametrize("name", ["clean", "geo"])
def test_check_two_way_stream(name: str) -> None:
    async def main() -> None:
        async with trio.open_nursery() as nursery:
            await trio.testing.check_two_way_stream(maker_for(LINKS[name], nursery), None)
            nursery.cancel_scope.cancel()

    run(main)


async def exchange(a: SerialSocket, b: SerialSocket, ab: bytes, ba: bytes) -> tuple[bytes, bytes]:
    got_b, got_a = bytearray(), bytearray()

    async def send(sock: SerialSocket, data: bytes) -> None:
        await sock.send_all(data)
        await sock.send_eof()

    async def recv(sock: SerialSocket, buf: bytearray) -> None:
        while chunk := await sock.receive_some():
            buf += chunk

    async with trio.open_nursery() as nursery:
        nursery.start_soon(send, a, ab)
        nursery.start_soon(send, b, ba)
        nursery.start_soon(recv, b, got_b)
        nursery.start_soon(recv, a, got_a)
    return bytes(got_b), bytes(got_a)


def test_noisy_moon_both_directions_at_once_byte_exact() -> None:
    async def main() -> None:
        ab = random.Random(1).randbytes(12_000)
        ba = bytes(range(256)) * 30
        async with serial_socket_pair("noisy-moon", seed=7) as (client, server):
            got_server, got_client = await exchange(client, server, ab, ba)
            assert got_server == ab
            assert got_client == ba
            with trio.fail_after(60):  # the last ACK is still on its way back
                while not client.endpoint.all_acknowledged:
                    await trio.sleep(0.1)
            stats = client.statistics()
            assert stats.link.bytes_acknowledged == len(ab)
            assert stats.port_bytes_out > len(ab)
            assert trio.current_time() < 300  # 12 KB at ~120 B/s with 1.3 s each way

    run(main)


def test_dead_link_is_a_broken_resource_with_a_report() -> None:
    cut = LinkConfig.symmetric(DirectionConfig(rate=9600, delay=0.5, outages=(Outage(20.0, 1e9),)))

    async def main() -> None:
        cfg = endpoint_config_for(cut, dead_after=30.0)
        async with serial_socket_pair(cut, endpoint=cfg) as (client, server):
            await client.send_all(b"before the outage")
            assert await server.receive_some() == b"before the outage"
            await trio.sleep(25.0)  # now inside the outage
            await client.send_all(b"x" * 500)

            async def keep_sending() -> None:
                while True:
                    await client.send_all(b"y" * 500)

            with pytest.raises(trio.BrokenResourceError) as info:
                await keep_sending()
            cause = info.value.__cause__
            assert isinstance(cause, LinkDeadError)
            assert cause.report.bytes_acknowledged == len(b"before the outage")
            assert cause.report.bytes_in_flight + cause.report.bytes_unsent >= 500
            assert "never sent" in str(cause)
            assert client.endpoint.state is State.DEAD

    run(main)


def test_listener_resets_and_accepts_the_next_connection() -> None:
    link_cfg = LinkConfig.preset("geo")
    cfg = endpoint_config_for(link_cfg)

    async def main() -> None:
        line = ImpairedLink(link_cfg)
        async with trio.open_nursery() as nursery, listen(line.b, cfg) as listener:
            for n in range(3):
                accepted: list[SerialSocket] = []

                async def do_accept(box: list[SerialSocket] = accepted) -> None:
                    box.append(await listener.accept())

                async with trio.open_nursery() as handshake:
                    handshake.start_soon(do_accept)
                    # A fresh client endpoint each time on the same line: the
                    # manipulator side resets and listens between sessions.
                    client = await connect(Borrowed(line.a), cfg, nursery=nursery)
                server = accepted[0]
                await client.send_all(f"session {n}".encode())
                assert await server.receive_some() == f"session {n}".encode()
                async with trio.open_nursery() as closing:
                    closing.start_soon(client.aclose)
                    closing.start_soon(server.aclose)
                assert server.endpoint.state in (State.LINGER, State.CLOSED)
            nursery.cancel_scope.cancel()

    run(main)


def test_refused_and_timed_out_connects_are_typed_errors() -> None:
    link_cfg = LinkConfig.preset("clean")

    async def main() -> None:
        line = ImpairedLink(link_cfg)
        async with trio.open_nursery() as nursery:
            with pytest.raises(TimeoutError, match="no answer to connect"):
                await connect(
                    Borrowed(line.a), EndpointConfig(connect_timeout=3.0), nursery=nursery
                )
            nursery.cancel_scope.cancel()

        line = ImpairedLink(link_cfg)
        async with trio.open_nursery() as nursery:
            server_cfg = EndpointConfig(auto_accept=False)

            async def refuser() -> None:
                from serialsocket import ConnectionRequested, Endpoint

                ep = Endpoint(server_cfg)
                ep.listen()
                try:
                    while data := await line.b.receive_some():
                        ep.receive_data(data, trio.current_time())
                        for event in ep.events():
                            if isinstance(event, ConnectionRequested):
                                ep.refuse("arm busy", trio.current_time())
                        await line.b.send_all(ep.data_to_send(trio.current_time()))
                except trio.BrokenResourceError:
                    return  # the refused client closed its end

            nursery.start_soon(refuser)
            with pytest.raises(ConnectionRefusedError, match="arm busy"):
                await connect(line.a, EndpointConfig(), nursery=nursery)
            nursery.cancel_scope.cancel()

    run(main)


def test_peer_abort_reaches_the_reader_with_its_reason() -> None:
    async def main() -> None:
        async with serial_socket_pair("geo") as (client, server):
            await client.send_all(b"partial")
            assert await server.receive_some() == b"partial"
            with trio.CancelScope() as scope:
                scope.cancel()
                await server.aclose()  # a cancelled close aborts
            with pytest.raises(trio.BrokenResourceError) as info:
                await client.receive_some()
            assert isinstance(info.value.__cause__, PeerAborted | LinkDeadError) or (
                info.value.__cause__ is not None
            )

    run(main)


def test_cancelled_receive_leaves_the_stream_usable() -> None:
    async def main() -> None:
        async with serial_socket_pair("geo") as (client, server):
            with trio.move_on_after(1.0):
                await server.receive_some()
            await client.send_all(b"still here")
            assert await server.receive_some() == b"still here"
            with trio.move_on_after(0.001):
                await client.send_all(b"z" * 200_000)  # cancelled part-way
            await server.send_all(b"and back")
            assert await client.receive_some() == b"and back"

    run(main)
