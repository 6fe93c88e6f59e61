"""Kermit streaming over a serial socket: the reliable transport below does the
repairs, so Kermit sends without an ACK per packet and keeps the line busy.

On virtual time (MockClock), over the in-memory impaired link: the serial
socket's own ARQ (issue 20's) repairs byte errors; Kermit, streaming, sees a
clean stream.  The goodput is compared with what the serial socket alone moves
for the same bytes on the same line.
"""

from __future__ import annotations

import pathlib
import random
from collections.abc import Awaitable, Callable
from typing import TypeVar

import pytest
import trio
import trio.testing

from linksim import DirectionConfig, LinkConfig, serial_socket_pair
from serialsocket.kermit import KermitConfig, KermitStatistics, kermit_receive, kermit_send

T = TypeVar("T")
SIZE = 40_000
LINE = LinkConfig.symmetric(DirectionConfig(rate=19_200, delay=0.25, byte_error_rate=1e-5), seed=3)


def _run(fn: Callable[[], Awaitable[T]]) -> T:
    return trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


def _kermit_seconds(tmp_path: pathlib.Path, config: KermitConfig) -> tuple[float, KermitStatistics]:
    tmp_path.mkdir()
    src = tmp_path / "src.bin"
    src.write_bytes(random.Random(1).randbytes(SIZE))
    out = tmp_path / "out"
    out.mkdir()

    async def main() -> tuple[float, KermitStatistics]:
        async with serial_socket_pair(LINE) as (client, server):
            t0 = trio.current_time()
            async with trio.open_nursery() as nursery:
                nursery.start_soon(kermit_receive, server, out, config)
                stats = await kermit_send(client, [src], config)
            return trio.current_time() - t0, stats

    seconds, stats = _run(main)
    assert (out / "src.bin").read_bytes() == src.read_bytes()
    return seconds, stats


def _socket_seconds(size: int) -> float:
    """The serial socket alone moving ``size`` random bytes on the same line."""
    data = random.Random(1).randbytes(size)

    async def main() -> float:
        async with serial_socket_pair(LINE) as (client, server):
            t0 = trio.current_time()
            got = bytearray()

            async def read() -> None:
                while len(got) < size:
                    got.extend(await server.receive_some())

            async with trio.open_nursery() as nursery:
                nursery.start_soon(read)
                await client.send_all(data)
            assert bytes(got) == data
            return trio.current_time() - t0

    return _run(main)


HINTS = {"delay": 0.25, "rate": 19_200}


def test_streaming_over_a_serial_socket_keeps_the_socket_busy(tmp_path: pathlib.Path) -> None:
    """Kermit's own bytes (its prefixes and framing) cross the socket at >= 0.9
    of the rate at which the socket alone moves that many bytes."""
    streaming, stats = _kermit_seconds(tmp_path / "s", KermitConfig(streaming=True, **HINTS))
    # Nothing was NAKed or damaged; the only resends are of Z, whose ACK waits
    # until the socket has drained its buffer (the timer backs off meanwhile).
    assert stats.naks_received == stats.damaged == 0
    assert stats.retransmissions == stats.timeouts
    # S, F, A, Z (and its resends) and B were answered, no D packet; all D
    # packets were long.
    assert stats.packets_received == 5 + stats.retransmissions
    assert stats.data_packet_length == 1000
    base = _socket_seconds(stats.bytes_sent)
    print(f"socket alone {base:.1f} s, Kermit streaming {streaming:.1f} s: {base / streaming:.3f}")
    assert base / streaming >= 0.9, (base, streaming)


@pytest.mark.parametrize("window", [1, 4])
def test_streaming_beats_small_windows_on_a_delayed_socket(
    tmp_path: pathlib.Path, window: int
) -> None:
    streaming, _ = _kermit_seconds(tmp_path / "s", KermitConfig(streaming=True, **HINTS))
    windowed, _ = _kermit_seconds(
        tmp_path / "w", KermitConfig(window=window, streaming=False, **HINTS)
    )
    assert streaming < windowed


def test_a_serial_socket_port_streams_by_default(tmp_path: pathlib.Path) -> None:
    """``streaming=None`` (the default): kermit_send and kermit_receive see a
    SerialSocket and offer streaming, as C-Kermit's SET RELIABLE AUTO does."""
    _, stats = _kermit_seconds(tmp_path / "auto", KermitConfig(**HINTS))
    assert stats.packets_received == 5 + stats.retransmissions  # no ACK of any D
