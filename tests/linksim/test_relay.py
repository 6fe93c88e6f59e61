"""The pty relay with real ptys, in-process and as ``linksim relay`` (bounded by timeouts)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import tty
from collections.abc import Awaitable, Callable

import pytest
import trio

from linksim import DirectionConfig, LinkConfig, ModemConfig, ModemPair, run_relay
from linksim.link import FaultAction, RelayStatistics, ScriptedFault

# Generous bounds: these tests move a few KB; a limit is only there to stop a hang.
LIMIT = 20.0


def open_tty(path: str) -> trio.lowlevel.FdStream:
    return trio.lowlevel.FdStream(os.open(path, os.O_RDWR | os.O_NOCTTY))


async def read_exactly(stream: trio.lowlevel.FdStream, n: int) -> bytes:
    got = bytearray()
    while len(got) < n:
        got += await stream.receive_some(n - len(got))
    return bytes(got)


async def read_until(stream: trio.lowlevel.FdStream, marker: bytes) -> bytes:
    got = bytearray()
    while marker not in got:
        got += await stream.receive_some(4096)
    return bytes(got)


def with_relay(
    config: LinkConfig,
    body: Callable[[str, str], Awaitable[None]],
    modems: ModemPair | None = None,
) -> RelayStatistics:
    result: list[RelayStatistics] = []

    async def main() -> None:
        stop = trio.Event()
        paths: list[str] = []
        ready = trio.Event()

        def on_ready(a: str, b: str) -> None:
            paths.extend([a, b])
            ready.set()

        async def relay() -> None:
            result.append(await run_relay(config, modems=modems, stop=stop, on_ready=on_ready))

        with trio.fail_after(LIMIT):
            async with trio.open_nursery() as nursery:
                nursery.start_soon(relay)
                await ready.wait()
                await body(paths[0], paths[1])
                stop.set()

    trio.run(main)
    return result[0]


def test_clean_relay_both_ways() -> None:
    data = bytes(range(256)) * 64  # every byte value: the ttys must be raw

    async def body(pa: str, pb: str) -> None:
        a, b = open_tty(pa), open_tty(pb)
        async with a, b, trio.open_nursery() as nursery:
            nursery.start_soon(a.send_all, data)
            assert await read_exactly(b, len(data)) == data
            await b.send_all(b"reply\r\n")
            assert await read_exactly(a, 7) == b"reply\r\n"

    stats = with_relay(LinkConfig(), body)
    assert stats.a_to_b.bytes_delivered == len(data)
    assert stats.b_to_a.bytes_delivered == 7


def test_impaired_relay_applies_the_model() -> None:
    # A scripted fault gives an exact, timing-independent result through real ptys.
    fault = ScriptedFault(FaultAction.CORRUPT, byte=10, xor=0x20)
    config = LinkConfig(a_to_b=DirectionConfig(rate=115200, delay=0.05, faults=(fault,)))

    async def body(pa: str, pb: str) -> None:
        a, b = open_tty(pa), open_tty(pb)
        async with a, b:
            await a.send_all(b"hello world, over")
            assert await read_exactly(b, 17) == b"hello worlD, over"

    stats = with_relay(config, body)
    assert stats.a_to_b.corrupted_scripted == 1
    assert stats.a_to_b.max_latency >= 0.05


def test_side_closing_and_reopening_keeps_relay_running() -> None:
    async def body(pa: str, pb: str) -> None:
        b = open_tty(pb)
        async with b:
            for round_ in range(3):
                a = open_tty(pa)
                async with a:
                    await a.send_all(b"round %d\n" % round_)
                    assert await read_exactly(b, 8) == b"round %d\n" % round_
                await trio.sleep(0.1)  # a stays closed: the master reads EIO meanwhile

    with_relay(LinkConfig(), body)


def test_modem_relay_dialogue() -> None:
    modems = ModemPair(ModemConfig(dial_time=0.05, ring_interval=0.2, handshake_time=0.05))

    async def body(pa: str, pb: str) -> None:
        a, b = open_tty(pa), open_tty(pb)
        async with a, b:
            await a.send_all(b"ATZ\r")
            assert await read_until(a, b"OK\r\n") == b"ATZ\r\r\nOK\r\n"
            await a.send_all(b"ATDT5551234\r")
            assert b"RING" in await read_until(b, b"RING\r\n")
            await b.send_all(b"ATA\r")
            assert (await read_until(b, b"CONNECT 2400\r\n")).endswith(b"\r\nCONNECT 2400\r\n")
            assert b"CONNECT 2400" in await read_until(a, b"CONNECT 2400\r\n")
            await a.send_all(b"through the modems")
            assert await read_exactly(b, 18) == b"through the modems"
            await trio.sleep(1.1)  # guard time (S12 = 1 s)
            await a.send_all(b"+++")
            assert await read_until(a, b"OK\r\n") == b"\r\nOK\r\n"
            await a.send_all(b"ATH\r")
            await read_until(a, b"OK\r\n")
            assert b"NO CARRIER" in await read_until(b, b"NO CARRIER\r\n")

    with_relay(LinkConfig(), body, modems)


def start_cli(*args: str) -> tuple[subprocess.Popen[str], dict[str, str]]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "linksim", "relay", "--json", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    return proc, json.loads(proc.stdout.readline())


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_cli_relay_json_and_clean_exit_on_signal(sig: signal.Signals) -> None:
    proc, paths = start_cli("--preset", "geo", "--seed", "3", "--stats", "--stats-interval", "0.2")
    try:
        assert set(paths) == {"a", "b"}
        fa = os.open(paths["a"], os.O_RDWR | os.O_NOCTTY)
        fb = os.open(paths["b"], os.O_RDWR | os.O_NOCTTY)
        os.write(fa, b"ping")
        got = b""
        deadline = time.monotonic() + LIMIT
        while len(got) < 4 and time.monotonic() < deadline:
            got += os.read(fb, 4)
        assert got == b"ping"
        os.close(fa)
        os.close(fb)
    finally:
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=LIMIT)
    assert proc.returncode == 0
    assert out == ""  # nothing on stdout after the paths line
    final = json.loads(err.strip().splitlines()[-1])
    assert final["a_to_b"]["bytes_delivered"] == 4


def test_cli_relay_duration_and_plain_paths() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "linksim", "relay", "--duration", "0.3", "--loss", "0.1"],
        capture_output=True,
        text=True,
        timeout=LIMIT,
        check=True,
    )
    lines = out.stdout.splitlines()
    assert len(lines) == 2
    assert all(line.startswith("/dev/") for line in lines)


def test_cli_relay_rejects_bad_values() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "linksim", "relay", "--loss", "1.5", "--duration", "0.1"],
        capture_output=True,
        text=True,
        timeout=LIMIT,
    )
    assert out.returncode == 2
    assert "argument --loss: must be a number in [0, 1], got '1.5'" in out.stderr


def test_a_tcp_serial_server_is_a_device() -> None:
    """``--device socket://HOST:PORT`` (ser2net style): bytes from a pty reach the
    TCP server through the line and its answers come back; the server closing
    the connection ends the relay with the reason."""
    outcome: dict[str, object] = {}

    async def main() -> None:
        with trio.fail_after(60):
            async with trio.open_nursery() as nursery:

                async def echo_once(stream: trio.SocketStream) -> None:
                    async with stream:
                        data = await stream.receive_some()
                        await stream.send_all(data.upper())
                    # closing: the relay's run ends

                listeners = await nursery.start(trio.serve_tcp, echo_once, 0)
                port = listeners[0].socket.getsockname()[1]
                master_fd, slave_fd = os.openpty()
                tty.setraw(slave_fd)
                slave_path = os.ttyname(slave_fd)
                master = trio.lowlevel.FdStream(master_fd)
                async with master:
                    relay_done = trio.Event()

                    async def relay() -> None:
                        try:
                            await run_relay(
                                LinkConfig.symmetric(DirectionConfig(delay=0.05)),
                                devices=[f"socket://127.0.0.1:{port}", slave_path],
                            )
                        except* ConnectionError as group:
                            outcome["ended"] = str(group.exceptions[0])
                        relay_done.set()

                    nursery.start_soon(relay)
                    await trio.sleep(0.3)
                    await master.send_all(b"hello arm")
                    got = b""
                    while len(got) < 9:
                        got += await master.receive_some()
                    outcome["answer"] = got
                    await relay_done.wait()
                os.close(slave_fd)
                nursery.cancel_scope.cancel()

    trio.run(main)
    assert outcome["answer"] == b"HELLO ARM"
    assert "the server closed the connection" in str(outcome["ended"])
