"""The blocking facade over a raw pty pair (real threads and I/O; bounds are hang guards)."""

from __future__ import annotations

import threading
from collections.abc import Callable

import pytest
import trio

from serialsocket import BlockingSerialSocket, EndpointConfig, open_pty_pair

GUARD = 30.0  # seconds; only stops a hang
# dead_after: real threads on a shared machine may be starved for seconds.
CFG = EndpointConfig(window=8, dead_after=60.0)


def in_thread(fn: Callable[[], object]) -> Callable[[], object]:
    """Run ``fn`` in a thread; the returned function joins it and returns its result."""
    box: list[object] = []
    errors: list[BaseException] = []

    def target() -> None:
        try:
            box.append(fn())
        except BaseException as exc:
            errors.append(exc)

    t = threading.Thread(target=target, daemon=True)
    t.start()

    def join() -> object:
        t.join(GUARD)
        assert not t.is_alive(), "thread hung"
        if errors:
            raise errors[0]
        return box[0]

    return join


def connected_pair() -> tuple[BlockingSerialSocket, BlockingSerialSocket]:
    a, b = open_pty_pair()
    server = in_thread(lambda: BlockingSerialSocket.accept(b, CFG, timeout=GUARD))
    client = BlockingSerialSocket.connect(a, CFG, timeout=GUARD)
    accepted = server()
    assert isinstance(accepted, BlockingSerialSocket)
    return client, accepted


def recv_all(sock: BlockingSerialSocket) -> bytes:
    got = bytearray()
    while chunk := sock.recv(65536):
        got += chunk
    return bytes(got)


def test_exchange_half_close_and_close() -> None:
    request = bytes(range(256)) * 400  # 100 KB, every byte value
    reply = b"done\n"
    client, server = connected_pair()
    with client:
        srv = in_thread(lambda: (recv_all(server), server.sendall(reply), server.shutdown()))
        client.sendall(request)
        client.shutdown()
        assert recv_all(client) == reply
        got, _, _ = srv()  # type: ignore[misc]
        assert got == request
        stats = client.statistics()
        assert stats.link.bytes_acknowledged == len(request)
        assert stats.port is not None
        assert stats.port.bytes_out == stats.port_bytes_out > len(request)
        closing = in_thread(server.close)
    closing()
    with pytest.raises(trio.ClosedResourceError):
        client.recv(1)
    client.close()  # idempotent


def test_recv_timeout_loses_nothing_and_the_socket_stays_usable() -> None:
    client, server = connected_pair()
    try:
        with pytest.raises(TimeoutError, match=r"recv timed out after 0\.05 s"):
            server.recv(100, timeout=0.05)
        client.sendall(b"after the timeout")
        got = b""
        while len(got) < 17:
            got += server.recv(100)
        assert got == b"after the timeout"
    finally:
        closing = in_thread(server.close)
        client.close()
        closing()


def test_connect_without_a_listener_times_out() -> None:
    a, b = open_pty_pair()
    with pytest.raises(TimeoutError, match="no answer to connect"):
        BlockingSerialSocket.connect(a, EndpointConfig(connect_timeout=0.3))
    trio.run(b.aclose)


def test_accept_timeout() -> None:
    a, b = open_pty_pair()
    with pytest.raises(TimeoutError, match=r"connecting timed out after 0\.2 s"):
        BlockingSerialSocket.accept(b, CFG, timeout=0.2)
    trio.run(a.aclose)
