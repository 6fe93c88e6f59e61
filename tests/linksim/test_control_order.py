"""A task run applies the arm's replies in request order, whatever trio's
scheduler does (issue 19: "#3 failed" printed before "#2 completed", accepted
times out of order, the console's predictor fed in a different order each run)."""

from __future__ import annotations

import pytest
import trio
import trio.testing

import linksim.link._virtual as virtual
from linksim import DEFAULT_WORLD, TaskRun, rock_task
from tcpstream import (
    ArmClient,
    Command,
    CommandCode,
    CommandFailed,
    CommandResult,
    FailureReason,
    Feedback,
    Server,
    ServerConfig,
    commands,
)
from tests.tcpstream.fakearm import FakeArm


class _FailsWeigh(FakeArm):
    async def execute(self, command: Command) -> CommandResult:
        if command.code is CommandCode.WEIGH:
            self.executed.append(command)
            raise CommandFailed(FailureReason.NO_OBJECT, "nothing grasped")
        return await super().execute(command)


SCRIPT = [
    commands.move_joint(1, 0.1),  # #1 takes a second
    commands.status(),  # #2 completes at once after it ...
    commands.weigh(),  # #3 ... and #3 fails at once: same instant, same read
    commands.status(),  # #4 is skipped (planned on #3 succeeding)
]


@pytest.mark.parametrize("scheduler_seed", range(8))
def test_replies_that_arrive_together_are_applied_in_request_order(
    monkeypatch: pytest.MonkeyPatch, scheduler_seed: int
) -> None:
    monkeypatch.setattr(virtual, "SCHEDULER_SEED", scheduler_seed)
    events: list[tuple[int, str]] = []

    async def main() -> None:
        arm = _FailsWeigh(move_time=1.0)
        async with Server(arm) as server, trio.open_nursery() as nursery:

            async def factory() -> trio.abc.Stream:
                client_end, server_end = trio.testing.memory_stream_pair()
                nursery.start_soon(server.serve_stream, server_end)
                return client_end

            seen: dict[int, str] = {}

            def on_change() -> None:
                for record in run.records:
                    if seen.get(record.index) != record.state.value:
                        seen[record.index] = record.state.value
                        events.append((record.index, record.state.value))

            run = TaskRun(SCRIPT, on_change=on_change)
            async with ArmClient(factory) as client:
                await run.run(client)
            nursery.cancel_scope.cancel()

    virtual.run_virtual(main)
    done = [(i, s) for i, s in events if s in ("completed", "failed")]
    assert done[:3] == [(1, "completed"), (2, "completed"), (3, "failed")], events
    accepted = [i for i, s in events if s == "accepted"]
    assert accepted == sorted(accepted), events


def test_the_final_pose_is_the_last_command_s_when_replies_arrive_together() -> None:
    """Completions held up on a line (an outage, a TCP stall) arrive in one
    burst with one timestamp: the report's final pose is the last command's
    (it was whichever of the tied ones came first: the bin, not home)."""
    run = TaskRun(rock_task(DEFAULT_WORLD).commands)
    poses = {}
    for record in run.records:
        pose = Feedback(
            joints=(record.index * 0.01, 0.0, 0.0, 0.0, 0.0, 0.0),
            finger_opening=0.08,
            p=(0.4, 0.0, 0.0),
            s=(0.0, 1.0, 0.0),
            a=(0.0, 0.0, -1.0),
        )
        poses[record.index] = pose
        record.result = CommandResult(pose)
        record.done_at = 42.0  # all seen at the same moment
    assert run.final_feedback == poses[len(run.records)]


def test_outcomes_pushed_after_a_resume_wait_for_the_earlier_ones() -> None:
    """After a cut, the arm pushes the outcome of a command that finishes on
    the new connection at once, but answers those that finished during the
    outage only when the re-sent commands reach it.  The run applies them in
    request order all the same (the README tour through ``linksim proxy
    --cut`` showed #8 completed 14 s before #1)."""
    events: list[tuple[int, str]] = []

    class _Deaf(trio.abc.Stream):
        """Hears the arm until ``deaf``; sends slowly when ``slow``."""

        def __init__(self, inner: trio.abc.Stream, *, slow: float) -> None:
            self.inner, self.deaf, self.slow = inner, False, slow

        async def send_all(self, data: bytes | bytearray | memoryview) -> None:
            await trio.sleep(self.slow)
            await self.inner.send_all(data)

        async def wait_send_all_might_not_block(self) -> None:
            await self.inner.wait_send_all_might_not_block()

        async def receive_some(self, max_bytes: int | None = None) -> bytes:
            while True:
                data = await self.inner.receive_some(max_bytes)
                if not self.deaf or not data:
                    return data

        async def aclose(self) -> None:
            await self.inner.aclose()

    async def main() -> None:
        arm = FakeArm(move_time=1.0)
        config = ServerConfig(dead_time=30.0)
        async with Server(arm, config) as server, trio.open_nursery() as nursery:
            streams: list[_Deaf] = []

            async def factory() -> trio.abc.Stream:
                client_end, server_end = trio.testing.memory_stream_pair()
                nursery.start_soon(server.serve_stream, server_end)
                # The first connection is quick; the second takes 1 s per send:
                # GRANT at 2.6 s, #3 finishes at 3 s and is pushed, the re-sent
                # #1 and #2 reach the arm at 3.6 s and are answered then.
                streams.append(_Deaf(client_end, slow=0.0 if not streams else 1.0))
                return streams[-1]

            seen: dict[int, str] = {}

            def on_change() -> None:
                for record in run.records:
                    if seen.get(record.index) != record.state.value:
                        seen[record.index] = record.state.value
                        events.append((record.index, record.state.value))

            moves = [commands.move_joint(1, 0.1), commands.move_joint(2, 0.1)]
            run = TaskRun([*moves, commands.move_joint(3, 0.1)], on_change=on_change)
            async with ArmClient(factory, reconnect_delay=0.1) as client:
                streams[0].deaf = True  # every reply on the first connection is lost

                async def cut() -> None:
                    await trio.sleep(1.5)  # #1 done, #2 running
                    await trio.aclose_forcefully(streams[0].inner)

                nursery.start_soon(cut)
                await run.run(client)
            assert arm.count(CommandCode.MOVE_JOINT) == 3
            nursery.cancel_scope.cancel()

    virtual.run_virtual(main)
    done = [i for i, s in events if s in ("completed", "failed")]
    assert done == [1, 2, 3], events
