"""The teleoperation channel (PROTOCOL.md section 14): codec, handshake, latest value,
rate adaptation, STOP priority and authentication, on virtual time."""

from __future__ import annotations

import random

import pytest
import trio
import trio.testing

from tcpstream.teleop import (
    ArmChannel,
    Backlog,
    Buttons,
    ChannelState,
    ContactFlags,
    Granted,
    OperatorArrived,
    OperatorChannel,
    RefuseCode,
    Refused,
    Reply,
    ReplyStatus,
    Sample,
    SampleArrived,
    StopArrived,
    TeleopArm,
    TeleopKind,
    TeleopMode,
    TeleopPacketError,
    TeleopRefused,
    decode_header,
    decode_reply,
    decode_sample,
    encode_reply,
    encode_sample,
    open_teleop,
    size_of,
)

KEY = b"telelink-test-vector-key-000001!"
ZERO6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def sample(n: int, x: float = 0.0, *, mode: TeleopMode = TeleopMode.CARTESIAN) -> Sample:
    return Sample(n, mode, Buttons.ENGAGED, 0, n / 104.0, (x, 0.0, 0.0, 0.0, 0.0, 0.0))


def reply(n: int, held: float = 0.0) -> Reply:
    return Reply(
        n, ReplyStatus.FOLLOWING, ContactFlags(0), 2, 0, n / 104.0, held, ZERO6, ZERO6, ZERO6
    )


def pair(key: bytes | None = KEY) -> tuple[OperatorChannel, ArmChannel]:
    op = OperatorChannel("operator", key, bytes(range(16)))
    arm = ArmChannel(key, bytes(range(16, 32)), rate_deadman=3.0, control_rate=125.0)
    return op, arm


def handshake(op: OperatorChannel, arm: ArmChannel) -> None:
    op.connect()
    events = arm.receive_data(op.data_to_send(), 0.0)
    if op._psk is not None:
        assert events == []
        assert op.receive_data(arm.data_to_send(), 0.0) == []  # CHALLENGE -> AUTH
        events = arm.receive_data(op.data_to_send(), 0.0)
    assert events == [OperatorArrived("operator")]
    arm.grant()
    assert op.receive_data(arm.data_to_send(), 0.0) == [Granted(3.0, 125.0)]
    assert op.state is arm.state is ChannelState.OPEN


# --- codec ---------------------------------------------------------------------------


def test_sizes_are_compact() -> None:
    assert size_of(TeleopKind.SAMPLE) == 56
    assert size_of(TeleopKind.REPLY) == 108
    assert size_of(TeleopKind.STOP) == 24


def test_sample_round_trip_and_float32_words() -> None:
    s = Sample(
        7,
        TeleopMode.RATE,
        Buttons.ENGAGED | Buttons.POSE_CHANGE,
        200,
        1.5,
        (0.25, -0.5, 0, 0, 0, 1),
    )
    raw = encode_sample(s, 3, None, b"\x11")
    assert len(raw) == 56
    assert decode_header(raw) == (TeleopKind.SAMPLE, 3, 56)
    assert decode_sample(raw) == s
    assert raw[-8:] == bytes(8)  # unkeyed: zero tag


@pytest.mark.parametrize(
    ("offset", "value", "why"),
    [
        (12, 9, "unknown mode"),
        (13, 0x80, "unknown button"),
        (15, 1, "reserved"),
        (8, 0, "number 0"),
    ],
)
def test_bad_sample_fields_are_typed_errors(offset: int, value: int, why: str) -> None:
    raw = bytearray(encode_sample(sample(1), 1, None, b"\x11"))
    if offset == 8:
        raw[8:12] = bytes(4)
    else:
        raw[offset] = value
    with pytest.raises(TeleopPacketError):
        decode_sample(bytes(raw))


def test_non_finite_words_are_refused_both_ways() -> None:
    with pytest.raises(ValueError, match="not finite"):
        encode_sample(
            Sample(1, TeleopMode.JOINT, Buttons(0), 0, 0.0, (float("nan"), 0, 0, 0, 0, 0)),
            1,
            None,
            b"",
        )
    raw = bytearray(encode_sample(sample(1), 1, None, b"\x11"))
    raw[24:28] = b"\x7f\xc0\x00\x00"  # float32 NaN in word 0
    with pytest.raises(TeleopPacketError):
        decode_sample(bytes(raw))


def test_reply_round_trip() -> None:
    r = Reply(
        9,
        ReplyStatus.FORCE_LIMIT,
        ContactFlags.CONTACT | ContactFlags.FORCE_LIMIT,
        2,
        255,
        2.0,
        0.5,
        (1, 2, 3, 0.5, 0, 0),
        (0.5, 0, 0.25, 0, 0, 0),
        (0.5, 0, 0.25, 0, 0, 0),
    )
    raw = encode_reply(r, 4, KEY, b"\x12")
    assert len(raw) == 108
    assert decode_reply(raw) == r


def test_bad_magic_is_a_resync() -> None:
    with pytest.raises(TeleopPacketError) as info:
        decode_header(b"TL\x01\x06\x00\x00\x00\x01")
    assert info.value.resync


# --- the sans-I/O channel -------------------------------------------------------------


@pytest.mark.parametrize("key", [KEY, None])
def test_handshake_keyed_and_unkeyed(key: bytes | None) -> None:
    op, arm = pair(key)
    handshake(op, arm)


def test_wrong_key_is_refused_without_saying_why() -> None:
    op = OperatorChannel("operator", b"x" * 32, bytes(16))
    arm = ArmChannel(KEY, bytes(16), rate_deadman=1.0, control_rate=100.0)
    op.connect()
    arm.receive_data(op.data_to_send(), 0.0)
    op.receive_data(arm.data_to_send(), 0.0)
    assert arm.receive_data(op.data_to_send(), 0.0) == [Refused(RefuseCode.NOT_AUTHORIZED)]
    assert op.receive_data(arm.data_to_send(), 0.0) == [Refused(RefuseCode.NOT_AUTHORIZED)]
    assert arm.state is op.state is ChannelState.CLOSED


def test_keyed_operator_refuses_an_arm_that_grants_without_challenge() -> None:
    op = OperatorChannel("operator", KEY, bytes(16))
    arm = ArmChannel(None, bytes(16), rate_deadman=1.0, control_rate=100.0)
    op.connect()
    arm.receive_data(op.data_to_send(), 0.0)
    arm.grant()
    events = op.receive_data(arm.data_to_send(), 0.0)
    assert op.state is ChannelState.CLOSED
    assert op.granted is None
    assert events[0].reason is RefuseCode.NOT_AUTHORIZED  # type: ignore[union-attr]


def test_coalescing_latest_value_at_both_ends() -> None:
    op, arm = pair()
    handshake(op, arm)
    for n in range(1, 6):
        op.offer(sample(n, 0.01 * n))
    assert op.poll(0.1) is True
    assert op.poll(0.1) is False  # nothing pending
    st = op.statistics()
    assert (st.samples_offered, st.samples_sent, st.samples_coalesced) == (5, 1, 4)
    op.offer(sample(6, 0.06))
    op.poll(0.2)
    events = arm.receive_data(op.data_to_send(), 0.3)
    assert [e.sample.sample for e in events if isinstance(e, SampleArrived)] == [5, 6]
    latest = arm.take_latest()
    assert latest is not None
    assert latest[0].sample == 6
    assert latest[0].words[0] == pytest.approx(0.06)
    assert arm.take_latest() is None
    assert arm.statistics().samples_superseded == 1


def test_transport_backlog_holds_samples_back() -> None:
    op, arm = pair()
    handshake(op, arm)
    op.offer(sample(1))
    assert op.poll(0.0, Backlog(queued_bytes=10)) is False
    assert op.poll(0.0, Backlog(queued_bytes=0, line_seconds=0.2)) is False
    op.offer(sample(2))
    assert op.poll(0.0, Backlog(queued_bytes=0)) is True
    st = op.statistics()
    assert (st.held_by_backlog, st.samples_sent, st.samples_coalesced) == (2, 1, 1)


def test_window_without_figures_grows_with_the_measured_path() -> None:
    op, arm = pair()
    handshake(op, arm)
    size = size_of(TeleopKind.SAMPLE)
    assert op.window_bytes() == 16 * size
    sent = 0
    for n in range(1, 40):
        op.offer(sample(n))
        sent += op.poll(0.0)
    assert sent == 16
    assert op.in_flight_bytes() == 16 * size
    # A reply for sample 8 after 1.0 s (0.1 s of it held at the arm): rtt 0.9 s.
    op.receive_data(b"", 1.0)
    arm.receive_data(op.data_to_send(), 0.5)
    arm.reply(reply(8, held=0.1))
    arm.poll(0.5)
    op.receive_data(arm.data_to_send(), 1.0)
    assert op.statistics().min_rtt == pytest.approx(0.9)
    assert op.in_flight_bytes() == 8 * size
    arm.reply(reply(16, held=0.1))
    arm.poll(1.5)
    op.receive_data(arm.data_to_send(), 2.0)
    # 8 samples acknowledged in 1 s: 448 B/s; window 2 x 448 x 0.9.
    assert op.statistics().delivery_rate == pytest.approx(448.0)
    assert op.window_bytes() == pytest.approx(2 * 448.0 * 0.9)


def test_stop_overtakes_the_pending_sample() -> None:
    op, arm = pair()
    handshake(op, arm)
    op.offer(sample(1))
    op.emergency_stop()
    assert op.pending is None
    assert op.poll(0.0) is False
    events = arm.receive_data(op.data_to_send(), 0.1)
    assert events == [StopArrived(0.1)]
    assert arm.stopped


def test_tampered_and_replayed_packets_are_counted_drops() -> None:
    op, arm = pair()
    handshake(op, arm)
    op.offer(sample(1))
    op.poll(0.0)
    good = op.data_to_send()
    bad = bytearray(good)
    bad[30] ^= 1
    assert arm.receive_data(bytes(bad), 0.0) == []
    assert arm.receive_data(good, 0.0) != []
    assert arm.receive_data(good, 0.0) == []  # the same counter again
    st = arm.statistics()
    assert (st.tag_failures, st.replays, st.samples_received) == (1, 1, 1)


def test_eight_bad_packets_in_a_row_end_the_channel() -> None:
    op, arm = pair()
    handshake(op, arm)
    op.offer(sample(1))
    op.poll(0.0)
    bad = bytearray(op.data_to_send())
    bad[-1] ^= 0xFF
    for _ in range(8):
        arm.receive_data(bytes(bad), 0.0)
    assert arm.state is ChannelState.CLOSED
    assert arm.data_to_send()[3] == TeleopKind.BYE


def test_parser_three_ways_and_garbage() -> None:
    op, arm = pair(None)
    handshake(op, arm)
    for n in range(1, 4):
        op.offer(sample(n))
        op.poll(0.0)
    wire = op.data_to_send()
    one_by_one = ArmChannel(None, bytes(16), rate_deadman=1.0, control_rate=100.0)
    whole, trailing = pair(None)[1], pair(None)[1]
    for a in (one_by_one, whole, trailing):
        a._state = ChannelState.OPEN
    got = [e for b in wire for e in one_by_one.receive_data(bytes([b]), 0.0)]
    assert [e.sample.sample for e in got if isinstance(e, SampleArrived)] == [1, 2, 3]
    assert len(whole.receive_data(wire, 0.0)) == 3
    assert len(trailing.receive_data(b"xyT" + wire + b"TT\x01", 0.0)) == 3
    assert trailing.statistics().resyncs >= 1


# --- over a stream, virtual time ------------------------------------------------------


async def _run_pair(n_samples: int, key: bytes | None) -> tuple[list[int], TeleopArm]:
    a, b = trio.testing.memory_stream_pair()
    applied: list[int] = []
    arm = TeleopArm(
        key=key, rate_deadman=1.0, control_rate=125.0, nonce_source=random.Random(1).randbytes
    )
    async with trio.open_nursery() as nursery:
        nursery.start_soon(arm.serve_stream, b)
        async with open_teleop(
            a, identity="op", key=key, nonce_source=random.Random(2).randbytes
        ) as op:
            for n in range(1, n_samples + 1):
                op.submit(sample(n, n * 1e-3))
                await trio.sleep(1 / 104)
                got = arm.latest()
                if got is not None:
                    applied.append(got[0].sample)
                    arm.reply(reply(got[0].sample))
            await trio.sleep(0.1)
            assert op.last_reply is not None
            assert op.last_reply.sample == applied[-1]
        nursery.cancel_scope.cancel()
    return applied, arm


@pytest.mark.parametrize("key", [KEY, None])
def test_over_a_stream_every_sample_is_applied(key: bytes | None) -> None:
    applied, _arm = trio.run(
        _run_pair, 208, key, clock=trio.testing.MockClock(autojump_threshold=0)
    )
    assert applied == list(range(1, 209))


async def _busy() -> None:
    arm = TeleopArm(key=KEY, rate_deadman=1.0, control_rate=125.0)
    a1, b1 = trio.testing.memory_stream_pair()
    a2, b2 = trio.testing.memory_stream_pair()
    async with trio.open_nursery() as nursery:
        nursery.start_soon(arm.serve_stream, b1)
        nursery.start_soon(arm.serve_stream, b2)
        async with open_teleop(a1, identity="first", key=KEY):
            with pytest.raises(TeleopRefused) as info:
                async with open_teleop(a2, identity="second", key=KEY):
                    pass
            assert info.value.reason is RefuseCode.BUSY
        nursery.cancel_scope.cancel()


def test_a_second_operator_is_refused_busy() -> None:
    trio.run(_busy, clock=trio.testing.MockClock(autojump_threshold=0))


def test_over_tls_keyed() -> None:
    """The channel over TLS (trio.SSLStream, trustme's CA) on an in-memory transport."""
    import ssl

    import trustme

    ca = trustme.CA()
    server_ctx = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    ca.issue_cert("localhost").configure_cert(server_ctx)
    client_ctx = ssl.create_default_context()
    ca.configure_trust(client_ctx)

    async def main() -> list[int]:
        a, b = trio.testing.memory_stream_pair()
        op_tls = trio.SSLStream(a, client_ctx, server_hostname="localhost")
        arm_tls = trio.SSLStream(b, server_ctx, server_side=True)
        got: list[int] = []

        def on_sample(s: Sample, _now: float) -> None:
            got.append(s.sample)
            arm.reply(reply(s.sample))  # the replies open the operator's window

        arm = TeleopArm(key=KEY, rate_deadman=1.0, control_rate=125.0, on_sample=on_sample)
        async with trio.open_nursery() as nursery:
            nursery.start_soon(arm.serve_stream, arm_tls)
            async with open_teleop(op_tls, identity="op", key=KEY) as op:
                for n in range(1, 53):
                    op.submit(sample(n))
                    await trio.sleep(1 / 104)
                await trio.sleep(0.1)
            nursery.cancel_scope.cancel()
        return got

    assert trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0)) == list(range(1, 53))


@pytest.mark.parametrize(
    ("key", "reason"), [(KEY, RefuseCode.NOT_AUTHORIZED), (None, RefuseCode.BAD_HELLO)]
)
def test_a_sample_before_the_hello_is_refused(key: bytes | None, reason: RefuseCode) -> None:
    """Keyed, a tagged packet before the handshake is an authentication failure; unkeyed,
    a first packet that is not a HELLO is a bad hello.  Either way: REFUSE, closed."""
    arm = ArmChannel(key, bytes(16), rate_deadman=1.0, control_rate=100.0)
    op = OperatorChannel("operator", KEY, bytes(16))
    op.offer(sample(1))  # not granted: nothing is sent
    assert op.poll(0.0) is False
    first = encode_sample(sample(1), 1, None, b"\x11")
    assert arm.receive_data(first, 0.0) == [Refused(reason)]
    assert arm.state is ChannelState.CLOSED
    assert arm.data_to_send()[3] == TeleopKind.REFUSE
    assert arm.receive_data(b"more", 0.0) == []  # a closed end reads nothing more


def test_handshake_timeouts_at_both_ends() -> None:
    async def main() -> None:
        # An operator whose arm never answers gives up.
        a, _b = trio.testing.memory_stream_pair()
        start = trio.current_time()
        with pytest.raises(TeleopRefused, match="no answer from the arm within 5 s"):
            async with open_teleop(a, identity="op", handshake_timeout=5.0):
                pass
        assert trio.current_time() - start == pytest.approx(5.0)
        # An arm whose peer never says HELLO lets it go.
        arm = TeleopArm(rate_deadman=1.0, control_rate=125.0, handshake_timeout=7.0)
        _c, d = trio.testing.memory_stream_pair()
        start = trio.current_time()
        await arm.serve_stream(d)
        assert trio.current_time() - start == pytest.approx(7.0)
        assert arm.refused == 1

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
