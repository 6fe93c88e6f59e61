"""Embed the telelink client in async (trio) controller code.

The arm normally runs on another machine (``linksim arm-server --transport
tcp``, or your real arm behind ``tcpstream.serve_tcp``).  To run as written,
this program starts the simulated arm on a loopback port first, then commands
it as a controller would: authenticated session, one command at a time,
pipelined commands, telemetry, and a refused command handled as a typed
error.

    python examples/async_controller.py
"""

from __future__ import annotations

import functools
import math
import secrets

import trio

import tcpstream
from linksim import SimulatedArm
from tcpstream import commands


async def controller(port: int, key: bytes) -> None:
    async with tcpstream.connect_tcp("127.0.0.1", port, key=key, identity="example") as arm:
        # One command, awaited: the reply carries seed 000's feedback array.
        state = (await arm.status()).feedback
        print("hand at", tuple(round(x, 3) for x in state.p), "m")

        # Several commands pipelined: each is queued at the arm at once and
        # confirmed twice, when accepted and when completed (matched by request id).
        handles = [
            await arm.submit(commands.open_fingers()),
            await arm.submit(commands.move_joint(1, math.radians(20))),
            await arm.submit(commands.move_joint(1, math.radians(-20))),
        ]
        for handle in handles:
            result = await handle.completed()
            print(
                f"{handle.command.code.name:<12} done, joint 1 = "
                f"{math.degrees(result.feedback.joints[0]):6.1f} deg"
            )

        # The arm refuses what it cannot do, with a reason and what to do next.
        try:
            await arm.move_to((3.0, 0.0, 0.0))
        except tcpstream.CommandFailed as exc:
            print("refused:", exc.reason.name, "-", exc.message)

        # Telemetry arrives every N-th control sample while the session lasts.
        with trio.move_on_after(1.0):
            async for feedback in arm.telemetry():
                print("telemetry: finger opening", round(feedback.finger_opening, 3), "m")
                break


async def main() -> None:
    key = secrets.token_bytes(32)  # share it with the arm out of band
    async with trio.open_nursery() as nursery:
        # The arm side, here in the same program: port 0 picks a free port.
        serve = functools.partial(tcpstream.serve_tcp, SimulatedArm(), 0, key=key)
        listeners = await nursery.start(serve)
        port = listeners[0].socket.getsockname()[1]
        await controller(port, key)
        nursery.cancel_scope.cancel()


if __name__ == "__main__":
    trio.run(main)
