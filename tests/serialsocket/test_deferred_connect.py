"""The deferred connect (``connect(port, defer=True)``, PROTOCOL.md section 13):
the connection request goes out with the first write, carrying its bytes as
early data, as TCP Fast Open's connect-on-first-send.  Virtual time on the
Earth-Moon line (9600 bit/s, 1.3 s each way): every time asserted is exact
up to the line's transmit times."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator, Awaitable, Callable

import pytest
import trio
import trio.testing

from linksim import LinkConfig, endpoint_config_for
from linksim.link import ImpairedLink
from serialsocket import (
    ConnectionRequested,
    Endpoint,
    EndpointConfig,
    LineFailed,
    SerialListener,
    SerialSocket,
    State,
    connect,
    listen,
    open_serial_socket,
)

from .borrowed import Borrowed

MOON = LinkConfig.preset("moon")
CFG = endpoint_config_for(MOON)
ONE_WAY = MOON.a_to_b.delay
CPS = (MOON.a_to_b.rate or 0) / MOON.a_to_b.bits_per_char  # characters a second
INIT_TIME = 120 / CPS
"""An upper bound on an init's transmit time here: fewer than 120 characters
with 64 of early data (the init's bound at 128-character packets)."""


def _state(sock: SerialSocket) -> State:
    """The endpoint's state, read afresh (mypy keeps no narrowing across calls)."""
    return sock.endpoint.state


def _line_time(sock: SerialSocket) -> float:
    """Seconds on the line for what ``sock`` has written so far (the init alone,
    before any answer came back)."""
    return sock.statistics().port_bytes_out / CPS


def run(fn: Callable[[], Awaitable[None]]) -> None:
    trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


@contextlib.asynccontextmanager
async def _moon() -> AsyncIterator[tuple[ImpairedLink, trio.Nursery, SerialListener]]:
    """The Moon line with a listener at its b end and a nursery, all within 120 s."""
    line = ImpairedLink(MOON)
    with trio.fail_after(120):
        async with trio.open_nursery() as nursery, listen(line.b, CFG) as listener:
            yield line, nursery, listener


async def _accept_one(
    listener: SerialListener,
    into: list[tuple[float, SerialSocket]],
    client: list[SerialSocket] | None = None,
    sent: list[float] | None = None,
) -> None:
    sock = await listener.accept()
    into.append((trio.current_time(), sock))
    if client and sent is not None:
        sent.append(_line_time(client[0]))  # the client's init, on the line until now


def test_the_first_write_rides_in_the_connection_request() -> None:
    async def main() -> None:
        async with _moon() as (line, nursery, listener):
            accepted: list[tuple[float, SerialSocket]] = []
            clients: list[SerialSocket] = []
            init_time: list[float] = []
            nursery.start_soon(_accept_one, listener, accepted, clients, init_time)
            client = await connect(line.a, CFG, nursery=nursery, defer=True)
            clients.append(client)
            await trio.sleep(10.0)
            # Nothing on the line yet: the request waits for the first write.
            assert client.statistics().port_bytes_out == 0
            assert listener.endpoint.state is State.LISTEN
            assert _state(client) is State.IDLE
            written_at = trio.current_time()
            await client.send_all(b"STOP ARM")
            assert trio.current_time() == written_at  # queued, not waited for
            assert _state(client) is State.CONNECTING
            while not accepted:
                await trio.sleep(0.01)
            accepted_at, server = accepted[0]
            # Delivered with the accept, one way after the write.
            assert await server.receive_some() == b"STOP ARM"
            # One way plus the init's line time (the 8 bytes in it), to a
            # character: the link hands a packet over with its last one.
            assert 0 < init_time[0] < INIT_TIME
            assert accepted_at == pytest.approx(written_at + init_time[0] + ONE_WAY, abs=1.5 / CPS)
            assert server.endpoint.statistics().early_received == 8
            await client.send_all(b" then more")
            assert await server.receive_some() == b" then more"
            assert _state(client) is State.ESTABLISHED
            link = client.statistics().link
            assert (link.early_sent, link.early_delivered) == (8, 8)
            assert client.expedited
            assert server.expedited
            async with trio.open_nursery() as closing:
                closing.start_soon(client.aclose)
                closing.start_soon(server.aclose)
            assert client.close_error is None
            assert server.close_error is None

    run(main)


def test_a_receive_alone_sends_the_request_a_moment_later() -> None:
    async def main() -> None:
        async with _moon() as (line, nursery, listener):
            accepted: list[tuple[float, SerialSocket]] = []

            clients: list[SerialSocket] = []
            init_time: list[float] = []

            async def greet() -> None:
                await _accept_one(listener, accepted, clients, init_time)
                await accepted[0][1].send_all(b"arm ready")

            nursery.start_soon(greet)
            client = await connect(line.a, CFG, nursery=nursery, defer=True)
            clients.append(client)
            started = trio.current_time()
            # A first receive cancelled within the moment neither sends the
            # request nor postpones it.
            with trio.move_on_after(0.02):
                await client.receive_some()
            assert client.statistics().port_bytes_out == 0
            assert await client.receive_some() == b"arm ready"
            accepted_at, server = accepted[0]
            request_at = started + 0.05  # _REQUEST_GRACE, from the first receive
            assert 0 < init_time[0] < INIT_TIME
            assert accepted_at == pytest.approx(request_at + init_time[0] + ONE_WAY, abs=1.5 / CPS)
            assert client.statistics().link.early_sent == 0
            assert server.endpoint.statistics().early_received == 0
            await client.aclose()
            await server.aclose()
            nursery.cancel_scope.cancel()

    run(main)


def test_an_unanswered_request_fails_the_next_operations_with_the_connect_error() -> None:
    async def main() -> None:
        line = ImpairedLink(MOON)  # nobody listens at b
        cfg = EndpointConfig(connect_timeout=3.0)
        async with trio.open_nursery() as nursery:
            client = await connect(Borrowed(line.a), cfg, nursery=nursery, defer=True)
            await trio.sleep(5.0)  # the connect timeout counts from the request
            written_at = trio.current_time()
            await client.send_all(b"HELLO")
            with pytest.raises(trio.BrokenResourceError) as info:
                await client.receive_some()
            assert trio.current_time() == pytest.approx(written_at + 3.0)
            assert isinstance(info.value.__cause__, TimeoutError)
            assert "no answer to connect within 3.0 s" in str(info.value.__cause__)
            for operation in (
                client.send_all(b"more"),
                client.receive_some(),
                client.send_eof(),
                client.send_expedited(b"stop"),
            ):
                with pytest.raises(trio.BrokenResourceError) as again:
                    await operation
                assert isinstance(again.value.__cause__, TimeoutError)
            assert not client.expedited
            await client.aclose()
            assert client.close_error is not None
            assert "connecting failed: no answer to connect within 3.0 s" in client.close_error
            nursery.cancel_scope.cancel()

    run(main)


def test_a_refused_request_fails_with_the_refusal() -> None:
    async def main() -> None:
        line = ImpairedLink(MOON)

        async def refuser() -> None:
            ep = Endpoint(EndpointConfig(auto_accept=False))
            ep.listen()
            try:
                while data := await line.b.receive_some():
                    ep.receive_data(data, trio.current_time())
                    for event in ep.events():
                        if isinstance(event, ConnectionRequested):
                            ep.refuse("arm busy", trio.current_time())
                    await line.b.send_all(ep.data_to_send(trio.current_time()))
            except trio.BrokenResourceError:
                return

        async with trio.open_nursery() as nursery:
            nursery.start_soon(refuser)
            client = await connect(line.a, CFG, nursery=nursery, defer=True)
            await client.send_all(b"HELLO")
            with pytest.raises(trio.BrokenResourceError) as info:
                await client.receive_some()
            assert isinstance(info.value.__cause__, ConnectionRefusedError)
            assert "arm busy" in str(info.value.__cause__)
            # The answer came back one round trip after the write.
            assert 2 * ONE_WAY < trio.current_time() < 2 * ONE_WAY + 2 * INIT_TIME
            await client.aclose()
            nursery.cancel_scope.cancel()

    run(main)


def test_a_failed_port_surfaces_as_line_failed() -> None:
    async def main() -> None:
        a, b = trio.testing.memory_stream_pair()
        async with trio.open_nursery() as nursery:
            client = await connect(a, EndpointConfig(), nursery=nursery, defer=True)
            await b.aclose()  # the other end of the port goes away
            with pytest.raises(trio.BrokenResourceError) as info:
                await client.receive_some()
            assert isinstance(info.value.__cause__, LineFailed)
            await client.aclose()
            nursery.cancel_scope.cancel()

    run(main)


def test_closing_before_the_first_write_sends_nothing() -> None:
    async def main() -> None:
        line = ImpairedLink(MOON)
        heard = bytearray()

        async def peer() -> None:
            while data := await line.b.receive_some():
                heard.extend(data)

        async with trio.open_nursery() as nursery:
            nursery.start_soon(peer)
            client = await connect(line.a, CFG, nursery=nursery, defer=True)
            await trio.sleep(10.0)
            closed_at = trio.current_time()
            await client.aclose()
            assert trio.current_time() == closed_at  # nothing to wait for
            assert client.close_error is None
            assert client.statistics().port_bytes_out == 0
            with pytest.raises(trio.ClosedResourceError):
                await client.send_all(b"late")
            await trio.sleep(10.0)
            assert heard == b""
            nursery.cancel_scope.cancel()

    run(main)


def test_closing_after_the_first_write_delivers_it() -> None:
    async def main() -> None:
        line = ImpairedLink(MOON)
        got = bytearray()
        with trio.fail_after(120):
            async with trio.open_nursery() as nursery, listen(line.b, CFG) as listener:

                async def drain() -> None:
                    server = await listener.accept()
                    while data := await server.receive_some():
                        got.extend(data)
                    await server.aclose()

                nursery.start_soon(drain)
                client = await connect(line.a, CFG, nursery=nursery, defer=True)
                await client.send_all(b"MOVE 1 2 3" * 30)  # more than rides in the init
                await client.aclose()  # while the request is still on its way
                assert client.close_error is None
                assert bytes(got) == b"MOVE 1 2 3" * 30
                assert client.statistics().link.early_delivered > 0

    run(main)


def test_a_cancelled_receive_waiting_for_the_connection_leaves_the_socket_usable() -> None:
    async def main() -> None:
        async with _moon() as (line, nursery, listener):

            async def echo() -> None:
                server = await listener.accept()
                while data := await server.receive_some():
                    await server.send_all(data.upper())
                await server.aclose()

            nursery.start_soon(echo)
            client = await connect(line.a, CFG, nursery=nursery, defer=True)
            await client.send_all(b"ping")
            with trio.move_on_after(1.0) as scope:
                await client.receive_some()
            assert scope.cancelled_caught
            assert _state(client) is State.CONNECTING
            assert await client.receive_some() == b"PING"
            await client.send_all(b"again")
            assert await client.receive_some() == b"AGAIN"
            await client.aclose()
            assert client.close_error is None

    run(main)


def test_an_expedited_message_waits_for_the_connection() -> None:
    async def main() -> None:
        async with _moon() as (line, nursery, listener):
            accepted: list[tuple[float, SerialSocket]] = []
            nursery.start_soon(_accept_one, listener, accepted)
            client = await connect(line.a, CFG, nursery=nursery, defer=True)
            # Before: the lane asked for (the answer decides), and no
            # latest-value lane (send_latest cannot wait for one).
            assert (client.expedited, client.latest) == (True, False)
            await client.send_expedited(b"STOP")  # sends the request, waits for the answer
            assert _state(client) is State.ESTABLISHED
            assert (client.expedited, client.latest) == (True, True)
            while not accepted:
                await trio.sleep(0.01)
            server = accepted[0][1]
            assert await server.receive_expedited() == b"STOP"
            async with trio.open_nursery() as closing:
                closing.start_soon(client.aclose)
                closing.start_soon(server.aclose)

    run(main)


def test_defer_and_early_data_together_are_a_value_error() -> None:
    async def main() -> None:
        a, _b = trio.testing.memory_stream_pair()
        with pytest.raises(ValueError, match="defer"):
            await connect(a, EndpointConfig(), early_data=b"x", defer=True)

    run(main)


def test_open_serial_socket_defers_too() -> None:
    async def main() -> None:
        async with _moon() as (line, nursery, listener):

            async def reply() -> None:
                server = await listener.accept()
                assert await server.receive_some() == b"hi"
                await server.send_all(b"yo")
                assert await server.receive_some() == b""
                await server.aclose()

            nursery.start_soon(reply)
            async with open_serial_socket(line.a, CFG, defer=True) as client:
                assert client.statistics().port_bytes_out == 0
                await client.send_all(b"hi")
                assert await client.receive_some() == b"yo"
            assert client.close_error is None
            assert client.statistics().link.early_delivered == 2

    run(main)


def test_send_eof_alone_sends_the_request() -> None:
    async def main() -> None:
        async with _moon() as (line, nursery, listener):

            async def read_eof() -> None:
                server = await listener.accept()
                assert await server.receive_some() == b""
                await server.aclose()

            nursery.start_soon(read_eof)
            client = await connect(line.a, CFG, nursery=nursery, defer=True)
            await client.send_eof()
            assert _state(client) is State.CONNECTING
            assert await client.receive_some() == b""
            await client.aclose()
            assert client.close_error is None

    run(main)
