"""The teleoperation channel on the transport's latest-value lane (PROTOCOL.md
14.8): samples and replies beside the stream, named by the channel's prefix,
dropped when stale; over a serial socket and through the mux."""

from __future__ import annotations

from collections.abc import Callable

import pytest
import trio
import trio.testing

from linksim import serial_socket_pair
from linksim.link import DirectionConfig, LinkConfig
from serialsocket import EndpointConfig, SerialSocket
from tcpstream.teleop import (
    Backlog,
    ChannelState,
    OperatorChannel,
    ReplyReceived,
    SampleArrived,
    TeleopArm,
    encode_sample,
    open_mux,
    open_teleop,
)

from .test_teleop_channel import KEY, handshake, pair, reply, sample


def lane_pair(key: bytes | None = KEY) -> tuple[OperatorChannel, object]:
    op, arm = pair(key)
    op.use_lane()
    arm.use_lane()
    handshake(op, arm)
    return op, arm


@pytest.mark.parametrize("key", [KEY, None])
def test_samples_and_replies_go_on_the_lane_everything_else_on_the_stream(
    key: bytes | None,
) -> None:
    op, arm = pair(key)
    op.use_lane()
    arm.use_lane()
    handshake(op, arm)  # the handshake itself travels on the stream
    op.offer(sample(1, 0.5))
    assert op.poll(1.0)
    assert op.data_to_send() == b""
    message = op.lane_to_send()
    assert message is not None
    assert message[:4] == bytes(range(4))  # the operator's HELLO nonce names the channel
    events = arm.receive_lane(message, 1.5)
    assert [type(e) for e in events] == [SampleArrived]
    assert arm.take_latest() is not None
    arm.reply(reply(1))
    assert arm.poll(1.6)
    assert arm.data_to_send() == b""
    back = arm.lane_to_send()
    assert back is not None
    assert [type(e) for e in op.receive_lane(back, 2.0)] == [ReplyReceived]
    op.emergency_stop()  # STOP stays on the stream
    assert op.lane_to_send() is None
    assert op.data_to_send()
    assert op.statistics().lane_packets_out == 1
    assert arm.statistics().lane_packets_in == 1


def test_a_lane_message_of_another_channel_or_before_the_grant_is_stale() -> None:
    op, arm = pair()
    op.use_lane()
    arm.use_lane()
    op.connect()
    # Before the HELLO arrived, and before the grant: dropped, counted, harmless.
    early = bytes(range(4)) + encode_sample(sample(1), 5, None, b"\x11")
    assert arm.receive_lane(early, 0.0) == []
    handshake_rest(op, arm)
    old = bytes(4) + encode_sample(sample(2), 50, arm._key, b"\x11")  # another channel's prefix
    assert arm.receive_lane(old, 1.0) == []
    stats = arm.statistics()
    assert stats.lane_stale == 2
    assert stats.bad_packets == 0
    assert arm.state is ChannelState.OPEN


def handshake_rest(op: OperatorChannel, arm: object) -> None:
    from tcpstream.teleop import ArmChannel

    assert isinstance(arm, ArmChannel)
    arm.receive_data(op.data_to_send(), 0.0)
    op.receive_data(arm.data_to_send(), 0.0)
    arm.receive_data(op.data_to_send(), 0.0)
    arm.grant()
    op.receive_data(arm.data_to_send(), 0.0)
    assert op.state is arm.state is ChannelState.OPEN


def test_a_sample_overtaken_by_a_stop_on_the_stream_is_dropped_not_punished() -> None:
    op, arm = lane_pair()
    op.offer(sample(1))
    assert op.poll(1.0)
    message = op.lane_to_send()
    assert message is not None
    op.emergency_stop()
    arm.receive_data(op.data_to_send(), 1.2)  # the STOP (counter above the sample's) first
    assert arm.receive_lane(message, 1.3) == []
    stats = arm.statistics()
    assert stats.lane_stale == 1
    assert stats.replays == 0
    assert stats.bad_packets == 0


def test_forged_and_malformed_lane_messages_are_counted_never_applied() -> None:
    op, arm = lane_pair()
    prefix = bytes(range(4))
    forged = prefix + encode_sample(sample(9, 3.0), 99, b"\x00" * 32, b"\x11")  # wrong key
    assert arm.receive_lane(forged, 1.0) == []
    assert arm.receive_lane(prefix + b"TT\x01", 1.0) == []  # a short header
    assert arm.receive_lane(prefix + encode_sample(sample(3), 7, None, b"\x11")[:-1], 1.0) == []
    wrong_kind = prefix + op_stop_packet(op)
    assert arm.receive_lane(wrong_kind, 1.0) == []
    assert arm.take_latest() is None
    stats = arm.statistics()
    assert stats.tag_failures == 1
    assert stats.bad_packets == 3


def op_stop_packet(op: OperatorChannel) -> bytes:
    op.emergency_stop()
    return op.data_to_send()


def test_replaced_on_the_transport_counts_as_coalesced() -> None:
    op, _arm = lane_pair()
    for n in (1, 2):
        op.offer(sample(n))
        assert op.poll(float(n))
        assert op.lane_to_send() is not None
    op.lane_replaced()  # the second replaced the first before it left
    stats = op.statistics()
    assert stats.samples_sent == 1
    assert stats.samples_coalesced == 1
    assert stats.samples_sent + stats.samples_coalesced == stats.samples_offered


LINE = LinkConfig.symmetric(DirectionConfig(rate=2400, delay=1.3))


@pytest.mark.parametrize("through_mux", [False, True])
def test_over_a_serial_socket_samples_take_the_lane(through_mux: bool) -> None:
    got: list[int] = []

    async def main() -> None:
        with trio.fail_after(600):
            async with serial_socket_pair(LINE) as (ctl, far):
                arm = TeleopArm(
                    key=KEY,
                    rate_deadman=3.0,
                    control_rate=125.0,
                    on_sample=lambda s, now: got.append(s.sample),
                )
                async with trio.open_nursery() as nursery:
                    if through_mux:
                        mux_ctl = await _enter(nursery, ctl)
                        mux_far = await _enter(nursery, far)
                        assert mux_ctl.teleop.latest
                        assert not mux_ctl.commands.latest
                        near, remote = mux_ctl.teleop, mux_far.teleop
                    else:
                        near, remote = ctl, far
                    nursery.start_soon(arm.serve_stream, remote)
                    async with open_teleop(
                        near, identity="operator", key=KEY, backlog=_figures(ctl)
                    ) as op:
                        for n in range(1, 301):  # 3 s at 100 Hz
                            op.submit(sample(n, n * 1e-3))
                            await trio.sleep(0.01)
                        with trio.fail_after(30):
                            while not got or got[-1] != 300:
                                await trio.sleep(0.05)
                        stats = op.statistics()
                        assert stats.lane_packets_out == stats.samples_sent
                        assert stats.lane_packets_out > 3
                    nursery.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    assert got == sorted(set(got))


def _figures(sock: SerialSocket) -> Callable[[], Backlog]:
    """The socket's own figures, as the channel's pacing wants them: what it
    holds unsent, and the line's queue followed from the bytes written to the
    port (as linksim's teleop runner does; ``line_backlog`` is as of the
    endpoint's last event)."""
    char_time = 10 / 2400
    state = {"out": 0, "line": 0.0, "at": trio.current_time()}

    def probe() -> Backlog:
        st = sock.statistics()
        now = trio.current_time()
        line = max(0.0, state["line"] - (now - state["at"]))
        line += (st.port_bytes_out - state["out"]) * char_time
        state.update(out=st.port_bytes_out, line=line, at=now)
        return Backlog(st.link.bytes_queued, line)

    return probe


async def _enter(nursery: trio.Nursery, stream: trio.abc.Stream):  # type: ignore[no-untyped-def]
    """A mux on ``stream`` living in ``nursery``."""
    ready: list[object] = []
    done = trio.Event()

    async def hold() -> None:
        async with open_mux(stream) as mux:
            ready.append(mux)
            done.set()
            await trio.sleep_forever()

    nursery.start_soon(hold)
    await done.wait()
    return ready[0]


def test_a_lane_too_short_for_a_sample_falls_back_to_the_stream() -> None:
    """A negotiated packet length too short for a sample in one packet: the lane
    refuses it, and the channel carries on over the stream."""
    tiny = EndpointConfig(max_packet_length=40, line_rate=2400, one_way_delay=1.3)
    got: list[int] = []

    async def main() -> None:
        with trio.fail_after(600):
            async with serial_socket_pair(LINE, endpoint=tiny) as (ctl, far):
                assert ctl.latest
                arm = TeleopArm(
                    rate_deadman=3.0,
                    control_rate=125.0,
                    on_sample=lambda s, now: got.append(s.sample),
                )
                async with trio.open_nursery() as nursery:
                    nursery.start_soon(arm.serve_stream, far)
                    async with open_teleop(ctl, identity="operator", backlog=_figures(ctl)) as op:
                        # One sample alone: refused by the lane, it must still go (it
                        # waited in the channel's output for a wake that never came).
                        op.submit(sample(1))
                        with trio.fail_after(30):
                            while got != [1]:
                                await trio.sleep(0.05)
                        for n in range(2, 101):
                            op.submit(sample(n))
                            await trio.sleep(0.01)
                        with trio.fail_after(60):
                            while not got or got[-1] != 100:
                                await trio.sleep(0.05)
                        assert op.statistics().lane_packets_out == 0
                    nursery.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    assert got == sorted(set(got))
