"""The asyncio client against the (trio) arm server over loopback TCP (issue 24).

The arm runs in a thread of its own (trio), the controller in asyncio on the
test's thread: the two libraries never share a loop, as in a real deployment.
These are wall-clock tests (real sockets); they assert outcomes, never durations.
"""

from __future__ import annotations

import ast
import asyncio
import pathlib
import queue
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from functools import partial
from typing import Any

import pytest
import trio

import tcpstream
import tcpstream.asyncio as arm_asyncio
from tcpstream import (
    AuthenticationFailed,
    CommandCode,
    CommandFailed,
    FailureReason,
    SessionClosed,
    commands,
    serve_tcp,
)

from .fakearm import FakeArm

KEY = b"0123456789abcdef-asyncio"
GUARD = 30.0
"""Seconds any one test may take before it fails instead of hanging CI."""


@contextmanager
def arm_server(arm: FakeArm, **options: Any) -> Iterator[int]:
    """A trio arm server on a free loopback port, in a thread; yields the port."""
    ports: queue.Queue[int] = queue.Queue()
    stop = threading.Event()

    def run() -> None:
        async def main() -> None:
            async with trio.open_nursery() as nursery:
                listeners = await nursery.start(partial(serve_tcp, arm, 0, **options))
                ports.put(listeners[0].socket.getsockname()[1])
                while not stop.is_set():
                    await trio.sleep(0.02)
                nursery.cancel_scope.cancel()

        trio.run(main)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        yield ports.get(timeout=10)
    finally:
        stop.set()
        thread.join(10)


def run(coro: Any) -> Any:
    async def guarded() -> Any:
        async with asyncio.timeout(GUARD):
            return await coro

    return asyncio.run(guarded())


def test_commands_results_and_typed_failures() -> None:
    arm = FakeArm(move_time=0.05)
    arm.fail[CommandCode.SQUEEZE] = FailureReason.NOT_GRASPING

    async def main() -> None:
        async with arm_asyncio.connect_tcp("127.0.0.1", port, key=KEY, identity="aio") as c:
            assert (await c.status()).feedback.p == (0.5, 0.0, 0.4)
            handles = [await c.submit(commands.move_joint(1 + i, 0.1)) for i in range(4)]
            positions = [await h.accepted() for h in handles]
            assert positions == sorted(positions)
            for h in handles:
                await h.completed()
            assert (await c.weigh()).aux[0] == 1.25
            with pytest.raises(CommandFailed) as failed:
                await c.squeeze(10.0)
            assert failed.value.reason is FailureReason.NOT_GRASPING
            # The failure barrier works the same: the next command runs.
            assert (await c.move_joints([0.25] * 6)).feedback.joints == (0.25,) * 6
            with pytest.raises(CommandFailed) as bad:
                await c.move_joint(9, 0.1)  # refused here, before the link
            assert bad.value.reason is FailureReason.BAD_ARGUMENT
            assert c.pending == 0

    with arm_server(arm, key=KEY) as port:
        run(main())
    assert arm.count(CommandCode.MOVE_JOINT) == 4
    assert arm.count(CommandCode.MOVE_JOINTS) == 1


def test_a_wrong_key_is_authentication_failed() -> None:
    async def main() -> None:
        with pytest.raises(AuthenticationFailed):
            async with arm_asyncio.connect_tcp("127.0.0.1", port, key=b"x" * 16):
                pass

    with arm_server(FakeArm(), key=KEY) as port:
        run(main())


def test_a_cut_connection_resumes_and_the_command_runs_once() -> None:
    arm = FakeArm(move_time=1.0)

    async def main() -> None:
        async with arm_asyncio.connect_tcp("127.0.0.1", port, key=KEY, reconnect_delay=0.1) as c:
            handle = await c.submit(commands.move_joints([0.4] * 6))
            await handle.accepted()
            assert c._writer is not None
            c._writer.transport.abort()  # the link dies mid-command
            result = await handle.completed()
            assert result.feedback.joints == (0.4,) * 6
            assert c.reconnects == 1

    with arm_server(arm, key=KEY, dead_time=30.0) as port:
        run(main())
    assert arm.count(CommandCode.MOVE_JOINTS) == 1


def test_a_deadline_around_the_block_unwinds_and_says_bye() -> None:
    arm = FakeArm(move_time=5.0)

    async def use() -> None:
        async with asyncio.timeout(0.5), arm_asyncio.connect_tcp("127.0.0.1", port) as c:
            await c.submit(commands.move_joint(1, 1.5))

    async def main() -> None:
        with pytest.raises(TimeoutError):
            await use()
        # The program goes on; the arm heard the BYE and stopped the move.
        for _ in range(200):
            if arm.halts:
                break
            await asyncio.sleep(0.01)

    with arm_server(arm) as port:
        run(main())
    assert arm.halts[0] is FailureReason.STOPPED


@pytest.mark.parametrize("deadline", [i * 0.01 for i in range(0, 30, 3)])
def test_cancellation_at_any_moment_leaves_no_task_behind(deadline: float) -> None:
    arm = FakeArm(move_time=0.05)

    async def use() -> None:
        async with (
            asyncio.timeout(deadline),
            arm_asyncio.connect_tcp("127.0.0.1", port, reconnect_attempts=0) as c,
        ):
            await c.status()
            await c.move_joint(1, 0.1)
            await asyncio.sleep(10)

    async def main() -> None:
        with pytest.raises(TimeoutError):
            await use()
        await asyncio.sleep(0)
        leftovers = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
        assert leftovers == []

    with arm_server(arm) as port:
        run(main())


def test_the_watchdog_ends_a_session_the_application_forgot() -> None:
    arm = FakeArm(move_time=30.0)

    async def main() -> None:
        async with arm_asyncio.connect_tcp("127.0.0.1", port, watchdog=0.5) as c:
            await c.submit(commands.move_joint(1, 0.1))
            await asyncio.sleep(1.5)  # the application hangs; no call
            with pytest.raises(SessionClosed, match="watchdog"):
                await c.status()

    with arm_server(arm) as port:
        run(main())
    assert arm.halts[0] is FailureReason.STOPPED


def test_the_asyncio_path_never_imports_trio() -> None:
    """tcpstream.asyncio and every tcpstream module it reaches are trio-free."""
    root = pathlib.Path(tcpstream.__file__).parent
    todo, seen = ["asyncio"], set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        tree = ast.parse((root / f"{name}.py").read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                assert not any(a.name.split(".")[0] == "trio" for a in node.names), name
            elif isinstance(node, ast.ImportFrom):
                assert (node.module or "").split(".")[0] != "trio", name
                if node.level == 1 and node.module:
                    todo.append(node.module)
                elif node.level == 1:
                    todo += [a.name for a in node.names if (root / f"{a.name}.py").exists()]
    assert {"_client_core", "_client_connection", "_connection"} <= seen
