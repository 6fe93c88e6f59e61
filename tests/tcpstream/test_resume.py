"""Exactly once across forced reconnects, and the deadman when the controller goes away."""

from __future__ import annotations

import contextlib

import pytest
import trio
import trio.testing
from hypothesis import given, settings
from hypothesis import strategies as st

from tcpstream import (
    ArmClient,
    CloseReason,
    Command,
    CommandCode,
    CommandFailed,
    CommandResult,
    FailureReason,
    Refused,
    RefuseReason,
    Server,
    ServerConfig,
    SessionClosed,
    commands,
)
from tcpstream.commands import PACKET_SIZE, Packet, PacketKind, decode_packet, encode_packet
from tcpstream.connection import ClientConnection, ControllerIdentity, SessionState

from .fakearm import FakeArm
from .harness import DeafStream, Wiring, run, wired

PATIENT = ServerConfig(dead_time=30.0)
"""A deadman long enough that reconnect tests are about memory, not halting."""


def test_reconnect_mid_command_attaches_to_the_running_one() -> None:
    arm = FakeArm(move_time=10.0)

    async def main() -> None:
        async with wired(arm, PATIENT) as w, w.client(reconnect_delay=0.5) as c:
            handle = await c.submit(commands.move_joints([0.2] * 6))
            await handle.accepted()
            await trio.sleep(2.0)
            await w.break_link()
            result = await handle.completed()
            assert result.feedback.joints == (0.2,) * 6
            assert trio.current_time() == pytest.approx(10.0, abs=0.01)
            assert c.reconnects == 1
            assert w.server.statistics().duplicates_answered == 1

    run(main)
    assert arm.count(CommandCode.MOVE_JOINTS) == 1


def test_a_reply_lost_with_the_link_is_answered_from_memory() -> None:
    arm = FakeArm(move_time=1.0)

    async def main() -> None:
        async with wired(arm, PATIENT) as w, w.client(reconnect_delay=3.0) as c:
            handle = await c.submit(commands.move_joints([0.4] * 6))
            await handle.accepted()
            await trio.sleep(0.5)
            await w.break_link()  # the move finishes at t=1 with nobody connected
            result = await handle.completed()
            assert result.feedback.joints == (0.4,) * 6
            assert trio.current_time() > 3.0  # answered after the reconnect
            assert w.server.statistics().duplicates_answered == 1

    run(main)
    assert arm.count(CommandCode.MOVE_JOINTS) == 1


def test_many_forced_reconnects_never_run_a_command_twice() -> None:
    arm = FakeArm(move_time=1.0)

    async def main() -> None:
        async with wired(arm, PATIENT) as w, w.client(reconnect_delay=0.25) as c:
            handles = [await c.submit(commands.move_joint(1 + i % 6, 0.01)) for i in range(8)]

            async def saboteur() -> None:
                for _ in range(5):
                    await trio.sleep(1.3)
                    await w.break_link()

            async with trio.open_nursery() as nursery:
                nursery.start_soon(saboteur)
                for h in handles:
                    await h.completed()
            assert c.reconnects == 5

    run(main)
    assert arm.count(CommandCode.MOVE_JOINT) == 8
    assert [int(c.args[0]) for c in arm.executed] == [1 + i % 6 for i in range(8)]


def test_deadman_halts_the_arm_when_the_controller_vanishes() -> None:
    arm = FakeArm(move_time=100.0)
    config = ServerConfig(rtt_hint=0.2)  # heartbeat 0.25 s, dead time 1.4 s

    async def main() -> None:
        async with wired(arm, config) as w, w.client(reconnect_attempts=0) as c:
            assert c.parameters is not None
            assert c.parameters.dead_time == pytest.approx(1.4)
            handle = await c.submit(commands.move_joints([1.0] * 6))
            await handle.accepted()
            await trio.sleep(5.0)
            await w.break_link()
            with pytest.raises(SessionClosed):
                await handle.completed()
            await trio.sleep(3.0)
            stats = w.server.statistics()
            assert stats.deadman_trips == 1
            assert stats.controller is None  # the lease is released: others may connect

    run(main)
    assert arm.halts[0] is FailureReason.DEADMAN
    # Heard last within one heartbeat before the break at t=5; halted 1.4 s after that.
    assert 5.0 + 1.4 - 0.25 <= arm.halt_times[0] <= 5.0 + 1.4
    assert arm.finished == []


def test_deadman_on_silence_while_connected() -> None:
    """A controller whose stream stays up but who sends nothing (hung program)."""
    arm = FakeArm(move_time=100.0)
    config = ServerConfig(rtt_hint=0.2, dead_time=2.0)

    async def main() -> None:
        async with wired(arm, config) as w:
            stream = await w.factory()
            conn = ClientConnection(ControllerIdentity("hung", 7))
            conn.connect(trio.current_time())
            await stream.send_all(conn.data_to_send())
            conn.receive_data(await stream.receive_some(PACKET_SIZE), trio.current_time())
            assert conn.role is not None  # granted
            conn.send_command(1, commands.move_joints([1.0] * 6), trio.current_time())
            await stream.send_all(conn.data_to_send())
            t0 = trio.current_time()
            kinds = [PacketKind.GRANT]
            while True:  # read, never answer, never heartbeat
                data = await stream.receive_some()
                if not data:
                    break
                for i in range(0, len(data), PACKET_SIZE):
                    packet = decode_packet(data[i : i + PACKET_SIZE])
                    kinds.append(packet.kind)
                    if packet.kind is PacketKind.BYE:
                        assert packet.status == CloseReason.SILENCE
                        assert trio.current_time() - t0 == pytest.approx(2.0, abs=1e-6)
            assert kinds[:2] == [PacketKind.GRANT, PacketKind.ACCEPTED]
            assert PacketKind.TELEMETRY in kinds  # telemetry doubles as the heartbeat
            assert kinds[-1] is PacketKind.BYE
            assert w.server.statistics().deadman_trips == 1

    run(main)
    assert FailureReason.DEADMAN in arm.halts
    assert arm.finished == []


def test_controller_goodbye_with_work_outstanding_stops_the_arm() -> None:
    arm = FakeArm(move_time=100.0)

    async def main() -> None:
        async with wired(arm) as w:
            async with w.client() as c:
                handle = await c.submit(commands.move_joints([1.0] * 6))
                await handle.accepted()
                await c.aclose(wait=False)
                with pytest.raises(SessionClosed):
                    await handle.completed()
            await trio.sleep(0.1)
            assert w.server.statistics().controller is None

    run(main)
    assert arm.halts[0] is FailureReason.STOPPED
    assert arm.finished == []


def test_resent_command_after_emergency_stop_is_not_rerun() -> None:
    """The e-stop's own request id is remembered too: re-sending it cannot stop later work."""
    arm = FakeArm(move_time=1.0)

    async def main() -> None:
        async with wired(arm, PATIENT) as w, w.client() as c:
            stop = await c.emergency_stop()
            assert stop.feedback is not None
            follow = await c.submit(commands.move_joint(2, 0.1))
            await follow.accepted()
            await w.break_link()
            await follow.completed()
            assert w.server.statistics().emergency_stops == 1

    run(main)
    assert arm.count(CommandCode.MOVE_JOINT) == 1


def test_failed_command_is_reported_once_even_when_resent() -> None:
    arm = FakeArm()
    arm.fail[CommandCode.CENTER_FINGERS] = FailureReason.NO_OBJECT

    async def main() -> None:
        async with wired(arm, PATIENT) as w, w.client() as c:
            with pytest.raises(CommandFailed) as info:
                await c.center_fingers()
            assert info.value.reason is FailureReason.NO_OBJECT

    run(main)
    assert arm.count(CommandCode.CENTER_FINGERS) == 1


def test_controller_error_says_goodbye_and_the_arm_stops() -> None:
    arm = FakeArm(move_time=100.0)

    async def main() -> None:
        async def controller_with_a_bug(w: Wiring) -> None:
            async with w.client() as c:
                handle = await c.submit(commands.move_joints([1.0] * 6))
                await handle.accepted()
                raise RuntimeError("controller bug")

        async with wired(arm) as w:
            with pytest.raises(RuntimeError, match="controller bug"):
                await controller_with_a_bug(w)
            await trio.sleep(0.01)  # far less than the dead time: the BYE did it
            assert w.server.statistics().controller is None
            assert w.server.statistics().deadman_trips == 0

    run(main)
    assert arm.halts[0] is FailureReason.STOPPED


def test_a_different_controller_waits_out_the_lease() -> None:
    """After an unclean disconnect, control is held for the dead time, then freed."""
    arm = FakeArm()
    config = ServerConfig(dead_time=5.0)

    async def main() -> None:
        async with wired(arm, config) as w, w.client(identity="first", reconnect_attempts=0) as c:
            await c.status()
            await w.break_link()
            await trio.sleep(1.0)
            with pytest.raises(Refused) as info:
                async with w.client(identity="second"):
                    pass
            assert info.value.reason is RefuseReason.BUSY
            await trio.sleep(5.0)
            async with w.client(identity="second") as second:
                await second.status()

    run(main)


def test_an_arm_that_lost_its_memory_is_not_sent_the_command_again() -> None:
    """The arm restarted while a command was queued: outcome unknown, not re-run."""
    first_arm, second_arm = FakeArm(move_time=10.0), FakeArm(move_time=10.0)

    async def main() -> None:
        async with (
            Server(first_arm, PATIENT) as first,
            Server(second_arm, PATIENT) as second,
            trio.open_nursery() as nursery,
        ):
            current = [first]
            streams: list[trio.abc.Stream] = []

            async def factory() -> trio.abc.Stream:
                client_end, server_end = trio.testing.memory_stream_pair()
                nursery.start_soon(current[0].serve_stream, server_end)
                streams.append(client_end)
                return client_end

            async with ArmClient(factory, reconnect_delay=0.5) as c:
                handle = await c.submit(commands.move_joints([1.0] * 6))
                await handle.accepted()
                current[0] = second  # "the arm restarted": a server with no memory
                await trio.aclose_forcefully(streams[-1])
                with pytest.raises(SessionClosed, match="outcome unknown"):
                    await handle.completed()
                assert (await c.status()).feedback is not None  # the session goes on
            nursery.cancel_scope.cancel()

    run(main)
    assert second_arm.count(CommandCode.MOVE_JOINTS) == 0
    assert second_arm.count(CommandCode.STATUS) == 1


class TimedArm(FakeArm):
    """MOVE_JOINT takes ``amount`` seconds (args[1]), so each command has its own length."""

    async def execute(self, command: Command) -> CommandResult:
        self.executed.append(command)
        await trio.sleep(command.args[1])
        self.finished.append(command)
        return CommandResult(self.state())


@settings(max_examples=25, deadline=None)
@given(
    durations=st.lists(st.sampled_from([0.1, 0.5, 1.0, 2.5]), min_size=1, max_size=6),
    breaks=st.lists(st.sampled_from([0.05, 0.3, 0.7, 1.1, 2.0]), max_size=4),
    delay=st.sampled_from([0.05, 0.4, 1.5]),
)
def test_random_disconnects_never_run_a_command_twice(
    durations: list[float], breaks: list[float], delay: float
) -> None:
    arm = TimedArm()

    async def main() -> None:
        async with (
            wired(arm, PATIENT) as w,
            w.client(reconnect_delay=delay, reconnect_attempts=10) as c,
        ):
            handles = [await c.submit(commands.move_joint(1, d)) for d in durations]

            async def saboteur() -> None:
                for gap in breaks:
                    await trio.sleep(gap)
                    await w.break_link()

            async with trio.open_nursery() as nursery:
                nursery.start_soon(saboteur)
                results = [await h.completed() for h in handles]
            assert len(results) == len(durations)

    run(main)
    # Each command ran exactly once, in request-id order, to completion.
    assert [c.args[1] for c in arm.executed] == durations
    assert [c.args[1] for c in arm.finished] == durations


def test_reconnecting_to_an_arm_that_never_answers_gives_up() -> None:
    arm = FakeArm(move_time=100.0)

    async def main() -> None:
        async with Server(arm, PATIENT) as server, trio.open_nursery() as nursery:
            opened: list[trio.abc.Stream] = []
            silent_ends: list[trio.abc.Stream] = []

            async def factory() -> trio.abc.Stream:
                client_end, server_end = trio.testing.memory_stream_pair()
                if not opened:
                    nursery.start_soon(server.serve_stream, server_end)
                else:
                    silent_ends.append(server_end)  # connected, never answered
                opened.append(client_end)
                return client_end

            async with ArmClient(
                factory, reconnect_attempts=2, reconnect_delay=0.5, handshake_timeout=3.0
            ) as c:
                handle = await c.submit(commands.move_joints([1.0] * 6))
                await handle.accepted()
                await trio.aclose_forcefully(opened[0])
                t0 = trio.current_time()
                with pytest.raises(SessionClosed):
                    await handle.completed()
                # Two reconnections, each waiting out its handshake, then no more.
                assert len(opened) == 3
                assert trio.current_time() - t0 == pytest.approx(0.5 + 3.0 + 1.0 + 3.0, abs=0.01)
            nursery.cancel_scope.cancel()

    run(main)


def test_a_restarted_arm_is_detected_even_before_any_reply() -> None:
    """Sent, taken in by the arm, reply lost, arm restarted: unknown, never re-run."""
    first_arm, second_arm = FakeArm(move_time=10.0), FakeArm(move_time=10.0)

    async def main() -> None:
        async with (
            Server(first_arm, PATIENT) as first,
            Server(second_arm, PATIENT) as second,
            trio.open_nursery() as nursery,
        ):
            current = [first]
            streams: list[DeafStream] = []

            async def factory() -> trio.abc.Stream:
                client_end, server_end = trio.testing.memory_stream_pair()
                nursery.start_soon(current[0].serve_stream, server_end)
                streams.append(DeafStream(client_end))
                return streams[-1]

            async with ArmClient(factory, reconnect_delay=0.5) as c:
                streams[-1].deaf = True  # the ACCEPTED will never be heard
                handle = await c.submit(commands.move_joints([1.0] * 6))
                await trio.sleep(0.1)
                assert first.statistics().commands_accepted == 1  # the arm took it in
                assert handle.position is None
                current[0] = second
                await trio.aclose_forcefully(streams[-1])
                with pytest.raises(SessionClosed, match="outcome unknown"):
                    await handle.completed()
            nursery.cancel_scope.cancel()

    run(main)
    assert first_arm.count(CommandCode.MOVE_JOINTS) == 1
    assert second_arm.executed == []


def test_a_controller_that_stops_reading_is_dropped_not_buffered_forever() -> None:
    arm = FakeArm()

    async def main() -> None:
        async with Server(arm, ServerConfig(telemetry_every=0)) as server:
            client_end, server_end = trio.testing.lockstep_stream_pair()
            async with trio.open_nursery() as nursery:
                nursery.start_soon(server.serve_stream, server_end)
                conn = ClientConnection(ControllerIdentity("deaf", 1))
                conn.connect(trio.current_time())
                await client_end.send_all(conn.data_to_send())
                conn.receive_data(await client_end.receive_some(PACKET_SIZE), trio.current_time())
                assert conn.state is SessionState.OPEN
                # From here on: heartbeats out (so it is not silent), never a byte read.
                counter = 1
                while server.statistics().connections:
                    await trio.sleep(0.25)
                    counter += 1
                    beat = encode_packet(Packet(PacketKind.HEARTBEAT, counter=counter))
                    with (
                        trio.move_on_after(1.0),
                        contextlib.suppress(trio.BrokenResourceError),  # dropped at last
                    ):
                        await client_end.send_all(beat)
                # The arm's heartbeats backed up, 256 packets at 4 per second.
                assert 60.0 <= trio.current_time() <= 70.0
                assert server.statistics().controller == "deaf"  # the lease runs on
                nursery.cancel_scope.cancel()

    run(main)


def test_a_closed_session_does_not_wait_forever_on_a_peer_that_stopped_reading() -> None:
    arm = FakeArm()

    async def main() -> None:
        async with Server(arm, ServerConfig(telemetry_every=0)) as server:
            client_end, server_end = trio.testing.lockstep_stream_pair()
            async with trio.open_nursery() as nursery:
                nursery.start_soon(server.serve_stream, server_end)
                conn = ClientConnection(ControllerIdentity("rude", 1))
                conn.connect(trio.current_time())
                await client_end.send_all(conn.data_to_send())
                conn.receive_data(await client_end.receive_some(PACKET_SIZE), trio.current_time())
                await trio.sleep(1.0)  # the arm's heartbeats now wait for a reader
                conn.close(CloseReason.NORMAL, trio.current_time())
                await client_end.send_all(conn.data_to_send())
                t0 = trio.current_time()
                while server.statistics().connections:
                    await trio.sleep(0.1)
                assert trio.current_time() - t0 <= 5.0 + 0.2  # CLOSE_TIMEOUT, not forever
                nursery.cancel_scope.cancel()

    run(main)


def test_after_a_deadman_the_resumed_controller_learns_why_its_command_stopped() -> None:
    arm = FakeArm(move_time=100.0)

    async def main() -> None:
        async with wired(arm) as w, w.client(reconnect_delay=3.0) as c:  # dead time 1.4 s
            handle = await c.submit(commands.move_joints([1.0] * 6))
            await handle.accepted()
            await w.break_link()
            with pytest.raises(CommandFailed) as info:
                await handle.completed()
            assert info.value.reason is FailureReason.DEADMAN
            assert c.reconnects == 1
            stats = w.server.statistics()
            assert (stats.deadman_trips, stats.duplicates_answered) == (1, 1)
            assert (await c.status()).feedback is not None  # in control again

    run(main)
    assert arm.count(CommandCode.MOVE_JOINTS) == 1
    assert arm.halts[0] is FailureReason.DEADMAN


def test_a_command_whose_accepted_was_lost_is_accepted_when_it_completes() -> None:
    """The ACCEPTED and COMPLETED of a command are both lost with the link;
    after the resume the arm answers COMPLETED from memory, with no ACCEPTED.
    ``accepted()`` returns (the arm did queue it) instead of tripping an
    assertion: seen in the README tour as a traceback from ``linksim control``
    through ``linksim proxy --cut``."""
    arm = FakeArm(move_time=1.0)
    streams: list[DeafStream] = []

    async def main() -> None:
        async with wired(arm, PATIENT) as w:

            async def factory() -> trio.abc.Stream:
                stream = DeafStream(await w.factory())
                streams.append(stream)
                return stream

            async with ArmClient(factory, reconnect_delay=3.0) as c:
                streams[-1].deaf = True
                handle = await c.submit(commands.move_joints([0.3] * 6))
                await trio.sleep(2.0)  # ran and finished; both replies lost
                await w.break_link()
                result = await handle.completed()
                assert await handle.accepted() == 0  # the position was never heard
                assert result.feedback.joints == (0.3,) * 6
                assert w.server.statistics().duplicates_answered == 1

    run(main)
    assert arm.count(CommandCode.MOVE_JOINTS) == 1
