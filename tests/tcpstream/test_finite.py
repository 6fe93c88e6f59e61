"""Huge but finite arguments, non-finite results and undecodable replies.

Finding 2 of issue 17: ``move_to((1e300,) * 3)`` passed validation, the arm
answered FAILED with ``inf`` in a detail word, the client's decoder rejected
that packet, the call timed out, and the next command came back SKIPPED for a
failure the client was never told about.
"""

from __future__ import annotations

import math
import struct

import pytest
import trio
import trio.testing

from linksim import SimulatedArm
from tcpstream import (
    ArmClient,
    Command,
    CommandCode,
    CommandFailed,
    CommandResult,
    FailureReason,
    Feedback,
    Server,
    commands,
)
from tcpstream.commands import Packet, PacketKind, encode_packet

from .fakearm import FakeArm
from .harness import run, wired

HUGE = 1e300
LENGTH_BOUND = 100.0
"""PROTOCOL.md section 4: |length| <= 100 m, |angle| <= 4 pi rad."""
ANGLE_BOUND = 4 * math.pi


@pytest.mark.parametrize(
    ("command", "word"),
    [
        (commands.move_to((HUGE, HUGE, HUGE)), 0),
        (commands.move_delta((HUGE, 0.0, 0.0)), 0),
        (commands.move_delta((0.0, 0.0, 0.0), (0.0, 0.0, HUGE)), 5),
        (commands.move_joints([0.0] * 5 + [HUGE]), 5),
        (commands.move_joint(3, -HUGE), 1),
        (commands.transform_to_pose([HUGE] + [0.0] * 5), 0),
        (commands.move_path([(0.5, 0.0, 0.4), (0.5, HUGE, 0.4)]), 6),
        (commands.add_obstacle((-HUGE, 0.0, 0.0), (1.0, 1.0, 1.0)), 0),
        (commands.open_fingers(HUGE), 0),
        (commands.squeeze(HUGE), 0),
        (commands.move_to((LENGTH_BOUND * 1.01, 0.0, 0.0)), 0),
        (commands.move_joint(1, ANGLE_BOUND * 1.01), 1),
    ],
)
def test_arguments_far_outside_the_workspace_are_bad_arguments(command: Command, word: int) -> None:
    arm = FakeArm()

    async def main() -> None:
        async with wired(arm) as w, w.client() as c:
            # Refused by the client before it crosses the link ...
            with pytest.raises(CommandFailed) as refused:
                await c.send(command)
            assert refused.value.reason is FailureReason.BAD_ARGUMENT
            assert refused.value.aux[0] == word
            # ... and by the arm, for a controller that does not check.
            conn = c._conn
            assert conn is not None
            conn.send_command(99, command, trio.current_time())
            c._pump.kick()  # type: ignore[union-attr]
            await trio.sleep(1.0)
            assert c.rejected_by_arm == 1  # FAILED BAD_ARGUMENT for #99
            assert (await c.status()).feedback.joints == (0.0,) * 6

    run(main)
    assert [cmd.code for cmd in arm.executed] == [CommandCode.STATUS]


def test_the_simulated_arm_answers_the_largest_allowed_targets_with_finite_words() -> None:
    b = LENGTH_BOUND
    cases = [
        commands.move_to((b, b, b)),
        commands.move_delta((-b, 0.0, 0.0), (ANGLE_BOUND, 0.0, 0.0)),
        commands.move_joints([ANGLE_BOUND] * 6),
        commands.move_path([(b, b, b), (-b, -b, -b)]),
    ]

    async def main() -> None:
        for command in cases:
            with pytest.raises(CommandFailed) as failed:
                await SimulatedArm().execute(command)
            assert all(math.isfinite(x) for x in failed.value.aux)

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))


class _Overflowing(FakeArm):
    """An executor whose failure detail and, on request, state are not finite."""

    def __init__(self) -> None:
        super().__init__(move_time=0.1)
        self.broken_state = False

    async def execute(self, command: Command) -> CommandResult:
        if command.code is CommandCode.MOVE_TO_POSITION:
            self.executed.append(command)
            raise CommandFailed(
                FailureReason.UNREACHABLE, "too far", aux=(math.inf, 0.0, -math.inf, math.nan)
            )
        return await super().execute(command)

    def state(self) -> Feedback:
        f = super().state()
        if self.broken_state:
            return Feedback(f.joints, math.nan, f.p, f.s, f.a)
        return f


def test_a_non_finite_failure_detail_reaches_the_client_as_the_failure_it_is() -> None:
    arm = _Overflowing()

    async def main() -> None:
        async with wired(arm) as w, w.client() as c:
            with trio.fail_after(5.0), pytest.raises(CommandFailed) as failed:
                await c.move_to((0.5, 0.0, 0.4))
            assert failed.value.reason is FailureReason.UNREACHABLE
            assert failed.value.aux == (1.7976931348623157e308, 0.0, -1.7976931348623157e308, 0.0)
            # The barrier is consistent with what the client was told: it knows
            # of the failure, so the next command runs.
            assert (await c.status()).feedback.joints == (0.0,) * 6
            # A state that is not finite is an arm fault, never a packet.
            arm.broken_state = True
            with trio.fail_after(5.0), pytest.raises(CommandFailed) as fault:
                await c.status()
            assert fault.value.reason is FailureReason.ARM_FAULT
            assert w.server.statistics().bad_packets == 0
            assert c.statistics().connection.bad_packets == 0  # type: ignore[union-attr]

    run(main)
    assert FailureReason.ARM_FAULT in arm.halts


def test_the_codec_refuses_to_build_a_packet_the_peer_would_reject() -> None:
    with pytest.raises(ValueError, match="finite"):
        encode_packet(Packet(PacketKind.FAILED, aux=(math.inf, 0.0, 0.0, 0.0)))
    body = struct.pack("!18d", *([0.0] * 17 + [math.nan]))
    with pytest.raises(ValueError, match="finite"):
        encode_packet(Packet(PacketKind.COMPLETED, body=body))


class _Poisoning(trio.abc.Stream):
    """Arm -> controller bytes pass through; the first FAILED reply gets an
    infinite detail word (what an arm with the old bug sent)."""

    def __init__(self, inner: trio.abc.Stream) -> None:
        self.inner = inner
        self.buffer = bytearray()
        self.poisoned = 0

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        await self.inner.send_all(data)

    async def wait_send_all_might_not_block(self) -> None:
        await self.inner.wait_send_all_might_not_block()

    async def receive_some(self, max_bytes: int | None = None) -> bytes:
        while len(self.buffer) < 216:
            data = await self.inner.receive_some()
            if not data:
                return bytes(self.buffer)
            self.buffer += data
        packet = bytearray(self.buffer[:216])
        del self.buffer[:216]
        if packet[3] == PacketKind.FAILED and not self.poisoned:
            packet[24:32] = struct.pack("!d", math.inf)
            self.poisoned += 1
        return bytes(packet)

    async def aclose(self) -> None:
        await self.inner.aclose()


def test_a_reply_the_client_cannot_decode_fails_its_command_at_once() -> None:
    arm = _Overflowing()

    async def main() -> None:
        async with Server(arm) as server, trio.open_nursery() as nursery:

            async def factory() -> trio.abc.Stream:
                client_end, server_end = trio.testing.memory_stream_pair()
                nursery.start_soon(server.serve_stream, server_end)
                return _Poisoning(client_end)

            async with ArmClient(factory) as c:
                with trio.fail_after(5.0), pytest.raises(CommandFailed) as failed:
                    await c.move_to((0.5, 0.0, 0.4))
                assert failed.value.reason is FailureReason.BAD_PACKET
                assert "could not be decoded" in failed.value.message
                # Not SKIPPED: the client counts it as a failure it has seen.
                assert (await c.status()).feedback.joints == (0.0,) * 6
            nursery.cancel_scope.cancel()

    run(main)
