"""The teleoperation channel (tcpstream PROTOCOL.md section 14) under a stateful fuzzer.

An operator end and an arm end, keyed, joined by two byte queues that arrive in
any chunking.  Rules interleave what a session does -- samples in every mode,
mode changes, the index button, polls with and without the transport's
figures, control ticks that take the newest sample and reply, the emergency
stop and its copies -- with what an attacker does: forged packets of every
kind (any counter, any body, a guessed tag), replays of genuine packets, and
flipped bits in the bytes on the way.

Invariants, checked after every step:

* **authentication**: a forged, replayed or damaged packet never becomes an
  event; every sample the arm reports is one the operator made, field for
  field (mode, buttons, trigger, stamp, the words to the float32), in
  increasing sample order, never twice;
* **latest value and coalescing**: each sample offered is sent, coalesced or
  still pending, exactly once; once the queues drain, the arm's newest sample
  is the operator's newest sent one (coalescing drops only what a newer
  sample carries: the words are sums, so the pose is never corrupted);
* **the emergency stop**: no sample arrives after the STOP; the arm reports the
  STOP once, however many copies arrive; the copies are bounded and end when
  a REPLY says STOPPED;
* **bounds**: the parsers never hold more than one packet.

``make fuzz`` runs this with ``HYPOTHESIS_PROFILE=deep`` (5000 runs, fresh
randomness); the default profile is the derandomized CI one.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import hypothesis.strategies as st
import numpy as np
import pytest
from hypothesis import settings
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule

from tcpstream.teleop import (
    MAGIC,
    TAG_SIZE,
    TELEOP_VERSION,
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
    TeleopEvent,
    TeleopKind,
    TeleopMode,
    decode_header,
    size_of,
)

# The deep profile's 5000 runs take minutes: past the suite-wide timeout for tests.
pytestmark = pytest.mark.timeout(3600)

KEY = b"fuzz-teleop-key-0123456789abcdef"
MAX_PACKET = max(size_of(k) for k in TeleopKind)
MAX_STOP_COPIES = 8
"""tcpstream._teleop_connection.MAX_STOP_COPIES, restated: the bound is the contract."""
ZERO6 = (0.0,) * 6


def _packets(data: bytes) -> list[bytes]:
    """Whole packets out of one end's output (it only ever emits whole packets)."""
    out = []
    while data:
        _, _, size = decode_header(data)
        out.append(data[:size])
        data = data[size:]
    return out


def _f32(x: float) -> float:
    return float(np.float32(x))


class TeleopMachine(RuleBasedStateMachine):
    """A keyed operator and arm; the attacker shares the wire but not the key."""

    def __init__(self) -> None:
        super().__init__()
        self.op = OperatorChannel("fuzz", KEY, bytes(16))
        self.arm = ArmChannel(KEY, bytes(range(16)), rate_deadman=1.0, control_rate=100.0)
        self.op.connect()
        self.arm.receive_data(self.op.data_to_send(), 0.0)
        self.op.receive_data(self.arm.data_to_send(), 0.0)
        self.arm.receive_data(self.op.data_to_send(), 0.0)
        self.arm.grant()
        self.op.receive_data(self.arm.data_to_send(), 0.0)
        assert self.op.state is ChannelState.OPEN
        self.now = 0.0
        self.n = 0
        self.mode = TeleopMode.CARTESIAN
        self.engaged = True
        self.sums = np.zeros(6)
        self.made: dict[int, Sample] = {}
        self.sent_numbers: list[int] = []
        self.arrived: list[int] = []
        self.stop_events = 0
        self.stop_offered = False
        self.copies_when_confirmed: int | None = None
        self.to_arm = b""
        self.to_op = b""
        self.genuine: list[bytes] = []  # every packet the operator sent, for replays
        self.damaged = False

    # -- the operator ----------------------------------------------------------------

    @rule(
        dx=st.lists(st.floats(-0.01, 0.01, allow_nan=False), min_size=6, max_size=6),
        trigger=st.integers(0, 255),
    )
    def sample(self, dx: list[float], trigger: int) -> None:
        self.n += 1
        if self.mode is TeleopMode.RATE:
            words = np.array(dx) * 10  # a deflection, not a sum
        else:
            if self.engaged:
                self.sums = self.sums + np.array(dx)
            words = self.sums
        buttons = Buttons.SHARED_COMPLIANCE | (Buttons.ENGAGED if self.engaged else Buttons(0))
        s = Sample(self.n, self.mode, buttons, trigger, self.now, tuple(float(w) for w in words))  # type: ignore[arg-type]
        self.made[self.n] = s
        if self.op.state is ChannelState.OPEN:
            self.op.offer(s)

    @rule(mode=st.sampled_from(TeleopMode))
    def change_mode(self, mode: TeleopMode) -> None:
        self.mode = mode

    @rule()
    def index_button(self) -> None:
        self.engaged = not self.engaged

    @rule(figures=st.sampled_from(["none", "idle", "queued", "line"]), dt=st.floats(0, 0.3))
    def poll(self, figures: str, dt: float) -> None:
        self.now += dt
        backlog = {
            "none": None,
            "idle": Backlog(0, 0.0),
            "queued": Backlog(56, 0.0),
            "line": Backlog(0, 0.2),
        }[figures]
        pending = self.op.pending
        if self.op.poll(self.now, backlog) and pending is not None and self.op.pending is None:
            self.sent_numbers.append(pending.sample)
        out = self.op.data_to_send()
        self.genuine += _packets(out)
        self.to_arm += out

    @precondition(lambda self: self.op.state is ChannelState.OPEN and not self.stop_offered)
    @rule()
    def emergency_stop(self) -> None:
        self.stop_offered = True
        self.op.emergency_stop()
        out = self.op.data_to_send()
        self.genuine += _packets(out)
        self.to_arm += out

    # -- the wire --------------------------------------------------------------------

    @rule(cut=st.integers(1, 200))
    def deliver_to_arm(self, cut: int) -> None:
        chunk, self.to_arm = self.to_arm[:cut], self.to_arm[cut:]
        self._arm_events(self.arm.receive_data(chunk, self.now), genuine=True)

    @rule(cut=st.integers(1, 300))
    def deliver_to_operator(self, cut: int) -> None:
        chunk, self.to_op = self.to_op[:cut], self.to_op[cut:]
        for ev in self.op.receive_data(chunk, self.now):
            if isinstance(ev, ReplyReceived):
                assert ev.reply.sample == 0 or ev.reply.sample in self.made
                if ev.reply.status is ReplyStatus.STOPPED and self.copies_when_confirmed is None:
                    self.copies_when_confirmed = self.op.statistics().stops_repeated

    @precondition(lambda self: len(self.to_arm) > 0)
    @rule(at=st.integers(0, 10_000), bit=st.integers(0, 7))
    def flip_a_bit(self, at: int, bit: int) -> None:
        data = bytearray(self.to_arm)
        data[at % len(data)] ^= 1 << bit
        self.to_arm = bytes(data)
        self.damaged = True

    # -- the attacker (between packets, so a forgery is judged as a packet) ----------

    def _at_boundary(self) -> bool:
        return not self.arm._buf and self.arm.state is ChannelState.OPEN

    @precondition(lambda self: self._at_boundary() and self.arm._bad_in_row < 6)
    @rule(
        kind=st.sampled_from(TeleopKind),
        counter=st.integers(0, 2**32 - 1),
        body=st.binary(min_size=0, max_size=100),
        tag=st.binary(min_size=TAG_SIZE, max_size=TAG_SIZE),
    )
    def forge(self, kind: TeleopKind, counter: int, body: bytes, tag: bytes) -> None:
        head = MAGIC + struct.pack("!BBI", TELEOP_VERSION, kind, counter)
        size = size_of(kind)
        raw = (head + body).ljust(size - TAG_SIZE, b"\0")[: size - TAG_SIZE] + tag
        before = self.arm.statistics()
        events = self.arm.receive_data(raw, self.now)
        assert events == [] or self.arm.state is ChannelState.CLOSED, events
        assert not any(isinstance(e, (SampleArrived, StopArrived)) for e in events)
        after = self.arm.statistics()
        assert after.samples_received == before.samples_received

    @precondition(lambda self: self._at_boundary() and self.genuine and self.arm._bad_in_row < 6)
    @rule(which=st.integers(0, 10_000))
    def replay(self, which: int) -> None:
        raw = self.genuine[which % len(self.genuine)]
        if decode_header(raw)[1] > self.arm._rx_counter:
            return  # not yet delivered: that would be the genuine packet, early
        events = self.arm.receive_data(raw, self.now)
        assert not any(isinstance(e, (SampleArrived, StopArrived)) for e in events), events

    # -- the arm ---------------------------------------------------------------------

    def _arm_events(self, events: Sequence[TeleopEvent], *, genuine: bool) -> None:
        for ev in events:
            if isinstance(ev, SampleArrived):
                assert genuine
                assert self.stop_events == 0, "a sample after the STOP"
                s = ev.sample
                want = self.made[s.sample]
                assert (s.mode, s.buttons, s.trigger, s.stamp) == (
                    want.mode,
                    want.buttons,
                    want.trigger,
                    want.stamp,
                )
                assert s.words == tuple(_f32(w) for w in want.words)
                self.arrived.append(s.sample)
            elif isinstance(ev, StopArrived):
                self.stop_events += 1

    @rule()
    def control_tick(self) -> None:
        latest = self.arm.take_latest()
        if self.arm.state is not ChannelState.OPEN:
            return
        applied = latest[0] if latest is not None else None
        status = ReplyStatus.STOPPED if self.arm.stopped else ReplyStatus.FOLLOWING
        self.arm.reply(
            Reply(
                applied.sample if applied else 0,
                status,
                ContactFlags(0),
                int(applied.mode) if applied else 0,
                0,
                applied.stamp if applied else 0.0,
                0.0,
                ZERO6,
                ZERO6,
                ZERO6,
            )
        )
        self.arm.poll(self.now)
        self.to_op += self.arm.data_to_send()

    @precondition(lambda self: not self.damaged)
    @rule()
    def drain(self) -> None:
        """Send what is pending and deliver everything: the newest sample gets through."""
        self.poll("idle", 0.0)
        self.deliver_to_arm(len(self.to_arm) or 1)
        if (
            self.arm.state is ChannelState.OPEN
            and self.stop_events == 0
            and self.sent_numbers
            and self.arrived
        ):
            assert self.arrived[-1] == self.sent_numbers[-1]

    # -- invariants ------------------------------------------------------------------

    @invariant()
    def in_order_never_twice(self) -> None:
        assert self.arrived == sorted(set(self.arrived))

    @invariant()
    def every_offer_accounted_once(self) -> None:
        s = self.op.statistics()
        pending = int(self.op.pending is not None)
        assert s.samples_sent + s.samples_coalesced + pending == (
            s.samples_offered - s.samples_after_stop
        )

    @invariant()
    def one_stop_bounded_copies(self) -> None:
        assert self.stop_events <= 1
        s = self.op.statistics()
        assert s.stops_repeated <= MAX_STOP_COPIES
        if self.copies_when_confirmed is not None:
            assert s.stops_repeated == self.copies_when_confirmed

    @invariant()
    def parsers_bounded(self) -> None:
        assert len(self.op._buf) < MAX_PACKET
        assert len(self.arm._buf) < MAX_PACKET


class TestTeleopStateful(TeleopMachine.TestCase):  # type: ignore[misc,valid-type]
    settings = settings(stateful_step_count=60)
