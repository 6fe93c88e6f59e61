"""SerialSocket over real ptys through ``linksim relay`` (delay, errors, modems), and
over a raw pty pair (garbage between packets, cancellation).

These run on the wall clock with real I/O; every wait has a generous bound
that only stops a hang (no timing is asserted).
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
from collections.abc import Awaitable, Callable, Iterator
from contextlib import contextmanager

import pytest
import trio

from linksim.link._pair import connected_pair
from serialsocket import (
    EndpointConfig,
    LinkDeadError,
    SerialSocket,
    answer,
    connect,
    dial,
    hangup,
    open_port,
    open_pty_pair,
)

from .borrowed import Borrowed

GUARD = 120.0
# Real time on a shared 2-core machine: a test process may be starved for
# seconds.  The derived dead-link time on these fast lines is 2 s, so every
# test that is not about a dead link allows a minute of silence.
PATIENT = 60.0


def run(fn: Callable[[], Awaitable[None]]) -> None:
    async def guarded() -> None:
        with trio.fail_after(GUARD):
            await fn()

    trio.run(guarded)


@contextmanager
def relay(*options: str) -> Iterator[tuple[str, str]]:
    """``linksim relay`` in a subprocess (its own core); yields the two tty paths."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "linksim", "relay", "--json", *options],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        paths = json.loads(proc.stdout.readline())
        yield paths["a"], paths["b"]
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 0


async def exchange(a: SerialSocket, b: SerialSocket, ab: bytes, ba: bytes) -> tuple[bytes, bytes]:
    """Send both ways at once, half-close, read to EOF; returns (b got, a got)."""
    got_b, got_a = bytearray(), bytearray()

    async def send(sock: SerialSocket, data: bytes) -> None:
        view = memoryview(data)
        while view:  # in pieces, as an application writes
            await sock.send_all(view[:32768])
            view = view[32768:]
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


def test_one_mebibyte_each_way_at_once_through_an_impaired_relay() -> None:
    ab = random.Random(1).randbytes(1 << 20)
    ba = random.Random(2).randbytes(1 << 20)
    cfg = EndpointConfig(one_way_delay=0.002, max_packet_length=2048, window=31, dead_after=PATIENT)

    async def main() -> None:
        with relay("--delay", "0.002", "--ber", "2e-6", "--seed", "3") as (path_a, path_b):
            port_a, port_b = await open_port(path_a), await open_port(path_b)
            async with connected_pair(port_a, port_b, cfg) as (client, server):
                got_b, got_a = await exchange(client, server, ab, ba)
                assert got_b == ab
                assert got_a == ba
                stats = client.statistics().link
                assert stats.check_failures + server.statistics().link.check_failures > 0
                assert stats.retransmissions + server.statistics().link.retransmissions > 0

    run(main)


def test_dial_through_emulated_modems_then_transfer_then_hang_up() -> None:
    ab = random.Random(4).randbytes(40_000)
    ba = b"ready\n" * 1000
    cfg = EndpointConfig(one_way_delay=0.002, window=16, dead_after=PATIENT)
    timings = ("--dial-time", "0.1", "--ring-interval", "0.3", "--handshake-time", "0.1")

    async def main() -> None:
        with relay("--modem", "--delay", "0.002", *timings) as (path_a, path_b):
            port_a, port_b = await open_port(path_a, 2400), await open_port(path_b, 2400)
            calls = {}

            async def do_answer() -> None:
                calls["answer"] = await answer(port_b, rings=2)

            async with trio.open_nursery() as nursery:
                nursery.start_soon(do_answer)
                await trio.sleep(0.2)  # the answering side has reset its modem
                # S12=10: a 0.2 s escape guard time, so hanging up is quick.
                calls["dial"] = await dial(port_a, "5551234", init="ATS12=10")
            assert calls["dial"].result == calls["answer"].result == "CONNECT 2400"

            borrowed_a, borrowed_b = Borrowed(port_a), Borrowed(port_b)
            async with connected_pair(borrowed_a, borrowed_b, cfg) as (client, server):
                got_b, got_a = await exchange(client, server, ab, ba)
                assert (got_b, got_a) == (ab, ba)
            # The sockets are closed; the modems are still online: hang up.
            await hangup(port_a, guard_time=0.2)
            port_b_lines = b""
            with trio.move_on_after(10):
                while b"NO CARRIER" not in port_b_lines:
                    port_b_lines += await port_b.receive_some()
            assert b"NO CARRIER" in port_b_lines  # the far modem lost the carrier
            await port_a.aclose()
            await port_b.aclose()

    run(main)


def test_peer_that_disappears_mid_transfer_gives_the_dead_link_report() -> None:
    chunk = 4000
    # The listener is a fresh Python process: give it time to start before giving up.
    cfg = EndpointConfig(one_way_delay=0.002, dead_after=1.0, window=8, connect_timeout=30.0)

    async def main() -> None:
        with relay("--delay", "0.002") as (path_a, path_b):
            # The far side is a separate program, killed without warning.
            peer = subprocess.Popen(
                [sys.executable, "-m", "serialsocket", "listen", path_b, "--delay", "0.002"],
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,  # a pipe nobody reads would close its window
                stderr=subprocess.DEVNULL,
            )
            try:
                port = await open_port(path_a)
                async with trio.open_nursery() as nursery:
                    client = await connect(port, cfg, nursery=nursery)
                    queued = 0
                    data = os.urandom(chunk)

                    async def send_until_broken() -> None:
                        nonlocal queued
                        while True:
                            await client.send_all(data)
                            queued += chunk
                            if queued == 20 * chunk:
                                peer.send_signal(signal.SIGKILL)

                    with pytest.raises(trio.BrokenResourceError) as info:
                        await send_until_broken()
                    cause = info.value.__cause__
                    assert isinstance(cause, LinkDeadError)
                    report = cause.report
                    assert report.silence >= 1.0
                    assert report.bytes_acknowledged >= 1  # the transfer had started
                    # Every byte is accounted for: confirmed, maybe-arrived or never sent;
                    # the send_all that failed had handed over between 0 and `chunk` bytes.
                    total = report.bytes_acknowledged + report.bytes_in_flight + report.bytes_unsent
                    assert queued <= total <= queued + chunk
                    assert "acknowledged" in str(cause)
                    await client.aclose()
                    nursery.cancel_scope.cancel()
            finally:
                peer.kill()
                peer.wait(timeout=30)

    run(main)


class _Garbage(trio.abc.Stream):
    """A port that puts random junk on the line between the packets it is given."""

    def __init__(self, inner: trio.abc.Stream, seed: int) -> None:
        self.inner = inner
        self.rng = random.Random(seed)
        self.injected = 0

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        # Junk of every kind: printable text, control characters, stray SOH
        # (a false packet start) and CR, 8-bit bytes.
        junk = bytes(
            self.rng.choice(b"\x01\r\n~#&\x00\xff\x80 AZaz09")
            for _ in range(self.rng.randrange(40))
        )
        self.injected += len(junk)
        await self.inner.send_all(junk + bytes(data) + junk[::-1])

    async def wait_send_all_might_not_block(self) -> None:
        await self.inner.wait_send_all_might_not_block()

    async def receive_some(self, max_bytes: int | None = None) -> bytes | bytearray:
        return await self.inner.receive_some(max_bytes)

    async def aclose(self) -> None:
        await self.inner.aclose()


def test_garbage_between_packets_is_skipped() -> None:
    ab = random.Random(6).randbytes(200_000)
    ba = random.Random(7).randbytes(150_000)
    cfg = EndpointConfig(window=16, dead_after=PATIENT)

    async def main() -> None:
        raw_a, raw_b = open_pty_pair()
        noisy_a, noisy_b = _Garbage(raw_a, 1), _Garbage(raw_b, 2)
        async with connected_pair(noisy_a, noisy_b, cfg) as (client, server):
            got_b, got_a = await exchange(client, server, ab, ba)
            assert (got_b, got_a) == (ab, ba)
            for sock, far in ((server, noisy_a), (client, noisy_b)):
                stats = sock.statistics().link
                assert far.injected > 1000
                assert stats.garbage_bytes + stats.rejected > 0
                assert stats.resyncs > 0

    run(main)


def test_cancelled_receive_and_send_leave_the_stream_usable() -> None:
    cfg = EndpointConfig(window=4, send_buffer=8192, receive_buffer=20_000, dead_after=PATIENT)

    async def main() -> None:
        raw_a, raw_b = open_pty_pair()
        async with connected_pair(raw_a, raw_b, cfg) as (client, server):
            # receive_some cancelled while waiting: nothing lost, still usable.
            with trio.move_on_after(0.05) as scope:
                await server.receive_some()
            assert scope.cancelled_caught
            await client.send_all(b"first")
            assert await server.receive_some() == b"first"

            # send_all cancelled part-way (the peer is not reading, so the
            # buffers fill): some prefix was queued; it and everything sent
            # after it arrive in order, nothing else (trio: the stream may be
            # left in an unknown state; ours stays usable).
            data = random.Random(8).randbytes(200_000)
            with trio.move_on_after(0.5) as scope:
                await client.send_all(data)
            assert scope.cancelled_caught
            got = bytearray()

            async def read_to_eof() -> None:
                while chunk := await server.receive_some():
                    got.extend(chunk)

            async with trio.open_nursery() as nursery:
                nursery.start_soon(read_to_eof)  # the buffers are full: read meanwhile
                await client.send_all(b"<after the cancel>")
                await client.send_eof()
            assert got.endswith(b"<after the cancel>")
            prefix = bytes(got[: -len(b"<after the cancel>")])
            assert 0 < len(prefix) < len(data)
            assert data.startswith(prefix)

    run(main)
