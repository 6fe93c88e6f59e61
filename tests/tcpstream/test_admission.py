"""Unauthenticated sockets cannot lock out a keyed controller (issue 17, finding 6).

Twelve plain TCP sockets, re-opened as they dropped, kept a keyed controller
out with SERVER_FULL on 4 of 4 tries.  Now a new connection takes the slot of
the least advanced handshake when the server is full, and one slot is always
the controller's.  The first test runs on real loopback TCP, the rest on
virtual time; outcomes are asserted, never a duration.

The issue's measurement is the first test's figure, printed under ``-s``:
``pytest tests/tcpstream/test_admission.py -s -k unauthenticated_sockets``.
"""

from __future__ import annotations

import random

import pytest
import trio

from tcpstream import (
    ArmClient,
    CommandCode,
    Refused,
    RefuseReason,
    Server,
    ServerConfig,
    connect_tcp,
)
from tcpstream.commands import PACKET_SIZE
from tcpstream.connection import ClientConnection, ControllerIdentity, Role

from .fakearm import FakeArm
from .harness import run, trio_scheduler_rng, wired

KEY = b"0123456789abcdef-admission"
GUARD = 120.0
"""Wall-clock guard: a hang fails the test instead of CI."""
FLOODERS = 24
RECONNECTS = 20


def test_a_flood_of_unauthenticated_sockets_never_keeps_the_controller_out() -> None:
    """Under the flood a keyed controller opens a new session 20 times, then
    one session's link blips 20 times and the controller resumes it each time
    with a single reconnect attempt (a refusal would end the session)."""
    arm = FakeArm(move_time=0.0)
    config = ServerConfig(key=KEY, max_connections=8, rtt_hint=0.05)
    got_in = 0
    resumed = 0
    opened = 0

    async def main() -> None:
        nonlocal got_in, resumed, opened
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
                    # One session whose link blips: every cut frees the
                    # controller's slot for the flood, and the resume must
                    # still get in at its first attempt.
                    links: list[trio.SocketStream] = []

                    async def link() -> trio.abc.Stream:
                        links.append(await trio.open_tcp_stream("127.0.0.1", port))
                        return links[-1]

                    async with ArmClient(
                        link, key=KEY, identity="blips", reconnect_attempts=1, reconnect_delay=0.05
                    ) as client:
                        await client.move_joint(1, 0.01)
                        for _ in range(RECONNECTS):
                            await trio.aclose_forcefully(links[-1])
                            await client.move_joint(1, 0.01)  # waits for the resume
                            resumed = client.statistics().reconnects
                    stats = server.statistics()
                    flood.cancel_scope.cancel()
                nursery.cancel_scope.cancel()
        assert stats.handshakes_evicted > 0
        print(
            f"\n{got_in}/{RECONNECTS} keyed sessions got in and {resumed}/{RECONNECTS} "
            f"resumes after a blip got in under a flood of {FLOODERS} sockets "
            f"({opened} opened, {stats.handshakes_evicted} evicted, {stats.refused} refused)"
        )

    trio.run(main)
    assert got_in == RECONNECTS
    assert resumed == RECONNECTS
    assert arm.count(CommandCode.MOVE_JOINT) == 2 * RECONNECTS + 1


# --- virtual time ---------------------------------------------------------------


async def _hold(stream: trio.abc.Stream) -> None:
    """Read until the arm closes the stream, never closing it ourselves."""
    try:
        while await stream.receive_some():
            pass
    except (trio.BrokenResourceError, trio.ClosedResourceError):
        pass


def test_observers_cannot_take_the_controllers_slot() -> None:
    """Granted observers were never evicted, so max_connections of them kept
    every controller out with SERVER_FULL; now one slot is the controller's."""
    arm = FakeArm(move_time=0.0)
    config = ServerConfig(key=KEY, max_connections=4)
    refusal: list[RefuseReason] = []

    async def main() -> None:
        async with wired(arm, config) as w, trio.open_nursery() as n:

            async def observe(i: int) -> None:
                try:
                    async with w.client(identity=f"eye{i}", key=KEY, observer=True):
                        await trio.sleep_forever()
                except Refused as exc:
                    refusal.append(exc.reason)

            for i in range(4):
                n.start_soon(observe, i)
                await trio.sleep(0.1)
            assert w.server.statistics().connections == 3  # the fourth was refused
            async with w.client(identity="ctl", key=KEY, reconnect_attempts=0) as c:
                await c.move_joint(1, 0.1)
                assert w.server.statistics().controller == "ctl"
            n.cancel_scope.cancel()

    run(main)
    assert refusal == [RefuseReason.SERVER_FULL]
    assert arm.count(CommandCode.MOVE_JOINT) == 1


def test_a_controller_resumes_when_every_slot_holds_a_granted_session() -> None:
    """The controller's old connection (its link blipped; the arm has not yet
    noticed) and observers fill every slot: the controller reconnecting under
    the same identity gets in and retires its old connection."""
    arm = FakeArm(move_time=0.0)
    config = ServerConfig(key=KEY, max_connections=4)

    async def main() -> None:
        async with wired(arm, config) as w, trio.open_nursery() as n:

            async def observe(i: int) -> None:
                async with w.client(identity=f"eye{i}", key=KEY, observer=True):
                    await trio.sleep_forever()

            async with w.client(identity="ctl", key=KEY, incarnation=7, reconnect_attempts=0):
                for i in range(3):
                    n.start_soon(observe, i)
                await trio.sleep(0.1)
                assert w.server.statistics().connections == 4
                async with w.client(
                    identity="ctl", key=KEY, incarnation=7, reconnect_attempts=0
                ) as new:
                    await new.move_joint(1, 0.2)
                    stats = w.server.statistics()
                    assert (stats.controller, stats.controller_connected) == ("ctl", True)
                    assert stats.refused == 0
            n.cancel_scope.cancel()

    run(main)
    assert arm.count(CommandCode.MOVE_JOINT) == 1


def test_refused_connections_that_linger_cannot_keep_the_controller_out() -> None:
    """A refused connection lingers while its REFUSE is flushed and its peer
    does not close.  Refused by the server (BUSY) it counted as "decided" and
    could not be evicted, so three rival HELLOs on an unkeyed arm, never
    reading, kept its own controller from resuming."""
    arm = FakeArm(move_time=0.0)
    config = ServerConfig(max_connections=4)

    async def main() -> None:
        async with wired(arm, config) as w, trio.open_nursery() as n:
            async with w.client(identity="ctl", incarnation=7, reconnect_attempts=0):
                for i in range(3):
                    rival = ClientConnection(ControllerIdentity("rival", i))
                    rival.connect(trio.current_time())
                    stream = await w.factory()
                    await stream.send_all(rival.data_to_send())
                    n.start_soon(_hold, stream)
                await trio.sleep(0.1)
                stats = w.server.statistics()
                assert (stats.refused, stats.connections) == (3, 4)  # BUSY, lingering
                async with w.client(identity="ctl", incarnation=7, reconnect_attempts=0) as again:
                    await again.move_joint(1, 0.1)
                assert w.server.statistics().handshakes_evicted == 1
            n.cancel_scope.cancel()

    run(main)
    assert arm.count(CommandCode.MOVE_JOINT) == 1


@pytest.mark.parametrize("keyed", [True, False])
def test_a_virtual_flood_never_keeps_the_controller_out(keyed: bool) -> None:
    """Sixteen flooding connections -- silent, half a HELLO, a whole HELLO and
    then silence, or one bad packet and then no reading -- re-opened 1 ms
    after each drop, while the controller reconnects twenty times."""
    key = KEY if keyed else None
    arm = FakeArm(move_time=0.0)
    config = ServerConfig(key=key, max_connections=8)
    got_in = 0
    opened = 0

    async def main() -> None:
        nonlocal got_in, opened
        trio_scheduler_rng().seed(17)
        async with wired(arm, config) as w:

            async def flooder(i: int) -> None:
                nonlocal opened
                behaviour = i % 4
                while True:
                    stream = await w.factory()
                    opened += 1
                    if behaviour == 1:
                        await stream.send_all(b"TL\x01\x01" + bytes(PACKET_SIZE // 2))
                    elif behaviour == 2:
                        hello = ClientConnection(
                            ControllerIdentity(f"flood{i}", opened), role=Role.OBSERVER
                        )
                        hello.connect(trio.current_time())
                        await stream.send_all(hello.data_to_send())
                    elif behaviour == 3:
                        await stream.send_all(bytes(PACKET_SIZE))
                    await _hold(stream)
                    await trio.sleep(0.001)

            async with trio.open_nursery() as flood:
                for i in range(16):
                    flood.start_soon(flooder, i)
                await trio.sleep(0.1)
                for attempt in range(RECONNECTS):
                    async with w.client(
                        identity="keyed", key=key, incarnation=attempt + 1, reconnect_attempts=0
                    ) as client:
                        await client.move_joint(1, 0.01)
                        got_in += 1
                    assert attempt + 1 == got_in
                stats = w.server.statistics()
                flood.cancel_scope.cancel()
        assert stats.handshakes_evicted > 0
        print(
            f"\nvirtual, keyed={keyed}: {got_in}/{RECONNECTS} got in under a flood of 16 "
            f"({opened} opened, {stats.handshakes_evicted} evicted, {stats.refused} refused)"
        )

    run(main)
    assert got_in == RECONNECTS
    assert arm.count(CommandCode.MOVE_JOINT) == RECONNECTS
