"""Exactly once under attack: forgotten identities, restarted arms, cuts at any moment.

The arm remembers a bounded number of controller identities.  When it cannot
prove whether a command ran -- it forgot the identity, or it restarted -- it
says so in the GRANT, and the client settles every unconfirmed command with
:class:`~tcpstream.OutcomeUnknown` instead of re-sending it (PROTOCOL.md 9).
"""

from __future__ import annotations

import pytest
import trio
import trio.testing

from tcpstream import (
    ArmClient,
    CommandCode,
    OutcomeUnknown,
    Server,
    ServerConfig,
    SessionClosed,
    commands,
)

from .fakearm import FakeArm
from .harness import DeafStream, SlowStream, run, wired


def test_a_forgotten_identity_never_gets_its_command_run_twice() -> None:
    """The review's scenario: request 1 runs, its replies are lost in a cut, 16
    other identities push the controller out of the arm's memory; on reconnect
    the command must be reported outcome-unknown, not re-sent and run again."""
    arm = FakeArm(move_time=1.0)
    config = ServerConfig(rtt_hint=0.2)  # dead time 1.4 s: the lease lapses quickly

    async def main() -> None:
        async with Server(arm, config) as server, trio.open_nursery() as nursery:
            streams: list[DeafStream] = []

            async def factory() -> trio.abc.Stream:
                client_end, server_end = trio.testing.memory_stream_pair()
                nursery.start_soon(server.serve_stream, server_end)
                wrapped = DeafStream(client_end)
                streams.append(wrapped)
                return wrapped  # type: ignore[return-value]

            victim = ArmClient(factory, identity="victim", reconnect_delay=20.0)
            async with victim:
                streams[-1].deaf = True
                handle = await victim.submit(commands.move_joint(1, 0.1))
                await trio.sleep(3.0)  # ran at the arm; ACCEPTED/COMPLETED never heard
                await trio.aclose_forcefully(streams[-1].inner)
                await trio.sleep(2.0)  # the lease lapses (dead time 1.4 s)
                for i in range(16):
                    other = ArmClient(factory, identity=f"other-{i}", reconnect_attempts=0)
                    async with other:
                        await other.status()
                # Before the fix: re-sent, run again, and reported plain COMPLETED.
                with pytest.raises(OutcomeUnknown, match="outcome unknown"):
                    await handle.completed()
                assert victim.reconnects == 1
                # The next command runs normally (a fresh memory for this identity).
                await victim.move_joint(2, 0.1)
            nursery.cancel_scope.cancel()

    run(main)
    moves = [c for c in arm.executed if c.code is CommandCode.MOVE_JOINT]
    assert [(int(c.args[0]), c.args[1]) for c in moves] == [(1, 0.1), (2, 0.1)]


def test_submit_during_reconnects_waits_for_the_session_and_leaks_nothing() -> None:
    """Finding 3: submit() racing a cut raised IllegalTransition (command not
    allowed in state closed) and left its handle pending, so leaving the client
    hung.  Now it waits for the resumed session, or raises SessionClosed."""
    import random

    arm = FakeArm(move_time=0.3)
    config = ServerConfig(rtt_hint=0.2, dead_time=30.0)
    rng = random.Random(17)

    async def main() -> None:
        async with Server(arm, config) as server, trio.open_nursery() as nursery:
            cut_points: list[trio.abc.Stream] = []

            async def factory() -> trio.abc.Stream:
                client_end, server_end = trio.testing.memory_stream_pair()
                nursery.start_soon(server.serve_stream, server_end)
                cut_points.append(server_end if len(cut_points) % 2 else client_end)
                return SlowStream(client_end, send_delay=0.002, close_delay=0.3)

            outcomes: dict[str, int] = {}
            with trio.fail_after(3600):
                async with ArmClient(
                    factory, identity="racer", reconnect_attempts=50, reconnect_delay=0.05
                ) as client:

                    async def saboteur() -> None:
                        for _ in range(30):
                            await trio.sleep(rng.uniform(0.0, 1.0))
                            await trio.aclose_forcefully(cut_points[-1])

                    async def commander() -> None:
                        for _ in range(60):
                            await trio.sleep(rng.choice([0.0, 0.001, 0.01, 0.1]))
                            try:
                                handle = await client.submit(commands.move_joint(1, 0.001))
                                await handle.completed()
                                outcome = "completed"
                            except OutcomeUnknown:
                                outcome = "unknown"
                            except SessionClosed:
                                outcome = "closed"
                            outcomes[outcome] = outcomes.get(outcome, 0) + 1

                    async with trio.open_nursery() as inner:
                        inner.start_soon(saboteur)
                        inner.start_soon(commander)
                    assert client.statistics().pending == 0
            assert sum(outcomes.values()) == 60
            # The arm never forgot the client: every command completed exactly once.
            assert outcomes == {"completed": 60}
            nursery.cancel_scope.cancel()

    run(main)
    assert len([c for c in arm.executed if c.code is CommandCode.MOVE_JOINT]) == 60


class _DiesWithACause(trio.abc.Stream):
    """A stream that breaks the way a serial socket does: BrokenResourceError
    whose cause says what happened to the line."""

    def __init__(self, inner: trio.abc.Stream) -> None:
        self.inner = inner
        self.dead = False

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        if self.dead:
            raise trio.BrokenResourceError("link dead") from ConnectionError("line lost at 7 s")
        await self.inner.send_all(data)

    async def wait_send_all_might_not_block(self) -> None:
        await self.inner.wait_send_all_might_not_block()

    async def receive_some(self, max_bytes: int | None = None) -> bytes:
        while not self.dead:
            with trio.move_on_after(0.05):
                return await self.inner.receive_some(max_bytes)
        raise trio.BrokenResourceError("link dead") from ConnectionError("line lost at 7 s")

    async def aclose(self) -> None:
        await trio.aclose_forcefully(self.inner)


def test_a_client_that_cannot_resume_says_why_for_each_command() -> None:
    arm = FakeArm(move_time=30.0)

    async def main() -> None:
        async with Server(arm) as server, trio.open_nursery() as nursery:
            streams: list[_DiesWithACause] = []

            async def factory() -> trio.abc.Stream:
                if streams:
                    raise OSError("no carrier")
                client_end, server_end = trio.testing.memory_stream_pair()
                nursery.start_soon(server.serve_stream, server_end)
                streams.append(_DiesWithACause(client_end))
                return streams[-1]  # type: ignore[return-value]

            async with ArmClient(factory, reconnect_attempts=2, reconnect_delay=0.1) as c:
                handle = await c.submit(commands.move_joint(1, 0.1))
                await handle.accepted()
                streams[0].dead = True
                with pytest.raises(OutcomeUnknown) as info:
                    await handle.completed()
            nursery.cancel_scope.cancel()
        text = str(info.value)
        assert "the link to the arm was lost" in text
        assert "line lost at 7 s" in text  # the stream's own cause
        assert "2 reconnect attempts failed (last: no carrier)" in text

    run(main)


def test_leaving_during_a_reconnect_never_waits_for_a_command_that_was_not_sent() -> None:
    """Finding 3's last point: a submit waiting for the resumed session when the
    caller leaves ``async with`` ends SessionClosed at once (nothing was sent,
    so nothing can have run), and the exit does not wait out the reconnect."""
    arm = FakeArm(move_time=0.1)
    outcome: list[str] = []

    async def main() -> None:
        async with wired(arm) as w, trio.open_nursery() as nursery:
            client = w.client(identity="leaver", reconnect_attempts=3, reconnect_delay=100.0)

            async def late_submit() -> None:
                try:
                    await client.submit(commands.move_joint(1, 0.1))
                    outcome.append("sent")
                except OutcomeUnknown:
                    outcome.append("unknown")
                except SessionClosed as exc:
                    outcome.append(f"closed: {exc}")

            async with client:
                await client.move_joint(2, 0.1)
                await w.break_link()
                await trio.sleep(1.0)  # the client waits 100 s before reconnecting
                nursery.start_soon(late_submit)
                await trio.sleep(1.0)
                assert outcome == []  # waiting for the session, as documented
                left = trio.current_time()
            assert trio.current_time() - left < 5.0, "the exit waited out the reconnect"
            await trio.sleep(0)
            assert client.statistics().pending == 0

    run(main)
    assert len(outcome) == 1
    assert outcome[0].startswith("closed: the session is closed; nothing was sent"), outcome
    assert [int(c.args[0]) for c in arm.executed if c.code is CommandCode.MOVE_JOINT] == [2]
