"""The loopback latency benchmark: real TCP on 127.0.0.1, the wall clock, 104 Hz."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import trio

from tcpstream.teleop import (
    ContactFlags,
    Reply,
    ReplyStatus,
    Sample,
    TeleopArm,
    TeleopMode,
    open_teleop,
)

from ._operator import Operator
from ._run import IDENTITY, percentile, script_for
from ._transport import SAMPLE_RATE

__all__ = ["run_teleop_loopback"]

_ZERO6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


async def run_teleop_loopback(seconds: float, *, key: bytes | None = None) -> dict[str, Any]:
    """The latency benchmark: real TCP over loopback, wall clock, 104 Hz for ``seconds``.

    Every sample carries its sampling time; the arm notes when its control
    loop applies it.  Returns sample counts and the sampling-to-execution
    latency (p50, p99, max).
    """
    applied: list[float] = []
    numbers: list[int] = []
    kinematics: list[float] = []
    arm_end: TeleopArm

    def on_sample(sample: Sample, arrived: float) -> None:
        # The arm servos on arrival: the sample is executed now, and the reply
        # acknowledges it (the operator's pacing window moves on).
        applied.append(arrived - sample.stamp)
        numbers.append(sample.sample)
        arm_end.reply(
            Reply(
                sample.sample,
                ReplyStatus.FOLLOWING,
                ContactFlags(0),
                2,
                0,
                sample.stamp,
                0.0,
                _ZERO6,
                _ZERO6,
                _ZERO6,
            )
        )

    arm_end = TeleopArm(key=key, rate_deadman=0.1, control_rate=SAMPLE_RATE, on_sample=on_sample)
    async with trio.open_nursery() as nursery:
        listeners = await trio.open_tcp_listeners(0, host="127.0.0.1")
        port = listeners[0].socket.getsockname()[1]

        async def serve(stream: trio.SocketStream) -> None:
            await arm_end.serve_stream(stream)

        nursery.start_soon(trio.serve_listeners, serve, listeners)
        stream = await trio.open_tcp_stream("127.0.0.1", port)
        operator = Operator(script_for("surface", TeleopMode.CARTESIAN), TeleopMode.CARTESIAN)
        async with stream, open_teleop(stream, identity=IDENTITY, key=key) as op:
            t0 = trio.current_time()
            dt = 1.0 / SAMPLE_RATE
            n = int(seconds * SAMPLE_RATE)
            for k in range(n):
                await trio.sleep_until(t0 + k * dt)
                now = trio.current_time()
                # The FRHC's kinematics (seed 004's KIN stage) run first; the stamp is
                # when the sample is ready to go: the channel's latency is measured.
                sample = operator.sample((now - t0) % 13.0, dt, stamp=now)
                ready = trio.current_time()
                kinematics.append(ready - now)
                op.submit(dataclasses.replace(sample, stamp=ready))
            await trio.sleep(0.1)
            stats = op.statistics()
        nursery.cancel_scope.cancel()
    return {
        "seconds": seconds,
        "sample_rate_hz": SAMPLE_RATE,
        "samples_sampled": operator.sampled,
        "samples_sent": stats.samples_sent,
        "samples_coalesced": stats.samples_coalesced,
        "samples_applied": len(numbers),
        "every_sample_applied": numbers == list(range(1, operator.sampled + 1)),
        "operator_kinematics_s": {
            "p50": percentile(kinematics, 50),
            "p99": percentile(kinematics, 99),
        },
        "latency_s": {
            "p50": percentile(applied, 50),
            "p99": percentile(applied, 99),
            "max": max(applied) if applied else math.nan,
        },
    }
