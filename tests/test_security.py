"""Security tests (issue 11) that the per-package suites do not already cover.

Already covered, and cited in RELIABILITY.md rather than repeated here: wrong
keys refused with byte-identical words (tests/tcpstream/test_connection.py::
test_wrong_key_is_refused_with_the_same_words), replay, reorder, tamper,
reflection and old-session packets on the sans-I/O cores, a second controller
refused BUSY (tests/tcpstream/test_session.py::
test_second_controller_is_refused_and_an_observer_gets_telemetry).

Here, on a running Server:

* a man in the middle of a keyed session replays and tampers with a real
  command packet: nothing runs twice, the copies are counted, the session and
  the next command carry on;
* somebody who knows the controller's *name* but not the key cannot take the
  arm over (the same-name takeover path needs the key too);
* nothing an unkeyed-looking or wrong-keyed client sends gets a GRANT from a
  keyed arm, and the refusal does not depend on how close the key was;
* a command flood is bounded by the queue (QUEUE_FULL, never unbounded
  growth);
* a local flood generator on 127.0.0.1 -- bounded in connections, bytes and
  time, stopping by itself -- cannot push the server past max_connections,
  and a good controller is served afterwards.
"""

from __future__ import annotations

import random
from collections.abc import Awaitable, Callable
from functools import partial

import pytest
import trio
import trio.testing

from tcpstream import (
    ArmClient,
    AuthenticationFailed,
    CommandCode,
    Refused,
    Server,
    ServerConfig,
    commands,
    connect_tcp,
    serve_tcp,
)
from tcpstream.commands import PACKET_SIZE, PacketKind, decode_packet
from tcpstream.connection import (
    ClientConnection,
    Completed,
    ControllerIdentity,
    Failed,
    Granted,
    SessionEnded,
    SessionState,
)

from .tcpstream.fakearm import FakeArm
from .tcpstream.harness import KEY, run, wired
from .test_bad_input_tcp import READ_LIMIT, _command_reply, _session, serving

WALL_GUARD = 60.0
"""Seconds of wall clock the loopback tests may take at most (a bound, not an assertion)."""


class Tap(trio.abc.Stream):
    """A man in the middle of the controller's stream: records what the controller
    writes and can inject bytes of its own into the arm's direction."""

    def __init__(self, inner: trio.abc.Stream) -> None:
        self.inner = inner
        self.written = bytearray()

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        self.written += data
        await self.inner.send_all(data)

    async def wait_send_all_might_not_block(self) -> None:
        await self.inner.wait_send_all_might_not_block()

    async def receive_some(self, max_bytes: int | None = None) -> bytes | bytearray:
        return await self.inner.receive_some(max_bytes)

    async def aclose(self) -> None:
        await self.inner.aclose()

    def packets(self) -> list[bytes]:
        raw = bytes(self.written)
        return [raw[i : i + PACKET_SIZE] for i in range(0, len(raw) - PACKET_SIZE + 1, PACKET_SIZE)]


def test_a_man_in_the_middle_cannot_replay_or_tamper_with_commands() -> None:
    arm = FakeArm(move_time=0.5)
    taps: list[Tap] = []

    async def main() -> None:
        async with wired(arm, ServerConfig(key=KEY)) as w:

            async def factory() -> trio.abc.Stream:
                tap = Tap(await w.factory())
                taps.append(tap)
                return tap

            async with ArmClient(factory, identity="op", key=KEY) as client:
                await client.move_joint(1, 0.25)
                [tap] = taps
                [original] = [p for p in tap.packets() if p[3] == PacketKind.COMMAND]
                tampered = bytearray(original)
                tampered[60] ^= 0x01  # one bit of the first argument word
                before = w.server.statistics().bad_packets
                await tap.inner.send_all(original)  # a replay
                await tap.inner.send_all(bytes(tampered))  # a tampered copy
                await client.move_joint(2, 0.5)  # the session carries on
                assert w.server.statistics().bad_packets - before == 2
            assert [c.code for c in arm.executed] == [CommandCode.MOVE_JOINT] * 2
            assert [c.args[:2] for c in arm.executed] == [(1.0, 0.25), (2.0, 0.5)]

    run(main)


@pytest.mark.parametrize(
    "key",
    [bytes([KEY[0] ^ 1]) + KEY[1:], KEY[:-1] + b"?", b"z" * 40, None],
    ids=["first-bit-off", "last-byte-off", "unrelated", "no-key"],
)
def test_the_controllers_name_without_the_key_cannot_take_the_arm_over(
    key: bytes | None,
) -> None:
    """The holder's name and the same-name takeover path do not help without the key;
    the holder keeps the arm and its next command runs."""

    async def main() -> None:
        async with serving(ServerConfig(key=KEY, rtt_hint=0.2)) as (server, arm, opener):
            holder_peer, holder, events = await _session(opener, name="op")
            assert any(isinstance(e, Granted) for e in events)
            intruder_peer, _, intruder_events = await _session(opener, key=key, name="op")
            assert not any(isinstance(e, Granted) for e in intruder_events)
            kinds = {
                decode_packet(bytes(intruder_peer.received[i : i + PACKET_SIZE])).kind
                for i in range(0, len(intruder_peer.received), PACKET_SIZE)
            }
            assert PacketKind.GRANT not in kinds
            holder.send_command(1, commands.move_joint(1, 0.1), trio.current_time())
            replies = await _command_reply(holder_peer, holder)
            assert type(replies[-1]).__name__ == "Completed"
            assert len(arm.executed) == 1
            assert server.statistics().controller == "op"

    run(main)


def test_wrong_keys_far_and_near_end_in_the_same_error_over_tcp() -> None:
    """Over real loopback TCP: one-bit-off and unrelated keys get the same
    AuthenticationFailed message; the arm runs nothing."""
    arm = FakeArm(move_time=0.01)
    messages: list[str] = []

    async def main() -> None:
        with trio.fail_after(WALL_GUARD):
            async with trio.open_nursery() as nursery:
                listeners = await nursery.start(partial(serve_tcp, arm, 0, key=KEY))
                port = listeners[0].socket.getsockname()[1]
                for key in (bytes([KEY[0] ^ 1]) + KEY[1:], b"q" * 48):
                    with pytest.raises((AuthenticationFailed, Refused)) as info:
                        async with connect_tcp("127.0.0.1", port, key=key) as c:
                            await c.status()
                    messages.append(str(info.value))
                nursery.cancel_scope.cancel()

    trio.run(main)
    assert len(messages) == 2
    assert messages[0] == messages[1]
    assert arm.executed == []


def test_a_command_flood_is_bounded_by_the_queue() -> None:
    """500 commands written at once by a (legitimate) controller: the arm queues
    queue_size of them behind the running one and fails the rest QUEUE_FULL --
    every one is answered, none is dropped silently, the queue never grows past
    its bound, and everything accepted runs exactly once."""
    # A long deadman: this hand-driven controller sends no heartbeats.
    # No packet-rate limit: all 500 must reach the queue in one burst (the rate
    # limit has its own tests below).
    config = ServerConfig(
        rtt_hint=0.2, queue_size=8, idle_timeout=None, dead_time=600.0, max_packet_rate=None
    )

    async def main() -> None:
        async with serving(config) as (server, arm, opener):
            peer, client, _ = await _session(opener, key=None)
            now = trio.current_time()
            for rid in range(1, 501):
                client.send_command(rid, commands.move_joint(1 + rid % 6, 0.001), now)
            await peer.send(client.data_to_send())
            answered: dict[int, str] = {}
            deepest = 0
            with trio.fail_after(READ_LIMIT * 10):
                while len(answered) < 500:
                    chunk = await peer.stream.receive_some()
                    assert chunk
                    client.receive_data(chunk, trio.current_time())
                    deepest = max(deepest, server.statistics().queue_depth)
                    while (ev := client.next_event()) is not None:
                        name = type(ev).__name__
                        if name in ("Completed", "Failed"):
                            rid = ev.request_id  # type: ignore[attr-defined]
                            assert rid not in answered
                            answered[rid] = (
                                ev.reason.name if isinstance(ev, Failed) else "COMPLETED"
                            )
                    await peer.send(client.data_to_send())
            full = [r for r, why in answered.items() if why == "QUEUE_FULL"]
            done = [r for r, why in answered.items() if why == "COMPLETED"]
            assert len(done) + len(full) == 500
            # All 500 arrive in one burst: one runs, queue_size wait, the rest are refused.
            assert len(done) == config.queue_size + 1
            assert deepest <= config.queue_size
            assert len(arm.executed) == len(done)

    run(main)


async def _status_flood(
    peer_send: Callable[[bytes], Awaitable[object]],
    receive: Callable[[], Awaitable[bytes | bytearray]],
    client: ClientConnection,
    count: int,
    started: float,
) -> list[tuple[float, int]]:
    """Write ``count`` STATUS commands at once and, at the same time (a peer
    that reads nothing while its write blocks is rightly dropped as STALLED),
    read until every one is answered; returns (time since ``started``, answers
    so far) after each read."""
    now = trio.current_time()
    for rid in range(1, count + 1):
        client.send_command(rid, commands.status(), now)
    answered: set[int] = set()
    progress: list[tuple[float, int]] = []
    async with trio.open_nursery() as nursery:
        nursery.start_soon(peer_send, client.data_to_send())
        while len(answered) < count:
            chunk = await receive()
            assert chunk, "the server closed the flooding connection"
            client.receive_data(bytes(chunk), trio.current_time())
            while (ev := client.next_event()) is not None:
                if isinstance(ev, Completed):
                    assert ev.request_id not in answered  # exactly once
                    answered.add(ev.request_id)
                else:
                    assert not isinstance(ev, (Failed, SessionEnded)), ev
            progress.append((trio.current_time() - started, len(answered)))
    return progress


def test_a_packet_flood_is_slowed_to_the_rate_limit_and_nothing_is_lost() -> None:
    """2000 STATUS packets written at once by an authenticated controller, on the
    virtual clock: the server answers them no faster than ``packet_burst`` plus
    ``max_packet_rate`` per second -- every one of them, exactly once, in the
    end (throttled reads, not drops) -- and counts the pauses.  Meanwhile an
    observer connects and is granted: the flood does not starve other peers."""
    rate, burst, count = 200.0, 32, 2000
    config = ServerConfig(
        key=KEY,
        rtt_hint=0.2,
        idle_timeout=None,
        dead_time=600.0,
        max_packet_rate=rate,
        packet_burst=burst,
    )

    async def main() -> None:
        async with serving(config) as (server, _arm, opener):
            started = trio.current_time()  # before the server's bucket exists
            peer, client, _ = await _session(opener)
            observer_granted: list[float] = []

            async def observer() -> None:
                await trio.sleep(1.0)  # well into the flood
                client_end, server_end = trio.testing.memory_stream_pair()
                opener._nursery.start_soon(server.serve_stream, server_end)

                async def factory() -> trio.abc.Stream:
                    return client_end

                t0 = trio.current_time()
                async with ArmClient(factory, key=KEY, identity="watch", observer=True):
                    observer_granted.append(trio.current_time() - t0)

            async with trio.open_nursery() as nursery:
                nursery.start_soon(observer)
                progress = await _status_flood(
                    peer.send, peer.stream.receive_some, client, count, started
                )
            # HELLO and AUTH came out of the same bucket: two more packets.
            for elapsed, answered in progress:
                assert answered + 2 <= burst + rate * elapsed + 1, (elapsed, answered)
            assert progress[-1][0] >= (count + 2 - burst) / rate  # it really was slowed
            stats = server.statistics()
            assert stats.throttled > 0
            # The flood took (count + 2 - burst) / rate seconds more than the burst
            # allowed, and almost all of it was spent in those pauses.
            assert stats.throttled_seconds == pytest.approx((count + 2 - burst) / rate, rel=0.05)
            assert len(observer_granted) == 1
            assert observer_granted[0] < 1.0  # virtual seconds: not queued behind the flood

    run(main)


def test_a_packet_flood_on_loopback_is_throttled_not_dropped() -> None:
    """The same on 127.0.0.1, bounded in count (1500 packets, 324 kB) and by
    WALL_GUARD: all answered exactly once and the pauses counted.  The bound on
    answers per second is the limiter's own arithmetic on the same monotonic
    clock, so it holds on any machine (a slow one answers fewer, never more)."""
    rate, burst, count = 1000.0, 64, 1500
    config = ServerConfig(
        key=KEY, rtt_hint=0.05, idle_timeout=None, max_packet_rate=rate, packet_burst=burst
    )
    arm = FakeArm(move_time=0.01)

    async def main() -> None:
        with trio.fail_after(WALL_GUARD):
            async with Server(arm, config) as server, trio.open_nursery() as nursery:
                listeners = await trio.open_tcp_listeners(0, host="127.0.0.1")
                port = listeners[0].socket.getsockname()[1]
                nursery.start_soon(server.serve_listeners, listeners)
                started = trio.current_time()
                stream = await trio.open_tcp_stream("127.0.0.1", port)
                async with stream:
                    client = ClientConnection(ControllerIdentity("flood", 1), key=KEY, now=started)
                    client.connect(started)
                    while client.state is not SessionState.OPEN:
                        await stream.send_all(client.data_to_send())
                        chunk = await stream.receive_some()
                        assert chunk
                        client.receive_data(chunk, trio.current_time())
                        while client.next_event() is not None:
                            pass
                    progress = await _status_flood(
                        stream.send_all, stream.receive_some, client, count, started
                    )
                stats = server.statistics()
                nursery.cancel_scope.cancel()
        for elapsed, answered in progress:
            assert answered + 2 <= burst + rate * elapsed + 1, (elapsed, answered)
        assert stats.throttled > 0

    trio.run(main)


async def _flood_one(port: int, rng: random.Random, kind: int, bytes_budget: int) -> str:
    """One flooding connection; returns how it ended.  Bounded: at most
    ``bytes_budget`` bytes, and the caller's deadline."""
    try:
        stream = await trio.open_tcp_stream("127.0.0.1", port)
    except OSError:
        return "refused"
    async with stream:
        try:
            if kind == 0:  # noise
                await stream.send_all(rng.randbytes(bytes_budget))
            elif kind == 1:  # half-open: says nothing
                pass
            else:  # a HELLO that never finishes
                await stream.send_all(b"TL\x01\x01" + bytes(50))
            with trio.move_on_after(15.0):
                while await stream.receive_some():
                    pass
                return "closed by server"
            return "still open"
        except (trio.BrokenResourceError, trio.ClosedResourceError, OSError):
            return "reset"


def test_loopback_flood_cannot_exceed_max_connections() -> None:
    """A flood generator on 127.0.0.1 only: 60 connections in waves of 20
    (noise, silent, half a HELLO), 64 KiB each at most, all within WALL_GUARD
    seconds.  The server never holds more than max_connections, refuses or drops
    the rest, and then serves a good controller."""
    arm = FakeArm(move_time=0.01)
    config = ServerConfig(key=KEY, max_connections=4, handshake_timeout=2.0, rtt_hint=0.05)
    outcomes: list[str] = []
    peak = 0

    async def main() -> None:
        nonlocal peak
        with trio.fail_after(WALL_GUARD):
            async with Server(arm, config) as server, trio.open_nursery() as nursery:
                listeners = await trio.open_tcp_listeners(0, host="127.0.0.1")
                port = listeners[0].socket.getsockname()[1]
                nursery.start_soon(server.serve_listeners, listeners)

                async def watch() -> None:
                    nonlocal peak
                    while True:
                        peak = max(peak, server.statistics().connections)
                        await trio.sleep(0.002)

                nursery.start_soon(watch)

                async def flood(i: int) -> None:
                    outcomes.append(await _flood_one(port, random.Random(i), i % 3, 64 * 1024))

                for wave in range(3):
                    async with trio.open_nursery() as waves:
                        for i in range(20):
                            waves.start_soon(flood, wave * 20 + i)
                async with connect_tcp("127.0.0.1", port, key=KEY, identity="good") as c:
                    await c.move_joint(1, 0.1)
                stats = server.statistics()
                nursery.cancel_scope.cancel()
        assert peak <= config.max_connections
        assert len(outcomes) == 60
        assert "still open" not in outcomes
        # The flood was turned away: refused when the slots held sessions,
        # or its older handshakes closed to admit newer connections.
        assert stats.refused + stats.handshakes_evicted > 0
        assert arm.count(CommandCode.MOVE_JOINT) == 1

    trio.run(main)
