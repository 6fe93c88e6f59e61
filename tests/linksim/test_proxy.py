"""``linksim proxy``: the line in front of a real TCP server (issue 24, section 5).

The timing model is checked exactly (sans-I/O, seeded); the proxy itself on
loopback sockets in real time, for what it delivers (every byte, in order, or
a reset where a cut says) and for the delay it adds (a lower bound only: a
slow machine adds time, it cannot remove the line's).
"""

from __future__ import annotations

import random
import subprocess
import sys
import time

import pytest
import trio

from linksim.cli import main
from linksim.link import (
    Cut,
    DirectionConfig,
    GilbertElliott,
    LinkConfig,
    Outage,
    TcpDirection,
    run_proxy,
)


def _model(**kw: object) -> TcpDirection:
    return TcpDirection(DirectionConfig(**kw), random.Random(1))  # type: ignore[arg-type]


def test_rate_and_delay() -> None:
    m = _model(rate=9600, delay=1.3)
    # 960 bytes at 960 B/s: one second on the wire, then 1.3 s of flight.
    assert m.send(960, 0.0) == pytest.approx(2.3)
    # Written at once, the next waits for the line.
    assert m.send(960, 0.0) == pytest.approx(3.3)
    # Written after the line went idle, it leaves at once.
    assert m.send(96, 10.0) == pytest.approx(11.4)


def test_arrivals_never_go_back_in_time_with_jitter() -> None:
    m = _model(delay=0.5, jitter=0.4)
    arrivals = [m.send(100, t * 0.01) for t in range(500)]
    assert arrivals == sorted(arrivals)
    assert all(a >= t * 0.01 + 0.5 for t, a in enumerate(arrivals))


def test_a_damaged_segment_stalls_one_rto_and_holds_what_follows() -> None:
    # Half the one-byte segments are hit: each waits one RTO (doubling when hit
    # again) and holds up everything behind it.
    m = TcpDirection(DirectionConfig(delay=1.0, byte_error_rate=0.5), random.Random(3), rtt=2.0)
    clean = TcpDirection(DirectionConfig(delay=1.0), random.Random(3), rtt=2.0)
    first = m.send(1, 0.0)
    assert first == pytest.approx(1.0) or first >= 1.0 + 2.2  # clean, or one RTO (2 + 0.2) late
    arrivals = [m.send(1, 0.0) for _ in range(200)]
    assert arrivals == sorted(arrivals)
    assert m.retransmissions > 50  # about half the segments
    assert max(arrivals) > clean.send(1, 0.0) + 2.2


def test_an_outage_holds_segments_until_it_ends() -> None:
    m = TcpDirection(
        DirectionConfig(delay=0.1, outages=(Outage(5.0, 8.0),)), random.Random(1), rtt=0.2
    )
    assert m.send(10, 1.0) == pytest.approx(1.1)
    held = m.send(10, 6.0)
    # Lost in the outage; resent one RTO (0.2 + 0.2) after it ends.
    assert held == pytest.approx(8.0 + 0.4 + 0.1)
    assert m.held_by_outage == 1


def test_bursts_hit_segments_and_the_model_is_deterministic() -> None:
    cfg = DirectionConfig(delay=0.2, burst=GilbertElliott(p_good_to_bad=0.01, p_bad_to_good=0.2))
    runs = []
    for _ in range(2):
        m = TcpDirection(cfg, random.Random(7), rtt=0.4)
        runs.append([m.send(100, t * 0.1) for t in range(100)])
        assert m.retransmissions > 0
    assert runs[0] == runs[1]


@pytest.mark.parametrize("text", ["sideways:10", "up:-1", "up", "down:x"])
def test_bad_cuts_are_refused(text: str) -> None:
    with pytest.raises(ValueError, match="up:BYTES or down:BYTES"):
        Cut.parse(text)


async def _echo_server(nursery: trio.Nursery) -> int:
    async def echo(stream: trio.SocketStream) -> None:
        async with stream:
            try:
                while data := await stream.receive_some():
                    await stream.send_all(data)
                await stream.send_eof()
            except trio.BrokenResourceError:
                pass

    listeners = await nursery.start(trio.serve_tcp, echo, 0)
    port: int = listeners[0].socket.getsockname()[1]
    return port


def test_every_byte_crosses_in_order_through_stalls_and_the_delay_is_there() -> None:
    config = LinkConfig.symmetric(
        DirectionConfig(rate=200_000, delay=0.15, byte_error_rate=1e-4, jitter=0.01), seed=4
    )
    payload = random.Random(9).randbytes(40_000)
    outcome: dict[str, object] = {}

    async def main_() -> None:
        with trio.fail_after(120):
            await nursery_body()

    async def nursery_body() -> None:
        async with trio.open_nursery() as nursery:
            server_port = await _echo_server(nursery)
            ready: list[int] = []
            stop = trio.Event()

            async def proxy() -> None:
                outcome["stats"] = await run_proxy(
                    config,
                    listen=("127.0.0.1", 0),
                    target=("127.0.0.1", server_port),
                    on_ready=lambda host, port: ready.append(port),
                    stop=stop,
                )

            nursery.start_soon(proxy)
            while not ready:
                await trio.sleep(0.01)
            stream = await trio.open_tcp_stream("127.0.0.1", ready[0])
            start = time.monotonic()
            await stream.send_all(b"x")
            assert await stream.receive_some(1) == b"x"
            outcome["round_trip"] = time.monotonic() - start
            got = bytearray()

            async def reader() -> None:
                while data := await stream.receive_some():
                    got.extend(data)

            async with trio.open_nursery() as inner:
                inner.start_soon(reader)
                await stream.send_all(payload)
                await stream.send_eof()
            outcome["echo"] = bytes(got)
            await stream.aclose()
            stop.set()
            while "stats" not in outcome:  # the proxy returns its counters
                await trio.sleep(0.01)
            nursery.cancel_scope.cancel()

    trio.run(main_)
    assert outcome["echo"] == payload
    assert isinstance(outcome["round_trip"], float)
    assert outcome["round_trip"] >= 0.3  # 0.15 s each way: a lower bound, never flaky
    stats = outcome["stats"]
    assert stats.bytes_up == stats.bytes_down == len(payload) + 1  # type: ignore[attr-defined]
    assert stats.retransmissions > 0  # type: ignore[attr-defined]


def test_a_cut_resets_both_sides_after_exactly_that_many_bytes() -> None:
    config = LinkConfig.symmetric(DirectionConfig(delay=0.01))
    received: list[bytes] = []
    client_saw: list[str] = []

    async def main_() -> None:
        with trio.fail_after(120):
            await nursery_body()

    async def nursery_body() -> None:
        async with trio.open_nursery() as nursery:

            async def sink(stream: trio.SocketStream) -> None:
                got = bytearray()
                try:
                    while data := await stream.receive_some():
                        got.extend(data)
                except trio.BrokenResourceError:
                    pass
                received.append(bytes(got))

            listeners = await nursery.start(trio.serve_tcp, sink, 0)
            server_port = listeners[0].socket.getsockname()[1]
            ready: list[int] = []

            async def proxy() -> None:
                await run_proxy(
                    config,
                    listen=("127.0.0.1", 0),
                    target=("127.0.0.1", server_port),
                    cuts=[Cut("up", 5000)],
                    on_ready=lambda host, port: ready.append(port),
                )

            nursery.start_soon(proxy)
            while not ready:
                await trio.sleep(0.01)
            stream = await trio.open_tcp_stream("127.0.0.1", ready[0])
            try:
                for _ in range(100):
                    await stream.send_all(bytes(1000))
                    await trio.sleep(0.005)
                client_saw.append("no reset")
            except trio.BrokenResourceError:
                client_saw.append("reset")
            with trio.move_on_after(5):
                while not received:
                    await trio.sleep(0.01)
            nursery.cancel_scope.cancel()

    trio.run(main_)
    assert received == [bytes(5000)]
    assert client_saw == ["reset"]


def test_the_command_line_refuses_bad_addresses(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["proxy", "--listen", "0", "--to", "127.0.0.1:0"])
    assert info.value.code == 2
    assert "--to needs the server's port" in capsys.readouterr().err


def test_the_command_line_runs_and_reports(tmp_path: object) -> None:
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "linksim",
            "proxy",
            "--listen",
            "0",
            "--to",
            "127.0.0.1:9",
            "--preset",
            "moon",
            "--json",
            "--stats",
            "--duration",
            "0.5",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert '"port":' in done.stdout
    assert '"connections": 0' in done.stderr
