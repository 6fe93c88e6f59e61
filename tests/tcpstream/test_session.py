"""Whole sessions over in-memory streams on virtual time: server, client and a fake arm."""

from __future__ import annotations

from typing import Any

import pytest
import trio

from tcpstream import (
    ArmClient,
    AuthenticationFailed,
    Command,
    CommandCode,
    CommandFailed,
    CommandResult,
    FailureReason,
    Feedback,
    LocalProtocolError,
    Refused,
    RefuseReason,
    Server,
    ServerConfig,
    commands,
)
from tcpstream.commands import PACKET_SIZE, Packet, PacketKind, decode_packet
from tcpstream.connection import ClientConnection, ControllerIdentity

from .fakearm import FakeArm
from .harness import KEY, run, wired


def test_commands_round_trip_with_feedback_and_aux() -> None:
    arm = FakeArm(move_time=2.0)

    async def main() -> None:
        async with wired(arm) as w, w.client(identity="ops") as c:
            status = await c.status()
            assert status.feedback.p == (0.5, 0.0, 0.4)
            t0 = trio.current_time()
            moved = await c.move_joints([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
            assert trio.current_time() - t0 == pytest.approx(2.0, abs=1e-6)
            assert moved.feedback.joints == (0.1, 0.2, 0.3, 0.4, 0.5, 0.6)
            assert (await c.weigh()).aux == (1.25, 0.0, 0.0, 0.0)
            arm.fail[CommandCode.SQUEEZE] = FailureReason.NOT_GRASPING
            with pytest.raises(CommandFailed) as info:
                await c.squeeze(5.0)
            assert info.value.reason is FailureReason.NOT_GRASPING
            assert info.value.aux == (1.0, 2.0, 3.0, 4.0)
            assert info.value.message == "scripted failure"
            stats = w.server.statistics()
            assert stats.commands_completed == 3
            assert stats.commands_failed == 1
            assert stats.controller == "ops"

    run(main)
    assert [c.code for c in arm.executed] == [
        CommandCode.STATUS,
        CommandCode.MOVE_JOINTS,
        CommandCode.WEIGH,
        CommandCode.SQUEEZE,
    ]


def test_bad_arguments_never_cross_the_link() -> None:
    arm = FakeArm()

    async def main() -> None:
        async with wired(arm) as w, w.client() as c:
            with pytest.raises(CommandFailed) as info:
                await c.change_speed(1.5)
            assert info.value.reason is FailureReason.BAD_ARGUMENT
            assert info.value.aux[0] == 0.0
            with pytest.raises(ValueError, match="S and A"):
                await c.move_to((0.1, 0.2, 0.3), s=(0.0, 1.0, 0.0))

    run(main)
    assert arm.executed == []


def test_pipelined_commands_run_in_order_with_queue_positions() -> None:
    arm = FakeArm(move_time=1.0)

    async def main() -> None:
        async with wired(arm) as w, w.client() as c:
            t0 = trio.current_time()
            handles = [await c.submit(commands.move_joint(j, 0.1)) for j in (1, 2, 3)]
            assert [await h.accepted() for h in handles] == [0, 1, 2]
            results = [await h.completed() for h in handles]
            assert trio.current_time() - t0 == pytest.approx(3.0, abs=1e-6)
            assert len(results) == 3

    run(main)
    assert [c.args[0] for c in arm.executed] == [1.0, 2.0, 3.0]


def test_emergency_stop_preempts_a_long_move_and_flushes_the_queue() -> None:
    arm = FakeArm(move_time=100.0)

    async def main() -> None:
        async with wired(arm) as w, w.client() as c:
            long_move = await c.submit(commands.move_joints([1.0] * 6))
            queued = [await c.submit(commands.move_joint(1, 0.1)) for _ in range(2)]
            await queued[-1].accepted()
            await trio.sleep(1.0)
            t0 = trio.current_time()
            stop = await c.emergency_stop()
            assert stop.feedback.joints == (0.0,) * 6  # never got there
            assert trio.current_time() - t0 < 0.01  # no queue to wait behind
            for handle in (long_move, *queued):
                with pytest.raises(CommandFailed) as info:
                    await handle.completed()
                assert info.value.reason is FailureReason.STOPPED
            assert w.server.statistics().emergency_stops == 1
            # The arm takes new commands afterwards.
            assert (await c.status()).feedback.joints == (0.0,) * 6

    run(main)
    assert arm.finished[-1].code is CommandCode.STATUS
    assert [c.code for c in arm.executed] == [CommandCode.MOVE_JOINTS, CommandCode.STATUS]
    assert arm.halts[0] is FailureReason.STOPPED


def test_queue_full_is_a_typed_failure() -> None:
    arm = FakeArm(move_time=10.0)

    async def main() -> None:
        async with wired(arm, ServerConfig(queue_size=2)) as w, w.client() as c:
            # Two waiting plus the one running fit; the fourth does not.
            handles = [await c.submit(commands.move_joint(1, 0.1)) for _ in range(4)]
            assert [await h.accepted() for h in handles[:3]] == [0, 1, 2]
            with pytest.raises(CommandFailed) as info:
                await handles[3].completed()
            assert info.value.reason is FailureReason.QUEUE_FULL
            for h in handles[:3]:
                await h.completed()

    run(main)
    assert len(arm.executed) == 3


def test_second_controller_is_refused_and_an_observer_gets_telemetry() -> None:
    arm = FakeArm(move_time=1.0)

    async def main() -> None:
        async with wired(arm) as w, w.client(identity="first") as first:
            with pytest.raises(Refused) as info:
                async with w.client(identity="second"):
                    pass
            assert info.value.reason is RefuseReason.BUSY
            assert "observer" in info.value.message
            async with w.client(identity="watcher", observer=True) as watcher:
                with pytest.raises(LocalProtocolError):
                    await watcher.status()
                await first.move_joints([0.3] * 6)
                samples = []
                async for feedback in watcher.telemetry():
                    samples.append(feedback)
                    if len(samples) == 3:
                        break
                assert samples[-1].joints == (0.3,) * 6
                assert watcher.latest_telemetry is not None
            assert w.server.statistics().refused == 1

    run(main)


def test_terminate_ends_the_session_and_the_arm_listens_again() -> None:
    arm = FakeArm()

    async def main() -> None:
        async with wired(arm) as w:
            async with w.client(identity="first") as c:
                await c.terminate()
                await trio.sleep(0.1)
                assert w.server.statistics().controller is None
            async with w.client(identity="second") as c2:
                assert (await c2.status()).feedback.p == (0.5, 0.0, 0.4)

    run(main)


def test_server_full_refuses_with_a_reason() -> None:
    arm = FakeArm()

    async def main() -> None:
        config = ServerConfig(max_connections=1)
        async with wired(arm, config) as w, w.client(identity="one"):
            with pytest.raises(Refused) as info:
                async with w.client(identity="two", observer=True):
                    pass
            assert info.value.reason is RefuseReason.SERVER_FULL

    run(main)


class BrokenArm(FakeArm):
    """An executor with bugs: execute raises, and halt and state may too."""

    def __init__(self) -> None:
        super().__init__()
        self.state_broken = False

    async def execute(self, command: Command) -> CommandResult:
        if command.code is CommandCode.WEIGH:
            raise ZeroDivisionError("scale divided by zero")
        return await super().execute(command)

    def halt(self, reason: FailureReason) -> None:
        super().halt(reason)
        raise RuntimeError("halt relay stuck")

    def state(self) -> Feedback:
        if self.state_broken:
            raise RuntimeError("encoder offline")
        return super().state()


def test_executor_bugs_fail_the_command_not_the_server() -> None:
    arm = BrokenArm()

    async def main() -> None:
        async with wired(arm) as w, w.client() as c:
            with pytest.raises(CommandFailed) as info:
                await c.weigh()
            assert info.value.reason is FailureReason.ARM_FAULT
            assert "scale divided by zero" in info.value.message
            arm.state_broken = True
            with pytest.raises(CommandFailed) as stop:
                await c.emergency_stop()  # halts (raising), state unreadable
            assert stop.value.reason is FailureReason.ARM_FAULT
            await trio.sleep(1.0)  # telemetry keeps trying, skipping samples
            arm.state_broken = False
            assert (await c.status()).feedback.p == (0.5, 0.0, 0.4)

    run(main)
    assert arm.halts[:2] == [FailureReason.ARM_FAULT, FailureReason.STOPPED]


def test_commands_after_terminate_are_refused_and_the_queue_before_it_drains() -> None:
    arm = FakeArm(move_time=1.0)

    async def main() -> None:
        async with wired(arm) as w, w.client() as c:
            move = await c.submit(commands.move_joint(1, 0.1))
            end = await c.submit(commands.terminate())
            late = await c.submit(commands.status())
            await move.completed()  # queued before TERMINATE: runs
            await end.completed()
            with pytest.raises(CommandFailed) as info:
                await late.completed()
            assert info.value.reason is FailureReason.TERMINATING

    run(main)
    assert [c.code for c in arm.executed] == [CommandCode.MOVE_JOINT]


@pytest.mark.parametrize(
    ("arm_key", "client_key", "words"),
    [
        pytest.param(KEY, b"another-key-of-16+bytes", "same pre-shared key", id="wrong-key"),
        pytest.param(KEY, None, "requires a pre-shared key", id="no-client-key"),
        pytest.param(None, KEY, "without authenticating", id="no-arm-key"),
    ],
)
def test_key_mismatches_raise_authentication_failed(
    arm_key: bytes | None, client_key: bytes | None, words: str
) -> None:
    arm = FakeArm()

    async def main() -> None:
        async with wired(arm, ServerConfig(key=arm_key)) as w:
            with pytest.raises(AuthenticationFailed, match=words):
                async with w.client(key=client_key):
                    pass
            async with w.client(key=arm_key) as c:  # the right key still works after
                await c.status()

    run(main)
    assert [c.code for c in arm.executed] == [CommandCode.STATUS]


def test_server_refuses_what_is_not_an_executor() -> None:
    with pytest.raises(TypeError, match=r"tcpstream\.Executor"):
        Server(object())  # type: ignore[arg-type]
    arm = FakeArm(control_rate_hz=0.0)
    with pytest.raises(ValueError, match="control_rate_hz"):
        Server(arm)


@pytest.mark.parametrize(
    ("options", "match"),
    [
        pytest.param({"identity": "x" * 33}, "identity", id="long-identity"),
        pytest.param({"identity": ""}, "identity", id="empty-identity"),
        pytest.param({"key": b"short"}, "16 bytes", id="short-key"),
        pytest.param({"incarnation": 2**64}, "64 bits", id="incarnation"),
        pytest.param({"max_in_flight": 0}, "max_in_flight", id="in-flight"),
    ],
)
def test_client_options_are_checked_at_construction(options: dict[str, Any], match: str) -> None:
    async def never() -> trio.abc.Stream:
        raise AssertionError("not reached")

    with pytest.raises(ValueError, match=match):
        ArmClient(never, **options)


def test_commands_queued_behind_a_failure_are_skipped_not_run() -> None:
    """The failure barrier: nothing planned after a failed command runs from the wrong place."""
    arm = FakeArm(move_time=1.0)
    arm.fail[CommandCode.MOVE_TO_POSITION] = FailureReason.UNREACHABLE

    async def main() -> None:
        async with wired(arm) as w, w.client() as c:
            first = await c.submit(commands.move_joint(1, 0.1))
            bad = await c.submit(commands.move_to((2.0, 0.0, 0.0)))
            after = [await c.submit(commands.close_fingers()), await c.submit(commands.weigh())]
            await first.completed()
            with pytest.raises(CommandFailed) as failed:
                await bad.completed()
            assert failed.value.reason is FailureReason.UNREACHABLE
            for handle in after:
                with pytest.raises(CommandFailed) as info:
                    await handle.completed()
                assert info.value.reason is FailureReason.SKIPPED
                assert info.value.aux[0] == bad.request_id
                assert f"#{bad.request_id} failed first" in info.value.message
            # Sent after the failure was seen: runs.
            assert (await c.status()).feedback is not None
            assert w.server.statistics().skipped == 2

    run(main)
    assert [c.code for c in arm.executed] == [
        CommandCode.MOVE_JOINT,
        CommandCode.MOVE_TO_POSITION,
        CommandCode.STATUS,
    ]


def test_a_command_in_flight_when_an_earlier_one_fails_is_skipped() -> None:
    """Sent before the controller could know of the failure, arriving after it: skipped."""
    arm = FakeArm()
    arm.fail[CommandCode.CENTER_FINGERS] = FailureReason.NO_OBJECT

    async def main() -> None:
        async with wired(arm) as w:
            stream = await w.factory()
            conn = ClientConnection(ControllerIdentity("raw", 5))
            conn.connect(trio.current_time())
            await stream.send_all(conn.data_to_send())
            conn.receive_data(await stream.receive_some(PACKET_SIZE), trio.current_time())

            buffer = bytearray()

            async def exchange(rid: int, command: Command, seen: int) -> Packet:
                conn.send_command(rid, command, trio.current_time(), failures_seen=seen)
                await stream.send_all(conn.data_to_send())
                while True:
                    while len(buffer) < PACKET_SIZE:
                        buffer.extend(await stream.receive_some())
                    packet = decode_packet(bytes(buffer[:PACKET_SIZE]))
                    del buffer[:PACKET_SIZE]
                    if packet.kind in (PacketKind.COMPLETED, PacketKind.FAILED):
                        return packet

            failed = await exchange(1, commands.center_fingers(), 0)
            assert failed.status == FailureReason.NO_OBJECT
            late = await exchange(2, commands.open_fingers(), 0)  # planned before the failure
            assert (late.status, late.aux[0]) == (FailureReason.SKIPPED, 1.0)
            informed = await exchange(3, commands.open_fingers(), 1)
            assert informed.kind is PacketKind.COMPLETED
            stop = await exchange(4, commands.emergency_stop(), 0)  # never skipped
            assert stop.kind is PacketKind.COMPLETED

    run(main)
    assert [c.code for c in arm.executed] == [CommandCode.CENTER_FINGERS, CommandCode.OPEN_FINGERS]
