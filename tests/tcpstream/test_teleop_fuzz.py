"""The teleoperation channel under hypothesis: any chunking of a valid stream delivers
every packet; mutated bytes are counted drops, never exceptions; a stateful run of
samples, replies, stops and a corrupting wire keeps the channel's promises."""

from __future__ import annotations

import hypothesis.strategies as st
import numpy as np
import pytest
from hypothesis import given
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule

from tcpstream.teleop import (
    ArmChannel,
    Backlog,
    Buttons,
    ChannelState,
    ContactFlags,
    OperatorChannel,
    Reply,
    ReplyReceived,
    ReplyStatus,
    Sample,
    SampleArrived,
    StopArrived,
    TeleopMode,
)

KEY = b"telelink-test-vector-key-000001!"
ZERO6 = (0.0,) * 6


def opened(key: bytes | None = KEY) -> tuple[OperatorChannel, ArmChannel]:
    op = OperatorChannel("fuzz", key, bytes(16))
    arm = ArmChannel(key, bytes(range(16)), rate_deadman=1.0, control_rate=100.0)
    op.connect()
    arm.receive_data(op.data_to_send(), 0.0)
    if key:
        op.receive_data(arm.data_to_send(), 0.0)
        arm.receive_data(op.data_to_send(), 0.0)
    arm.grant()
    op.receive_data(arm.data_to_send(), 0.0)
    assert op.state is ChannelState.OPEN
    return op, arm


def wire(n: int) -> bytes:
    op, _ = opened()
    out = b""
    for k in range(1, n + 1):
        op.offer(
            Sample(k, TeleopMode.CARTESIAN, Buttons.ENGAGED, 0, k / 100, (k * 1e-3, 0, 0, 0, 0, 0))
        )
        op.poll(0.0)
        out += op.data_to_send()
    return out


WIRE = wire(12)


@given(st.lists(st.integers(min_value=1, max_value=80), min_size=1, max_size=40))
def test_any_chunking_delivers_every_sample(cuts: list[int]) -> None:
    _, arm = opened()
    got: list[int] = []
    at = 0
    for c in [*cuts, len(WIRE)]:
        for ev in arm.receive_data(WIRE[at : at + c], 0.0):
            assert isinstance(ev, SampleArrived)
            got.append(ev.sample.sample)
        at += c
        if at >= len(WIRE):
            break
    assert got == list(range(1, 13))


@given(
    st.lists(
        st.tuples(st.integers(min_value=0, max_value=len(WIRE) - 1), st.integers(0, 255)),
        min_size=1,
        max_size=6,
    ),
    st.binary(max_size=40),
)
def test_mutations_are_counted_drops_never_exceptions(
    flips: list[tuple[int, int]], junk: bytes
) -> None:
    data = bytearray(WIRE)
    for at, value in flips:
        data[at] = value
    _, arm = opened()
    events = arm.receive_data(junk + bytes(data), 0.0)
    numbers = [e.sample.sample for e in events if isinstance(e, SampleArrived)]
    assert numbers == sorted(set(numbers))  # in order, never twice
    # Keyed: a sample that arrives is one the operator sent, word for word.
    for e in events:
        if isinstance(e, SampleArrived):
            assert e.sample.words[0] == float(np.float32(e.sample.sample * 1e-3))
    s = arm.statistics()
    assert s.samples_received == len(numbers)


class ChannelMachine(RuleBasedStateMachine):
    """Operator and arm joined by a wire that chunks and may corrupt one byte."""

    def __init__(self) -> None:
        super().__init__()
        self.op, self.arm = opened()
        self.n = 0
        self.sum = 0.0
        self.sent: dict[int, float] = {}
        self.applied: list[int] = []
        self.stopped = False
        self.to_arm = b""
        self.to_op = b""
        self.corrupted = False
        self.now = 0.0

    @rule(dx=st.floats(-0.01, 0.01, allow_nan=False))
    def sample(self, dx: float) -> None:
        self.n += 1
        self.sum += dx
        s = Sample(
            self.n, TeleopMode.CARTESIAN, Buttons.ENGAGED, 0, self.now, (self.sum, 0, 0, 0, 0, 0)
        )
        self.sent[self.n] = float(np.float32(self.sum))
        if self.op.state is ChannelState.OPEN:
            self.op.offer(s)

    @rule(queued=st.integers(0, 1))
    def poll(self, queued: int) -> None:
        self.now += 0.01
        self.op.poll(self.now, Backlog(queued) if queued else None)
        self.to_arm += self.op.data_to_send()

    @precondition(lambda self: self.op.state is ChannelState.OPEN)
    @rule()
    def stop(self) -> None:
        self.op.emergency_stop()
        self.to_arm += self.op.data_to_send()

    @rule(cut=st.integers(1, 200))
    def deliver_to_arm(self, cut: int) -> None:
        chunk, self.to_arm = self.to_arm[:cut], self.to_arm[cut:]
        for ev in self.arm.receive_data(chunk, self.now):
            if isinstance(ev, SampleArrived):
                assert not self.stopped, "a sample after STOP"
                self.applied.append(ev.sample.sample)
                assert ev.sample.words[0] == self.sent[ev.sample.sample]
            elif isinstance(ev, StopArrived):
                self.stopped = True
        latest = self.arm.take_latest()
        if latest is not None and self.arm.state is ChannelState.OPEN:
            s = latest[0]
            self.arm.reply(
                Reply(
                    s.sample,
                    ReplyStatus.FOLLOWING,
                    ContactFlags(0),
                    2,
                    0,
                    s.stamp,
                    0.0,
                    ZERO6,
                    ZERO6,
                    ZERO6,
                )
            )
            self.arm.poll(self.now)
            self.to_op += self.arm.data_to_send()

    @rule(cut=st.integers(1, 300))
    def deliver_to_operator(self, cut: int) -> None:
        chunk, self.to_op = self.to_op[:cut], self.to_op[cut:]
        for ev in self.op.receive_data(chunk, self.now):
            if isinstance(ev, ReplyReceived):
                assert ev.reply.sample in self.sent

    @precondition(lambda self: len(self.to_arm) > 0 and not self.corrupted)
    @rule(at=st.integers(0, 10_000), bit=st.integers(0, 7))
    def corrupt(self, at: int, bit: int) -> None:
        self.corrupted = True
        data = bytearray(self.to_arm)
        data[at % len(data)] ^= 1 << bit
        self.to_arm = bytes(data)

    @invariant()
    def in_order_never_twice(self) -> None:
        assert self.applied == sorted(set(self.applied))
        st_ = self.op.statistics()
        pending = int(self.op.pending is not None)
        offered = st_.samples_offered - st_.samples_after_stop
        assert st_.samples_sent + st_.samples_coalesced + pending == offered
        # Bounded parsers: never more than one packet's bytes waiting.
        assert len(self.op._buf) <= 108
        assert len(self.arm._buf) <= 108


TestChannelMachine = ChannelMachine.TestCase


def test_the_session_harness_catches_a_teleop_arm_that_skips_the_key(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """fuzz/fuzz_session.py's teleoperation property can fail: an arm without the key
    lets the wrong-key operator's HELLO through, and the harness says so."""
    from fuzz import fuzz_session

    fuzz_session.one_input(b"\xf0\x03\x03\x03")  # keyed: the liar is refused
    monkeypatch.setattr(fuzz_session, "KEY", None)
    with pytest.raises(AssertionError, match="without the key"):
        fuzz_session.one_input(b"\xf0\x03\x03\x03")
