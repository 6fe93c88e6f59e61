"""The command session over a serial socket on a simulated Earth-Moon line.

Everything runs in one process on trio's virtual clock, so the 1.3 s each
way, the 2400 bit/s line and its noise bursts cost no real time: the program
finishes in about a second and prints what the link did.

    python examples/moon_link.py
"""

from __future__ import annotations

import trio
import trio.testing

import tcpstream
from linksim import SimulatedArm, serial_socket_pair
from tcpstream import commands


async def main() -> None:
    async with serial_socket_pair("noisy-moon", seed=1) as (ground, moon):
        # The arm's side of the session: a server over the serial socket.
        server_config = tcpstream.ServerConfig(rtt_hint=6.0)  # 2 x 1.3 s + serialisation
        async with (
            tcpstream.Server(SimulatedArm(), server_config) as server,
            trio.open_nursery() as nursery,
        ):
            nursery.start_soon(server.serve_stream, moon)
            async with tcpstream.connect_stream(ground, identity="ground") as arm:
                start = trio.current_time()
                await arm.send(commands.open_fingers())
                result = await arm.send(commands.move_joint(6, 0.5))
                print(
                    f"two commands in {trio.current_time() - start:.1f} s of link time;"
                    f" joint 6 at {result.feedback.joints[5]:.2f} rad"
                )
            link = ground.statistics().link
            print(
                f"RTT {link.smoothed_rtt:.2f} s, {link.retransmissions} retransmissions,"
                f" {link.check_failures} CRC failures"
            )
            nursery.cancel_scope.cancel()


if __name__ == "__main__":
    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
