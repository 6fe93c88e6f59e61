"""Real loopback TCP (127.0.0.1 only, bounded): plain, TLS with trustme, and the blocking facade."""

from __future__ import annotations

import ssl
from functools import partial
from typing import Any

import pytest
import trio
import trustme

from tcpstream import (
    BlockingClient,
    CommandCode,
    FailureReason,
    SessionClosed,
    commands,
    connect_tcp,
    serve_tcp,
)

from .fakearm import FakeArm
from .harness import KEY

GUARD = 30.0
"""Seconds of wall time before a hung real-socket test fails instead of hanging."""


def _port(listeners: list[Any]) -> int:
    listener = listeners[0]
    sock = getattr(listener, "socket", None) or listener.transport_listener.socket
    port: int = sock.getsockname()[1]
    return port


@pytest.fixture(scope="module")
def tls() -> tuple[ssl.SSLContext, ssl.SSLContext]:
    ca = trustme.CA()
    server_ctx = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    ca.issue_cert("arm.test").configure_cert(server_ctx)
    client_ctx = ssl.create_default_context()
    ca.configure_trust(client_ctx)
    return server_ctx, client_ctx


def test_tls_session_with_key(tls: tuple[ssl.SSLContext, ssl.SSLContext]) -> None:
    server_ctx, client_ctx = tls
    arm = FakeArm(move_time=0.01)

    async def main() -> None:
        with trio.fail_after(GUARD):
            async with trio.open_nursery() as nursery:
                listeners = await nursery.start(
                    partial(serve_tcp, arm, 0, ssl_context=server_ctx, key=KEY)
                )
                async with connect_tcp(
                    "127.0.0.1",
                    _port(listeners),
                    ssl_context=client_ctx,
                    server_hostname="arm.test",
                    key=KEY,
                ) as c:
                    assert isinstance(c._pump.stream, trio.SSLStream)  # type: ignore[union-attr]
                    moved = await c.move_joints([0.5] * 6)
                    assert moved.feedback.joints == (0.5,) * 6
                nursery.cancel_scope.cancel()

    trio.run(main)
    assert arm.count(CommandCode.MOVE_JOINTS) == 1


def test_tls_client_refuses_an_untrusted_certificate(
    tls: tuple[ssl.SSLContext, ssl.SSLContext],
) -> None:
    server_ctx, _ = tls
    stranger = ssl.create_default_context()
    trustme.CA().configure_trust(stranger)  # trusts some other CA only
    arm = FakeArm()

    async def main() -> None:
        with trio.fail_after(GUARD):
            async with trio.open_nursery() as nursery:
                listeners = await nursery.start(partial(serve_tcp, arm, 0, ssl_context=server_ctx))
                with pytest.raises(SessionClosed, match="cannot reach the arm"):
                    async with connect_tcp(
                        "127.0.0.1",
                        _port(listeners),
                        ssl_context=stranger,
                        server_hostname="arm.test",
                    ):
                        pass
                nursery.cancel_scope.cancel()

    trio.run(main)
    assert arm.executed == []


def test_blocking_facade_over_tcp() -> None:
    arm = FakeArm(move_time=0.01)

    async def main() -> None:
        with trio.fail_after(GUARD):
            async with trio.open_nursery() as nursery:
                listeners = await nursery.start(partial(serve_tcp, arm, 0, key=KEY))
                port = _port(listeners)

                def controller() -> None:
                    with BlockingClient.tcp("127.0.0.1", port, key=KEY, timeout=10.0) as c:
                        assert c.status().feedback.p == (0.5, 0.0, 0.4)
                        assert c.move_joints([0.25] * 6).feedback.joints == (0.25,) * 6
                        assert c.weigh().aux[0] == 1.25
                        arm.move_time = 5.0
                        with pytest.raises(TimeoutError, match="may still run"):
                            c.send(commands.move_joint(1, 0.1), timeout=0.05)
                        c.emergency_stop()

                await trio.to_thread.run_sync(controller)
                nursery.cancel_scope.cancel()

    trio.run(main)
    assert arm.count(CommandCode.MOVE_JOINTS) == 1
    assert arm.count(CommandCode.MOVE_JOINT) == 1  # started, then stopped
    assert arm.halts[0] is FailureReason.STOPPED


def test_connection_refused_is_reported() -> None:
    async def main() -> None:
        with trio.fail_after(GUARD):
            listeners = await trio.open_tcp_listeners(0, host="127.0.0.1")
            port = _port(listeners)
            await listeners[0].aclose()  # nothing listens there now
            with pytest.raises(SessionClosed, match="cannot reach"):
                async with connect_tcp("127.0.0.1", port):
                    pass

    trio.run(main)
