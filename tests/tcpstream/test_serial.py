"""The same session, unchanged, over a serial socket on the noisy Earth-Moon line (virtual time).

tcpstream never imports serialsocket or linksim; the test joins them through
``trio.abc.Stream`` only, exactly as a user would.
"""

from __future__ import annotations

import pytest
import trio

from linksim import serial_socket_pair
from tcpstream import (
    CommandCode,
    CommandFailed,
    FailureReason,
    Server,
    ServerConfig,
    commands,
    connect_stream,
)

from .fakearm import FakeArm
from .harness import KEY, run

# 2400 bit/s and 1.3 s each way: a 216-byte packet, Kermit-encoded, is ~1 s on
# the line, so a command's round trip is ~5 s.  Telemetry every 10 s of samples
# keeps the line mostly for commands.
MOON = ServerConfig(key=KEY, rtt_hint=6.0, telemetry_every=1250)


@pytest.mark.parametrize("seed", [3])
def test_session_over_noisy_moon_serial_socket(seed: int) -> None:
    arm = FakeArm(move_time=4.0)

    async def main() -> None:
        with trio.fail_after(3600):  # virtual seconds: a hang fails, never blocks
            async with (
                serial_socket_pair("noisy-moon", seed=seed) as (controller_end, arm_end),
                Server(arm, MOON) as server,
                trio.open_nursery() as nursery,
            ):
                nursery.start_soon(server.serve_stream, arm_end)
                async with connect_stream(
                    controller_end, key=KEY, identity="earth", handshake_timeout=60.0
                ) as c:
                    assert c.parameters is not None
                    assert c.parameters.dead_time == pytest.approx(24.0)
                    status = await c.status()
                    assert status.feedback.p == (0.5, 0.0, 0.4)
                    handles = [await c.submit(commands.move_joint(j, 0.05)) for j in (1, 2, 3)]
                    for h in handles:
                        await h.completed()
                    # An emergency stop crosses the line ahead of nothing and stops
                    # a long move long before it would have finished.
                    arm.move_time = 600.0
                    long_move = await c.submit(commands.move_joints([0.3] * 6))
                    await long_move.accepted()
                    t0 = trio.current_time()
                    await c.emergency_stop()
                    with pytest.raises(CommandFailed) as stopped:
                        await long_move.completed()
                    assert stopped.value.reason is FailureReason.STOPPED
                    assert trio.current_time() - t0 < 30.0
                    arm.move_time = 4.0
                    arm.fail[CommandCode.WEIGH] = FailureReason.NOT_GRASPING
                    with pytest.raises(CommandFailed) as info:
                        await c.weigh()
                    assert info.value.reason is FailureReason.NOT_GRASPING
                    await c.terminate()
                    # The moon is far: ~5 s per round trip, 3 x 4 s of motion.
                    assert trio.current_time() > 30.0
                stats = server.statistics()
                assert stats.commands_completed == 6  # five commands and the stop
                assert stats.emergency_stops == 1
                assert stats.bad_packets == 0  # the serial socket delivered every byte intact
                assert stats.deadman_trips == 0

    run(main)
    assert [c.code for c in arm.executed] == [
        CommandCode.STATUS,
        CommandCode.MOVE_JOINT,
        CommandCode.MOVE_JOINT,
        CommandCode.MOVE_JOINT,
        CommandCode.MOVE_JOINTS,
        CommandCode.WEIGH,
    ]
    assert FailureReason.STOPPED in arm.halts
