"""serialsocket.asyncio: the serial socket for asyncio (issue 24, section 2).

The scenarios of test_socket.py (both directions at once byte-exact, half
close, a listener that accepts the next connection, typed refused and
timed-out connects, the peer's abort with its reason, a dead link with its
report, a cancelled read that leaves the socket usable) run here against the
asyncio adapter, over a pty pair or an in-memory line; and the two adapters
talk to each other over a pty (the trio side in a thread of its own, as in a
real deployment).  asyncio has no virtual clock: these run on the wall clock
and assert outcomes, bytes and counts, never durations.
"""

from __future__ import annotations

import asyncio
import os
import queue
import random
import subprocess
import sys
import threading
import tty
from collections.abc import Awaitable, Callable, Iterator
from contextlib import contextmanager
from typing import Any

import pytest
import trio

import serialsocket
import serialsocket.asyncio as sa
import tcpstream
import tcpstream.asyncio as arm_asyncio
from serialsocket import EndpointConfig, LinkDeadError, PeerAborted, SocketStatistics, State
from tcpstream import Server, ServerConfig, commands
from tests.tcpstream.fakearm import FakeArm

GUARD = 30.0
"""Seconds any one test may take before it fails instead of hanging CI."""

PAYLOAD = bytes(range(256)) * 300  # every byte value, 76.8 KB: many windows' worth


def run(fn: Callable[[], Awaitable[None]]) -> None:
    async def guarded() -> None:
        async with asyncio.timeout(GUARD):
            await fn()

    asyncio.run(guarded())


class MemoryEnd:
    """One end of an in-memory line (an :class:`serialsocket.asyncio.AsyncPort`).

    ``cut`` silently drops everything written from then on, both ways: the
    ports stay up and the link goes silent, as on a line whose carrier died.
    ``error_rate``: each byte written has one bit flipped with this
    probability (a seeded RNG), as line noise does.
    """

    def __init__(self, line: MemoryLine, inbox: asyncio.Queue[bytes], peer: asyncio.Queue[bytes]):
        self._line, self._inbox, self._peer = line, inbox, peer

    async def read(self, max_bytes: int) -> bytes:
        return await self._inbox.get()

    async def write(self, data: bytes) -> None:
        line = self._line
        if line.error_rate:
            noisy = bytearray(data)
            for i in range(len(noisy)):
                if line.rng.random() < line.error_rate:
                    noisy[i] ^= 1 << line.rng.randrange(8)
                    line.flipped += 1
            data = bytes(noisy)
        if not line.cut:
            self._peer.put_nowait(bytes(data))
        await asyncio.sleep(0)

    async def aclose(self) -> None:
        await asyncio.sleep(0)


class MemoryLine:
    def __init__(self, error_rate: float = 0.0, seed: int = 1) -> None:
        ab: asyncio.Queue[bytes] = asyncio.Queue()
        ba: asyncio.Queue[bytes] = asyncio.Queue()
        self.cut = False
        self.error_rate = error_rate
        self.rng = random.Random(seed)
        self.flipped = 0
        self.a = MemoryEnd(self, ba, ab)
        self.b = MemoryEnd(self, ab, ba)


async def pair(
    a: sa.AsyncPort, b: sa.AsyncPort, config: EndpointConfig | None = None
) -> tuple[sa.AsyncioSerialSocket, sa.AsyncioSerialSocket]:
    server = asyncio.create_task(sa.accept(b, config))
    client = await sa.connect(a, config)
    return client, await server


async def exchange(
    a: sa.AsyncioSerialSocket, b: sa.AsyncioSerialSocket, ab: bytes, ba: bytes
) -> tuple[bytes, bytes]:
    """Both directions at once: each side writes, half-closes, and reads to EOF."""

    async def side(sock: sa.AsyncioSerialSocket, out: bytes) -> bytes:
        async def send() -> None:
            sock.write(out)
            await sock.drain()
            sock.write_eof()

        sender = asyncio.create_task(send())
        got = await sock.read()
        await sender
        return got

    got_b, got_a = await asyncio.gather(side(a, ab), side(b, ba))
    return got_a, got_b


def test_both_directions_at_once_byte_exact_over_a_pty() -> None:
    async def main() -> None:
        a, b = sa.open_pty_pair()
        client, server = await pair(a, b)
        back = PAYLOAD[::-1]
        got_at_server, got_at_client = await exchange(client, server, PAYLOAD, back)
        assert got_at_server == PAYLOAD
        assert got_at_client == back
        await asyncio.gather(client.aclose(), server.aclose())
        assert client.close_error is None
        assert server.close_error is None
        stats = client.statistics()
        assert isinstance(stats, SocketStatistics)
        assert stats.link.bytes_acknowledged == len(PAYLOAD)
        assert stats.link.bytes_delivered == len(back)
        assert stats.port is not None
        assert stats.port.bytes_out == stats.port_bytes_out > 0

    run(main)


def test_both_directions_at_once_byte_exact_over_a_noisy_line() -> None:
    """Bit errors both ways (1 byte in 2000): every damaged packet is rejected by
    its check and repaired by NAK or timeout; the data arrives exact, once."""

    async def main() -> None:
        line = MemoryLine(error_rate=5e-4, seed=7)
        client, server = await pair(line.a, line.b)
        back = PAYLOAD[::-1]
        got_at_server, got_at_client = await exchange(client, server, PAYLOAD, back)
        assert got_at_server == PAYLOAD
        assert got_at_client == back
        await asyncio.gather(client.aclose(), server.aclose())
        assert (client.close_error, server.close_error) == (None, None)
        assert line.flipped > 0
        links = [client.statistics().link, server.statistics().link]
        assert sum(st.check_failures + st.rejected for st in links) > 0
        assert sum(st.retransmissions for st in links) > 0

    run(main)


def test_half_close_keeps_the_other_direction_open() -> None:
    async def main() -> None:
        line = MemoryLine()
        client, server = await pair(line.a, line.b)
        client.write(b"question")
        client.write_eof()
        assert await server.read() == b"question"  # to EOF
        assert server.at_eof()
        with pytest.raises(RuntimeError, match="write_eof"):
            client.write(b"more")
        server.write(b"answer")
        await server.drain()
        assert await client.readexactly(6) == b"answer"
        await server.aclose()
        await client.aclose()
        assert (client.close_error, server.close_error) == (None, None)

    run(main)


def test_listener_resets_and_accepts_the_next_connection() -> None:
    async def main() -> None:
        line = MemoryLine()
        seen: list[bytes] = []
        async with sa.listen(line.b, EndpointConfig(linger=0.05)) as listener:

            async def serve_two() -> None:
                for _ in range(2):
                    sock = await listener.accept()
                    seen.append(await sock.read())
                    await sock.aclose()

            server = asyncio.create_task(serve_two())
            for text in (b"first", b"second"):
                async with sa.open_serial_socket(line.a) as sock:
                    sock.write(text)
                    sock.write_eof()
                    assert await sock.read() == b""
                assert sock.close_error is None
            await server
            assert listener.endpoint.statistics().state in {"linger", "closed", "listen"}
        assert seen == [b"first", b"second"]

    run(main)


def test_refused_and_timed_out_connects_are_typed_errors() -> None:
    async def main() -> None:
        line = MemoryLine()
        with pytest.raises(TimeoutError, match="no answer to connect"):
            await sa.connect(line.a, EndpointConfig(connect_timeout=0.5))

        line = MemoryLine()

        async def refuser() -> None:
            ep = serialsocket.Endpoint(EndpointConfig(auto_accept=False))
            ep.listen()
            loop = asyncio.get_running_loop()
            while data := await line.b.read(65536):
                ep.receive_data(data, loop.time())
                for event in ep.events():
                    if isinstance(event, serialsocket.ConnectionRequested):
                        ep.refuse("arm busy", loop.time())
                await line.b.write(ep.data_to_send(loop.time()))

        task = asyncio.create_task(refuser())
        with pytest.raises(ConnectionRefusedError, match="arm busy"):
            await sa.connect(line.a)
        task.cancel()

    run(main)


def test_peer_abort_reaches_the_reader_with_its_reason() -> None:
    async def main() -> None:
        line = MemoryLine()
        client, server = await pair(line.a, line.b)
        client.write(b"partial")
        assert await server.read(100) == b"partial"
        server.abort("operator pressed stop")
        await server.wait_closed()
        with pytest.raises(ConnectionError) as info:
            await client.read(100)
        assert isinstance(info.value.__cause__, PeerAborted)
        assert info.value.__cause__.reason == "operator pressed stop"
        await client.aclose()
        assert client.close_error is not None
        assert "the peer aborted the connection: operator pressed stop" in client.close_error
        assert server.close_error is not None
        assert "this side aborted the connection" in server.close_error

    run(main)


def test_a_silent_link_is_dead_with_a_report() -> None:
    async def main() -> None:
        line = MemoryLine()
        client, server = await pair(line.a, line.b, EndpointConfig(dead_after=1.0))
        client.write(b"x" * 1000)
        await client.wait_acknowledged()
        line.cut = True
        client.write(b"y" * 500)
        with pytest.raises(ConnectionError) as info:
            await client.read(100)
        cause = info.value.__cause__
        assert isinstance(cause, LinkDeadError)
        assert cause.report.bytes_acknowledged == 1000
        assert cause.report.bytes_in_flight + cause.report.bytes_unsent == 500
        assert client.endpoint.state is State.DEAD
        await client.aclose()
        assert client.close_error is not None
        assert "link dead" in client.close_error
        server.abort()
        await server.wait_closed()

    run(main)


def test_cancelled_read_and_drain_leave_the_socket_usable() -> None:
    async def main() -> None:
        line = MemoryLine()
        client, server = await pair(line.a, line.b)
        with pytest.raises(TimeoutError):
            async with asyncio.timeout(0.05):
                await server.read(100)
        client.write(b"still here")
        assert await server.readexactly(10) == b"still here"
        client.write(b"z" * 200_000)  # far more than the send buffer holds
        with pytest.raises(TimeoutError):
            async with asyncio.timeout(0.001):
                await client.drain()
        assert client.get_write_buffer_size() > 0
        got = await server.readexactly(200_000)  # the rest still arrives, once
        assert got == b"z" * 200_000
        server.write(b"and back")
        await server.drain()
        assert await client.readexactly(8) == b"and back"
        await asyncio.gather(client.aclose(), server.aclose())
        assert (client.close_error, server.close_error) == (None, None)

    run(main)


def test_an_exception_in_the_block_aborts_and_leaves_no_task_behind() -> None:
    async def main() -> None:
        line = MemoryLine()
        server_task = asyncio.create_task(sa.accept(line.b))
        opened: list[sa.AsyncioSerialSocket] = []

        async def use() -> None:
            async with asyncio.timeout(0.2), sa.open_serial_socket(line.a) as sock:
                opened.append(sock)
                sock.write(b"abc")
                await asyncio.sleep(10)

        with pytest.raises(TimeoutError):
            await use()
        (sock,) = opened
        server = await server_task
        assert await server.read(10) == b"abc"
        with pytest.raises(ConnectionError) as info:
            await server.read(10)
        assert isinstance(info.value.__cause__, PeerAborted)
        assert info.value.__cause__.reason == "connection interrupted"
        assert sock.close_error is not None
        await server.aclose()
        await asyncio.sleep(0)
        leftovers = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
        assert leftovers == []

    run(main)


def test_a_url_port_through_pyserial_loop() -> None:
    async def main() -> None:
        port = await sa.open_port("loop://", 115200)
        try:
            await port.write(b"\x01hello\r")
            got = b""
            while len(got) < 7:
                got += await port.read(100)
            assert got == b"\x01hello\r"
            assert port.statistics().bytes_out == 7
        finally:
            await port.aclose()
        with pytest.raises(OSError, match="was closed"):
            await port.read(1)

    run(main)


# -- the two adapters on one line ------------------------------------------------------


@contextmanager
def raw_pty() -> Iterator[tuple[int, str]]:
    """A raw pty: (the master fd, the slave's path); the slave fd is closed."""
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    name = os.ttyname(slave)
    try:
        yield master, name
    finally:
        os.close(master)
        os.close(slave)


@contextmanager
def in_trio_thread(
    main: Callable[[trio.lowlevel.FdStream], Awaitable[Any]], fd: int
) -> Iterator[queue.Queue[Any]]:
    """Run ``main`` over a trio stream on a duplicate of ``fd`` in a thread; its
    result (or exception) lands in the yielded queue."""
    results: queue.Queue[Any] = queue.Queue()

    def target() -> None:
        async def guarded() -> Any:
            with trio.fail_after(GUARD):
                return await main(trio.lowlevel.FdStream(os.dup(fd)))

        try:
            results.put(trio.run(guarded))
        except BaseException as exc:  # reported to the test
            results.put(exc)

    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    try:
        yield results
    finally:
        thread.join(GUARD)


@pytest.mark.parametrize("asyncio_side", ["connects", "listens"])
def test_the_asyncio_and_trio_sockets_talk_over_a_pty(asyncio_side: str) -> None:
    """Echo-reversed both ways: the trio socket on the master, the asyncio one on
    the slave through pyserial (the path a real device takes)."""

    async def trio_side(stream: trio.lowlevel.FdStream) -> tuple[int, str | None]:
        if asyncio_side == "connects":
            async with serialsocket.listen(stream) as listener:
                sock = await listener.accept()
                data = b""
                while chunk := await sock.receive_some():
                    data += chunk
                await sock.send_all(data[::-1])
                await sock.aclose()
        else:
            sock = await serialsocket.connect(stream)
            await sock.send_all(PAYLOAD)
            await sock.send_eof()
            data = b""
            while chunk := await sock.receive_some():
                data += chunk
            assert data == PAYLOAD[::-1]
            await sock.aclose()
        return len(data), sock.close_error

    async def asyncio_main(path: str) -> None:
        port = await sa.open_port(path, 115200)
        if asyncio_side == "connects":
            async with sa.open_serial_socket(port) as sock:
                sock.write(PAYLOAD)
                sock.write_eof()
                assert await sock.read() == PAYLOAD[::-1]
        else:
            async with sa.listen(port) as listener:
                sock = await listener.accept()
                data = await sock.read()
                sock.write(data[::-1])
                await sock.aclose()
        assert sock.close_error is None

    with raw_pty() as (master, path), in_trio_thread(trio_side, master) as results:
        run(lambda: asyncio_main(path))
        outcome = results.get(timeout=GUARD)
    if isinstance(outcome, BaseException):
        raise outcome
    assert outcome == (len(PAYLOAD), None)


def test_tcpstream_asyncio_client_over_the_asyncio_serial_socket() -> None:
    """open_connection's (reader, writer) pair carries the asyncio arm client to a
    trio arm server on the other end of a pty."""
    arm = FakeArm(move_time=0.01)

    async def arm_side(stream: trio.lowlevel.FdStream) -> None:
        async with serialsocket.listen(stream) as listener:
            sock = await listener.accept()
            async with Server(arm, ServerConfig(telemetry_every=0)) as server:
                await server.serve_stream(sock)

    async def controller(path: str) -> None:
        async def opener() -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
            return await sa.open_connection(path, baud=115200)

        async with arm_asyncio.AsyncioArmClient(opener, identity="aio-serial") as client:
            assert (await client.status()).feedback.p == (0.5, 0.0, 0.4)
            handle = await client.submit(commands.move_joint(2, 0.3))
            assert await handle.accepted() >= 0
            await handle.completed()
            assert client.pending == 0

    with raw_pty() as (master, path), in_trio_thread(arm_side, master) as results:
        run(lambda: controller(path))
        outcome = results.get(timeout=GUARD)
    if isinstance(outcome, BaseException):
        raise outcome
    assert [c.code for c in arm.executed] == [
        commands.CommandCode.STATUS,
        commands.CommandCode.MOVE_JOINT,
    ]


def test_importing_and_using_it_never_imports_trio() -> None:
    """With trio made unimportable, the asyncio adapter still runs a whole exchange."""
    code = """
import asyncio, sys
sys.modules["trio"] = None  # any 'import trio' now raises ImportError
import serialsocket.asyncio as sa

async def main():
    a, b = sa.open_pty_pair()
    server = asyncio.create_task(sa.accept(b))
    async with sa.open_serial_socket(a) as sock:
        peer = await server
        sock.write(b"no trio here")
        sock.write_eof()
        assert await peer.read() == b"no trio here"
        await peer.aclose()
    assert sock.close_error is None, sock.close_error

asyncio.run(main())
loaded = [m for m, mod in sys.modules.items() if mod is not None and m.split(".")[0] == "trio"]
print("trio modules:", sorted(loaded))
"""
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=GUARD, check=False
    )
    assert done.returncode == 0, done.stderr
    assert "trio modules: []" in done.stdout


def test_two_sockets_over_pyserial_socket_urls() -> None:
    """The URL port (a reader thread, executor writes) under a whole exchange: two
    ``socket://`` ports joined by a TCP null modem, as ser2net would join two lines."""

    async def main() -> None:
        joined: list[tuple[asyncio.StreamReader, asyncio.StreamWriter]] = []
        both = asyncio.Event()

        async def pipe(src: asyncio.StreamReader, dst: asyncio.StreamWriter) -> None:
            while data := await src.read(65536):
                dst.write(data)
                await dst.drain()

        async def on_connect(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            joined.append((reader, writer))
            if len(joined) == 2:
                both.set()
            await both.wait()
            other = joined[1] if joined[0][0] is reader else joined[0]
            await pipe(reader, other[1])

        modem = await asyncio.start_server(on_connect, "127.0.0.1", 0)
        url = f"socket://127.0.0.1:{modem.sockets[0].getsockname()[1]}"
        a, b = await sa.open_port(url), await sa.open_port(url)
        # Small, and patient: the URL port reads in a thread that waits for the
        # GIL while the loop works; on a loaded machine the default 2 s of
        # silence could pass for a dead link.
        client, server = await pair(a, b, EndpointConfig(dead_after=GUARD))
        ab, ba = PAYLOAD[:3000], PAYLOAD[:2000][::-1]
        got_at_server, got_at_client = await exchange(client, server, ab, ba)
        assert (got_at_server, got_at_client) == (ab, ba)
        await asyncio.gather(client.aclose(), server.aclose())
        assert (client.close_error, server.close_error) == (None, None)
        stats = client.statistics().port
        assert stats is not None
        assert stats.name == url
        modem.close()
        for _, writer in joined:
            writer.close()
        await modem.wait_closed()

    run(main)


def test_a_socket_url_port_reads_what_tcp_has_queued_in_one_call() -> None:
    """The asyncio port's reader thread reads socket:// as the trio port's
    does (tests/serialsocket/test_port.py): one recv of everything queued,
    not recv(1) per byte."""
    payload = bytes(range(256)) * 16  # 4096 bytes: one _THREAD_BURST

    async def main() -> None:
        peers: list[asyncio.StreamWriter] = []

        async def on_connect(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            peers.append(writer)

        modem = await asyncio.start_server(on_connect, "127.0.0.1", 0)
        port = await sa.open_port(f"socket://127.0.0.1:{modem.sockets[0].getsockname()[1]}")
        reads = 0
        read = port.serial.read

        def counted(size: int = 1) -> bytes:
            nonlocal reads
            reads += 1
            return bytes(read(size))

        port.serial.read = counted  # the reader thread's next read is counted
        while not peers:
            await asyncio.sleep(0.01)
        peers[0].write(payload)
        got = b""
        async with asyncio.timeout(GUARD):
            while len(got) < len(payload):
                got += await port.read(len(payload) - len(got))
        assert got == payload
        assert reads <= 100, reads
        await port.aclose()
        peers[0].close()
        modem.close()
        await modem.wait_closed()

    run(main)


def test_open_connection_streams_half_close_and_close() -> None:
    async def main() -> None:
        line = MemoryLine()
        server_task = asyncio.create_task(sa.accept(line.b))
        reader, writer = await sa.open_connection(line.a)
        server = await server_task
        server.write(b"telemetry")
        server.write_eof()
        assert await reader.read() == b"telemetry"  # to the peer's EOF
        assert reader.at_eof()
        writer.write(b"still writing after the peer's EOF")
        await writer.drain()
        assert writer.can_write_eof()
        writer.write_eof()
        assert await server.read() == b"still writing after the peer's EOF"  # and our EOF
        writer.close()
        await writer.wait_closed()
        await server.aclose()
        sock = writer.get_extra_info("socket")
        assert isinstance(sock, sa.AsyncioSerialSocket)
        assert (sock.close_error, server.close_error) == (None, None)

    run(main)


@pytest.mark.parametrize("deadline", [0.0, 0.0005, 0.002, 0.005, 0.01, 0.03])
def test_cancellation_at_any_moment_leaves_no_task_and_the_listener_serving(
    deadline: float,
) -> None:
    """Cancelled while connecting, writing or closing: the peer is told (or never
    connected), no task of ours is left, and the listener accepts the next one."""

    async def use(line: MemoryLine) -> None:
        async with asyncio.timeout(deadline), sa.open_serial_socket(line.a) as sock:
            for _ in range(50):
                sock.write(b"x" * 2000)
                await sock.drain()
            await asyncio.sleep(10)

    async def main() -> None:
        line = MemoryLine()
        async with sa.listen(line.b, EndpointConfig(linger=0.01)) as listener:
            with pytest.raises(TimeoutError):
                await use(line)
            mine = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
            # Only the listener's own two tasks remain.
            assert sorted(t.get_name() for t in mine) == [
                "serialsocket-reader",
                "serialsocket-writer",
            ]
            accepting = asyncio.create_task(listener.accept())
            async with sa.open_serial_socket(line.a) as sock:
                peer = await accepting
                sock.write(b"next")
                sock.write_eof()
                assert await peer.read() == b"next"
                await peer.aclose()
            assert sock.close_error is None

    run(main)


def test_the_public_names_are_pinned() -> None:
    assert sorted(sa.__all__) == [
        "AsyncPort",
        "AsyncioSerialListener",
        "AsyncioSerialPort",
        "AsyncioSerialSocket",
        "accept",
        "connect",
        "listen",
        "open_connection",
        "open_port",
        "open_pty_pair",
        "open_serial_socket",
        "serve",
    ]
    for name in sa.__all__:
        assert getattr(sa, name) is not None


def test_misuse_is_a_runtime_error_and_leaves_the_socket_usable() -> None:
    async def main() -> None:
        line = MemoryLine()
        client, server = await pair(line.a, line.b)
        first = asyncio.create_task(server.read(10))
        await asyncio.sleep(0)
        with pytest.raises(RuntimeError, match="already reading"):
            await server.read(10)
        client.write(b"one")
        assert await first == b"one"
        with pytest.raises(RuntimeError, match="before close"):
            await client.wait_closed()
        await asyncio.gather(client.aclose(), server.aclose())
        with pytest.raises(RuntimeError, match="was closed"):
            client.write(b"late")
        with pytest.raises(RuntimeError, match="was closed"):
            await client.read(1)
        await client.aclose()  # idempotent
        assert (client.close_error, server.close_error) == (None, None)

    run(main)


def test_the_expedited_lane_between_asyncio_sockets() -> None:
    """send_expedited / receive_expedited: ahead of queued data, whole, once."""

    async def main() -> None:
        line = MemoryLine()
        a, b = await pair(line.a, line.b)
        assert a.expedited
        assert b.expedited
        a.write(PAYLOAD)
        await a.send_expedited(b"stop now")
        assert await b.receive_expedited() == b"stop now"
        assert await b.readexactly(len(PAYLOAD)) == PAYLOAD
        with pytest.raises(ValueError, match="1024"):
            await a.send_expedited(bytes(2000))
        await a.aclose()
        await b.aclose()

    run(main)


def test_the_latest_value_lane_between_asyncio_sockets() -> None:
    """send_latest / receive_latest: the newest value arrives, in order, never twice."""

    async def main() -> None:
        line = MemoryLine()
        a, b = await pair(line.a, line.b)
        assert a.latest
        assert b.latest
        for n in range(1, 21):
            a.send_latest(n.to_bytes(4, "big"))
            await asyncio.sleep(0.001)
        got: list[int] = []
        while not got or got[-1] != 20:
            got.append(int.from_bytes(await b.receive_latest(), "big"))
        assert got == sorted(set(got))
        with pytest.raises(ValueError, match="1024"):
            a.send_latest(bytes(2000))
        await a.aclose()
        await b.aclose()
        with pytest.raises(RuntimeError):
            a.send_latest(b"after close")

    run(main)


def test_the_asyncio_client_sends_its_emergency_stop_on_the_lane() -> None:
    """The asyncio arm client finds the lane under open_connection's writer and
    sends EMERGENCY_STOP there; the trio arm takes it from there."""
    arm = FakeArm(move_time=600.0)
    seen: list[int] = []

    async def arm_side(stream: trio.lowlevel.FdStream) -> None:
        async with serialsocket.listen(stream) as listener:
            sock = await listener.accept()
            async with Server(arm, ServerConfig(telemetry_every=0)) as server:
                await server.serve_stream(sock)
                seen.append(server.statistics().emergency_stops)
                seen.append(sock.statistics().link.expedited_received)

    async def controller(path: str) -> None:
        async def opener() -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
            return await sa.open_connection(path, baud=115200)

        async with arm_asyncio.AsyncioArmClient(opener, identity="aio-lane") as client:
            move = await client.submit(commands.move_joint(2, 0.3))
            await move.accepted()
            await client.emergency_stop()
            with pytest.raises(tcpstream.CommandFailed):
                await move.completed()

    with raw_pty() as (master, path), in_trio_thread(arm_side, master) as results:
        run(lambda: controller(path))
        outcome = results.get(timeout=GUARD)
    if isinstance(outcome, BaseException):
        raise outcome
    assert seen == [1, 1]  # one stop, and it came on the lane


def test_early_data_rides_in_the_connection_request() -> None:
    """serialsocket/PROTOCOL.md section 13, through the asyncio connect."""

    async def main() -> None:
        line = MemoryLine()
        server_task = asyncio.create_task(sa.accept(line.b))
        client = await sa.connect(line.a, early_data=b"first words")
        server = await server_task
        client.write(b", then more")
        await client.drain()
        client.write_eof()
        assert await server.read() == b"first words, then more"
        assert client.statistics().link.early_delivered == len(b"first words")
        assert server.statistics().link.early_received == len(b"first words")
        await asyncio.gather(client.aclose(), server.aclose())
        with pytest.raises(ValueError, match="early_data"):
            await sa.connect(line.a, EndpointConfig(send_buffer=4), early_data=b"too long")

    run(main)
