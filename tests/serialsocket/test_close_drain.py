"""A close never aborts a link that is still making progress (issue 17, finding 5).

``SerialSocket.aclose`` used to wait a fixed dead-link interval from the moment
it was called, however much data was still draining, then abort: the listener
exited 1 with 258 081 of 262 144 bytes while connect exited 0.  Now the close
waits as long as our data keeps being acknowledged, and says (``close_error``)
when it did not complete.  Virtual time, seeded link.
"""

from __future__ import annotations

import random

import trio
import trio.testing

from linksim import DirectionConfig, LinkConfig, endpoint_config_for, serial_socket_pair
from serialsocket import EndpointConfig


def _run(fn):  # type: ignore[no-untyped-def]
    return trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


LINE = LinkConfig.symmetric(DirectionConfig(rate=2400, delay=0.2, byte_error_rate=1e-3), seed=5)


def test_a_close_with_a_long_backlog_waits_for_it_and_completes() -> None:
    data = random.Random(3).randbytes(20_000)  # ~90 s of line time at 2400 bit/s
    # A dead-link interval far shorter than the drain: the old close gave up
    # after it although every packet kept being acknowledged.
    endpoint = endpoint_config_for(LINE, dead_after=8.0, send_buffer=65_536)
    got = bytearray()
    outcome: dict[str, object] = {}

    async def main() -> None:
        async with serial_socket_pair(LINE, endpoint=endpoint) as (client, server):

            async def read_all() -> None:
                while chunk := await server.receive_some():
                    got.extend(chunk)
                await server.send_eof()

            async with trio.open_nursery() as nursery:
                nursery.start_soon(read_all)
                await client.send_all(data)  # returns once queued, long before delivered
                started = trio.current_time()
                await client.aclose()
                outcome["close_took"] = trio.current_time() - started
                outcome["error"] = client.close_error

    _run(main)
    assert bytes(got) == data
    assert outcome["error"] is None
    assert outcome["close_took"] > 8.0  # it outlasted the dead-link interval, draining


def test_a_close_with_no_progress_gives_up_and_says_so() -> None:
    """The peer stops acknowledging (its line goes dead in our direction): after
    close_timeout without progress the close is abandoned, with a report."""
    dead = LinkConfig(
        a_to_b=DirectionConfig(rate=2400, delay=0.2),
        b_to_a=DirectionConfig(rate=2400, delay=0.2),
    )
    endpoint = endpoint_config_for(dead, dead_after=30.0)
    outcome: dict[str, object] = {}

    async def main() -> None:
        async with serial_socket_pair(dead, endpoint=endpoint) as (client, server):
            client.close_timeout = 5.0
            await client.send_all(b"x" * 5000)
            # The server never reads: its window closes and nothing more is acked.
            await client.aclose()
            outcome["error"] = client.close_error
            await server.aclose()

    _run(main)
    error = outcome["error"]
    assert isinstance(error, str)
    assert error == (
        "the connection did not close cleanly: this side aborted the connection: "
        "close made no progress for 5.0 s; sent: 5000 bytes acknowledged, 0 in flight "
        "(may or may not have arrived), 0 never sent; "
        "received: 0 bytes from the peer, its EOF not received"
    )


def test_without_hints_a_close_on_a_long_line_waits_by_the_measured_round_trip() -> None:
    """The close's patience came from the hints (2 s without any), so on a
    1.3 s line every close without hints gave up before an ACK could return:
    ``serialsocket connect`` exited 1 with 0 of 8192 bytes acknowledged
    through a relay at 2400 bit/s.  Now it is the endpoint's dead-link
    interval, which follows the measured round trip."""
    line = LinkConfig.symmetric(DirectionConfig(rate=2400, delay=1.3), seed=2)
    data = random.Random(4).randbytes(8192)
    got = bytearray()
    outcome: dict[str, object] = {}

    async def main() -> None:
        async with serial_socket_pair(line, endpoint=EndpointConfig()) as (client, server):

            async def read_all() -> None:
                while chunk := await server.receive_some():
                    got.extend(chunk)
                await server.send_eof()

            async with trio.open_nursery() as nursery:
                nursery.start_soon(read_all)
                await client.send_all(data)
                await client.aclose()
                outcome["error"] = client.close_error

    _run(main)
    assert bytes(got) == data
    assert outcome["error"] is None
