"""The in-memory impaired link: trio conformance, exact timing on a virtual clock, bounds."""

from __future__ import annotations

from collections.abc import Awaitable, Callable

import pytest
import trio
import trio.testing

from linksim import DirectionConfig, LinkConfig, open_impaired_link
from linksim.link import ImpairedLink, LinkEnd


def run_virtual(fn: Callable[[], Awaitable[None]]) -> None:
    trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


def maker(
    config: LinkConfig, read_latency: float = 0.0
) -> Callable[[], Awaitable[tuple[LinkEnd, LinkEnd]]]:
    async def make() -> tuple[LinkEnd, LinkEnd]:
        link = ImpairedLink(config, read_latency=read_latency)
        return link.a, link.b

    return make


def clogged_maker(config: LinkConfig) -> Callable[[], Awaitable[tuple[LinkEnd, LinkEnd]]]:
    # rx_buffer=1 and one byte already on its way each way: send_all blocks
    # until the far end reads.
    async def make() -> tuple[LinkEnd, LinkEnd]:
        link = ImpairedLink(config, rx_buffer=1)
        await link.a.send_all(b"!")
        await link.b.send_all(b"!")
        return link.a, link.b

    return make


def test_conformance_clean() -> None:
    async def main() -> None:
        await trio.testing.check_half_closeable_stream(
            maker(LinkConfig()), clogged_maker(LinkConfig())
        )

    trio.run(main)


@pytest.mark.parametrize(
    "direction",
    [DirectionConfig(delay=0.25), DirectionConfig(rate=115200, delay=1.3)],
    ids=["delay", "rate-and-delay"],
)
def test_conformance_timing_only(direction: DirectionConfig) -> None:
    config = LinkConfig.symmetric(direction)

    async def main() -> None:
        # the checks push 1 MiB each way; a 0.5 s read latency keeps that to a
        # few thousand wakeups on the virtual clock
        await trio.testing.check_half_closeable_stream(maker(config, read_latency=0.5), None)

    run_virtual(main)


def test_byte_arrives_after_delay_plus_char_time() -> None:
    config = LinkConfig.symmetric(DirectionConfig(rate=1024, bits_per_char=8, delay=1.25))

    async def main() -> None:
        async with open_impaired_link(config) as (a, b):
            await trio.sleep(3.0)
            await a.send_all(b"x")
            assert await b.receive_some() == b"x"
            assert trio.current_time() == 3.0 + 1.25 + 8 / 1024
            # back-to-back characters pace at one char time each
            t0 = trio.current_time()
            await b.send_all(b"abcd")
            got = b""
            arrivals = []
            while len(got) < 4:
                got += await a.receive_some(1)
                arrivals.append(trio.current_time() - t0)
            assert got == b"abcd"
            assert arrivals == [1.25 + k / 128 for k in (1, 2, 3, 4)]

    run_virtual(main)


def test_rate_paces_writer_and_caps_throughput() -> None:
    # 2400 bit/s 8N1 = 240 B/s: 24 076 bytes occupy the line for 100.3 s; the
    # writer returns once the rest fits the 4096-byte tty buffer.
    config = LinkConfig.symmetric(DirectionConfig(rate=2400, delay=0.5))
    payload = bytes(range(256)) * 94 + b"0123456789ab"
    assert len(payload) == 24_076

    async def main() -> None:
        async with open_impaired_link(config) as (a, b):
            received = bytearray()
            done_writing = 0.0

            async def writer() -> None:
                nonlocal done_writing
                await a.send_all(payload)
                done_writing = trio.current_time()

            async with trio.open_nursery() as nursery:
                nursery.start_soon(writer)
                # Read in 10-second gulps (a per-byte reader costs one wakeup per byte).
                while len(received) < len(payload):
                    await trio.sleep(10.0)
                    received += await b.receive_some()
            assert bytes(received) == payload
            # bytes that had arrived by 100 s were read then; the rest by 110 s
            assert trio.current_time() == 110.0
            # blocked writers wake per 256 drained bytes (n_tty's WAKEUP_CHARS):
            # 4096 at once, then 78 x 256 as room opens, the last 12 when the
            # backlog is down to 3840 bytes
            assert len(payload) == 4096 + 78 * 256 + 12
            assert done_writing == pytest.approx((len(payload) - 3840 - 12) / 240, abs=1e-9)
            stats = a.send_statistics()
            assert stats.bytes_sent == stats.bytes_delivered == len(payload)
            assert stats.bytes_dropped == 0
            assert stats.max_latency == pytest.approx(0.5 + 4096 / 240, abs=256 / 240)

    run_virtual(main)


def test_hours_of_link_time_on_virtual_clock() -> None:
    config = LinkConfig.preset("moon")

    async def main() -> None:
        async with open_impaired_link(config) as (a, b):
            for i in range(3600):  # one command a second for an hour
                await a.send_all(b"%04d\n" % i)
                await trio.sleep(1.0)
            await a.send_eof()
            got = bytearray()
            while chunk := await b.receive_some():
                got += chunk
            assert bytes(got) == b"".join(b"%04d\n" % i for i in range(3600))
            assert trio.current_time() >= 3600.0

    run_virtual(main)


def test_eof_arrives_one_delay_later_after_data() -> None:
    async def main() -> None:
        async with open_impaired_link(LinkConfig.preset("geo")) as (a, b):
            await a.send_all(b"hi")
            await a.send_eof()
            assert await b.receive_some() == b"hi"
            assert trio.current_time() == 0.27
            assert await b.receive_some() == b""
            assert trio.current_time() == 0.27
            # the other direction still works after a's half-close
            await b.send_all(b"back")
            assert await a.receive_some() == b"back"

    run_virtual(main)


def test_lossy_link_statistics_add_up() -> None:
    config = LinkConfig.symmetric(
        DirectionConfig(rate=9600, loss=0.01, byte_error_rate=0.01, noise=0.01), seed=7
    )
    data = bytes(range(256)) * 40

    async def main() -> None:
        async with open_impaired_link(config) as (a, b):
            await a.send_all(data)
            await a.send_eof()
            got = bytearray()
            while chunk := await b.receive_some():
                got += chunk
            s = a.send_statistics()
            assert s == b.receive_statistics()
            assert s.bytes_sent == len(data)
            assert s.bytes_delivered == len(got) == len(data) - s.bytes_dropped + s.bytes_inserted
            assert s.bytes_dropped > 0
            assert s.bytes_corrupted > 0
            assert s.bytes_inserted > 0
            assert s.bytes_in_flight == 0

    run_virtual(main)


def test_rx_buffer_applies_back_pressure_without_rate() -> None:
    async def main() -> None:
        async with open_impaired_link(LinkConfig(), rx_buffer=1000) as (a, b):
            with trio.move_on_after(5) as scope:
                await a.send_all(bytes(1001))
            assert scope.cancelled_caught  # blocked: b never read
            assert a.send_statistics().bytes_sent == 1000
            assert len(await b.receive_some()) == 1000

    run_virtual(main)
