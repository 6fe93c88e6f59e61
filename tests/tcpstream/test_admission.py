"""Unauthenticated sockets cannot lock out a keyed controller (issue 17, finding 6).

Twelve plain TCP sockets, re-opened as they dropped, kept a keyed controller
out with SERVER_FULL on 4 of 4 tries.  Now a new connection takes the slot of
the least advanced handshake when the server is full.  Real loopback TCP;
the outcome is asserted, never a duration.
"""

from __future__ import annotations

import random

import trio

from tcpstream import PACKET_SIZE, CommandCode, Server, ServerConfig, connect_tcp

from .fakearm import FakeArm

KEY = b"0123456789abcdef-admission"
GUARD = 120.0
"""Wall-clock guard: a hang fails the test instead of CI."""
FLOODERS = 24
RECONNECTS = 20


def test_a_flood_of_unauthenticated_sockets_never_keeps_the_controller_out() -> None:
    arm = FakeArm(move_time=0.0)
    config = ServerConfig(key=KEY, max_connections=8, rtt_hint=0.05)
    got_in = 0
    opened = 0

    async def main() -> None:
        nonlocal got_in, opened
        with trio.fail_after(GUARD):
            async with Server(arm, config) as server, trio.open_nursery() as nursery:
                listeners = await trio.open_tcp_listeners(0, host="127.0.0.1")
                port = listeners[0].socket.getsockname()[1]
                nursery.start_soon(server.serve_listeners, listeners)

                async def flooder(seed: int) -> None:
                    nonlocal opened
                    rng = random.Random(seed)
                    while True:  # re-open as soon as the arm drops it
                        try:
                            stream = await trio.open_tcp_stream("127.0.0.1", port)
                        except OSError:
                            await trio.sleep(0.01)
                            continue
                        opened += 1
                        async with stream:
                            if rng.random() < 0.5:  # half a HELLO, then silence
                                await stream.send_all(b"TL\x01\x01" + bytes(PACKET_SIZE // 2))
                            try:
                                while await stream.receive_some():
                                    pass
                            except (trio.BrokenResourceError, trio.ClosedResourceError):
                                pass

                async with trio.open_nursery() as flood:
                    for i in range(FLOODERS):
                        flood.start_soon(flooder, i)
                    await trio.sleep(0.5)  # every slot is taken by the flood
                    for attempt in range(RECONNECTS):
                        async with connect_tcp(
                            "127.0.0.1", port, key=KEY, identity="keyed", reconnect_attempts=0
                        ) as client:
                            await client.move_joint(1, 0.01)
                            got_in += 1
                        assert attempt + 1 == got_in
                    stats = server.statistics()
                    flood.cancel_scope.cancel()
                nursery.cancel_scope.cancel()
        assert stats.handshakes_evicted > 0
        print(
            f"\n{got_in}/{RECONNECTS} keyed sessions got in under a flood of {FLOODERS} "
            f"sockets ({opened} opened, {stats.handshakes_evicted} evicted, "
            f"{stats.refused} refused)"
        )

    trio.run(main)
    assert got_in == RECONNECTS
    assert arm.count(CommandCode.MOVE_JOINT) == RECONNECTS
