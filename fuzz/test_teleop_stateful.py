"""The teleoperation channel (tcpstream PROTOCOL.md section 14) under a stateful fuzzer.

An operator end and an arm end, keyed, joined by two byte queues that arrive in
any chunking -- and, in about half the runs, by the transport's latest-value
lane too (section 14.8: samples and replies travel there, everything else on
the stream).  Rules interleave what a session does -- samples in every mode,
mode changes, the index button, polls with and without the transport's
figures, control ticks that take the newest sample and reply, the emergency
stop and its copies -- with what the lane does (a value waiting for the line
is replaced by a newer one; values on the line arrive in order, at most once,
or are lost; they overtake the stream's bytes or are overtaken by them; the
transport may refuse the lane, sending the rest on the stream) and with what
an attacker does: forged packets of every kind (any counter, any body, a
guessed tag), replays of genuine packets, and flipped bits in the bytes on the
way; on the lane also messages of another channel, reflected ones (a sample
sent back to the operator, a reply to the arm) and stream packets put on it.

Invariants, checked after every step:

* **authentication**: a forged, replayed, reflected, damaged or foreign
  packet never becomes an event; every sample the arm reports is one the
  operator made, field for field (mode, buttons, trigger, stamp, the words to
  the float32), in increasing sample order, never twice; every reply the
  operator reports is one the arm made, in order, never twice;
* **latest value and coalescing**: each sample (reply) offered is sent,
  coalesced or still pending, exactly once -- a value the lane replaced before
  it left counts as coalesced, not sent; once the queues drain, the arm's
  newest sample is the operator's newest sent one that was not lost on the
  lane (coalescing drops only what a newer sample carries: the words are sums,
  so the pose is never corrupted);
* **the emergency stop**: no sample arrives after the STOP; the arm reports the
  STOP once, however many copies arrive; the copies are bounded and end when
  a REPLY says STOPPED;
* **bounds**: the parsers never hold more than one packet.

``make fuzz`` runs this with ``HYPOTHESIS_PROFILE=deep`` (5000 runs, fresh
randomness); the default profile is the derandomized CI one.
"""

from __future__ import annotations

import struct
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import hypothesis.strategies as st
import numpy as np
import pytest
from hypothesis import settings
from hypothesis.stateful import (
    RuleBasedStateMachine,
    initialize,
    invariant,
    precondition,
    rule,
)

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
OPERATOR_NONCE = bytes(range(0xA0, 0xB0))
MAX_PACKET = max(size_of(k) for k in TeleopKind)
MAX_STOP_COPIES = 8
"""tcpstream._teleop_connection.MAX_STOP_COPIES, restated: the bound is the contract."""
LANE_PREFIX = OPERATOR_NONCE[:4]
"""PROTOCOL.md 14.8, restated: a lane message is the operator's nonce[0:4], then the packet."""
LANE_DEPTH = 2
"""Lane messages on the simulated line at once, per direction (besides the one waiting)."""
ZERO6 = (0.0,) * 6
VALUE_EVENTS = (SampleArrived, StopArrived, ReplyReceived)


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


def _counter(message: bytes) -> int:
    return decode_header(message[len(LANE_PREFIX) :])[1]


@dataclass
class _Value:
    """One lane message and what it carries: a sample number or a reply serial."""

    message: bytes
    number: int
    flipped: bool = False


@dataclass
class _Lane:
    """One direction of the transport's latest-value lane.

    At most one value waits for the line (a newer one replaces it: the sender
    hears of it through ``lane_replaced``); up to :data:`LANE_DEPTH` are on the
    line, to arrive in order, each at most once, or to be lost.  The lane and
    the stream are independent: either may overtake the other.
    """

    waiting: _Value | None = None
    line: deque[_Value] = field(default_factory=deque)
    genuine: list[bytes] = field(default_factory=list)  # every message sent, for replays
    lost: set[int] = field(default_factory=set)  # numbers lost or damaged on the way
    accepted: int = 0  # messages the transport took on its lane
    replaced: int = 0
    refuse_next: bool = False  # the transport refuses the next message (too long for a packet)

    def push(self, value: _Value) -> _Value | None:
        """Hand a message to the transport; returns the waiting one it replaced."""
        replaced, self.waiting = self.waiting, value
        self.accepted += 1
        self.genuine.append(value.message)
        if replaced is not None:
            self.replaced += 1
        self.to_line()  # an idle line takes it at once
        return replaced

    def to_line(self, *, depth: int = LANE_DEPTH) -> None:
        if self.waiting is not None and len(self.line) < depth:
            self.line.append(self.waiting)
            self.waiting = None


class TeleopMachine(RuleBasedStateMachine):
    """A keyed operator and arm; the attacker shares the wire but not the key."""

    def __init__(self) -> None:
        super().__init__()
        self.op = OperatorChannel("fuzz", KEY, OPERATOR_NONCE)
        self.arm = ArmChannel(KEY, bytes(range(16)), rate_deadman=1.0, control_rate=100.0)
        self.lane_mode = False
        self.stop_after = 0
        self.now = 0.0
        self.n = 0
        self.mode = TeleopMode.CARTESIAN
        self.engaged = True
        self.sums = np.zeros(6)
        self.made: dict[int, Sample] = {}
        self.sent_numbers: list[int] = []  # samples the transport carries (not replaced)
        self.arrived: list[int] = []
        self.replies: dict[int, tuple[int, ReplyStatus]] = {}  # serial -> (sample, status)
        self.replies_sent: list[int] = []
        self.replies_arrived: list[int] = []
        self.stop_events = 0
        self.stop_offered = False
        self.copies_when_confirmed: int | None = None
        self.to_arm = b""
        self.to_op = b""
        self.genuine: list[bytes] = []  # every packet the operator sent, for replays
        self.genuine_arm: list[bytes] = []  # the arm's stream packets (the handshake's)
        self.damaged = False
        self.lane_to_arm = _Lane()
        self.lane_to_op = _Lane()

    @initialize(lane=st.booleans(), stop_after=st.integers(0, 12))
    def handshake(self, lane: bool, stop_after: int) -> None:
        """Open the channel, on a transport with a latest-value lane or without.

        The STOP ends the samples, and a rule among many is soon drawn: it may be
        pressed only after ``stop_after`` samples, so that most runs see samples
        flow (0, where a shrink goes, keeps it available from the start)."""
        self.lane_mode = lane
        self.stop_after = stop_after
        if lane:
            self.op.use_lane()
            self.arm.use_lane()
        self.op.connect()
        self.arm.receive_data(self.op.data_to_send(), 0.0)
        self.op.receive_data(self._arm_out(), 0.0)
        self.arm.receive_data(self.op.data_to_send(), 0.0)
        if lane:
            # Not yet OPEN at either end: a lane message is stale, whatever it holds.
            for end in (self.arm, self.op):
                assert end.receive_lane(LANE_PREFIX + bytes(56), 0.0) == []
                assert end.statistics().lane_stale == 1
        self.arm.grant()
        self.op.receive_data(self._arm_out(), 0.0)
        assert self.op.state is ChannelState.OPEN

    def _arm_out(self) -> bytes:
        out = self.arm.data_to_send()
        self.genuine_arm += _packets(out)
        return out

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
            self._to_lane(self.op, self.lane_to_arm, pending.sample, self.sent_numbers)
        else:
            assert self.op.lane_to_send() is None
        out = self.op.data_to_send()
        self.genuine += _packets(out)
        self.to_arm += out

    def _to_lane(
        self, end: OperatorChannel | ArmChannel, lane: _Lane, number: int, sent: list[int]
    ) -> None:
        """What the I/O loop does after a poll: the lane message, if any, to the transport."""
        message = end.lane_to_send()
        if not end.lane:
            assert message is None  # not in lane mode, or refused before: on the stream
            return
        assert message is not None
        assert message[: len(LANE_PREFIX)] == LANE_PREFIX
        if lane.refuse_next:
            lane.refuse_next = False
            end.lane_refused(message)  # the packet goes on the stream, and every later one
            return
        if end is self.op:
            self.genuine.append(message[len(LANE_PREFIX) :])
        replaced = lane.push(_Value(message, number))
        if replaced is not None:
            end.lane_replaced()
            sent.remove(replaced.number)

    @precondition(
        lambda self: (
            self.op.state is ChannelState.OPEN
            and not self.stop_offered
            and self.n >= self.stop_after
        )
    )
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
        self._op_events(self.op.receive_data(chunk, self.now), genuine=True)

    @precondition(lambda self: len(self.to_arm) > 0)
    @rule(at=st.integers(0, 10_000), bit=st.integers(0, 7))
    def flip_a_bit(self, at: int, bit: int) -> None:
        data = bytearray(self.to_arm)
        data[at % len(data)] ^= 1 << bit
        self.to_arm = bytes(data)
        self.damaged = True

    # -- the lane --------------------------------------------------------------------

    def _lane(self, to_arm: bool) -> tuple[_Lane, OperatorChannel | ArmChannel]:
        """The lane in that direction and its receiving end."""
        return (self.lane_to_arm, self.arm) if to_arm else (self.lane_to_op, self.op)

    def _lane_deliver(self, to_arm: bool) -> None:
        lane, end = self._lane(to_arm)
        value = lane.line.popleft()
        events = end.receive_lane(value.message, self.now)
        if value.flipped:
            assert not any(isinstance(e, VALUE_EVENTS) for e in events), events
        if to_arm:
            self._arm_events(events, genuine=not value.flipped)
        else:
            self._op_events(events, genuine=not value.flipped)

    @precondition(
        lambda self: (
            self.lane_to_arm.waiting
            or self.lane_to_arm.line
            or self.lane_to_op.waiting
            or self.lane_to_op.line
        )
    )
    @rule(
        to_arm=st.booleans(),
        # Deliveries weigh most: it takes several values on the lane to race or replace.
        what=st.sampled_from(["deliver", "deliver", "deliver", "lose", "line", "flip", "refuse"]),
        which=st.integers(0, LANE_DEPTH),
        at=st.integers(0, 200),
        bit=st.integers(0, 7),
    )
    def lane(self, to_arm: bool, what: str, which: int, at: int, bit: int) -> None:
        """The lane's doing: the value at the head of the line arrives or is lost; the
        waiting one goes on the line; a bit flips on the line; the transport will
        refuse the next value (too long for one of its packets: to the stream)."""
        if not (self._lane(to_arm)[0].line or self._lane(to_arm)[0].waiting):
            to_arm = not to_arm  # the precondition says the other has something
        lane, _ = self._lane(to_arm)
        if what == "refuse":
            lane.refuse_next = True
        elif what == "line":
            lane.to_line()
        elif not lane.line:
            return
        elif what == "deliver":
            self._lane_deliver(to_arm)
        elif what == "lose":
            lane.lost.add(lane.line.popleft().number)
        else:
            value = lane.line[which % len(lane.line)]
            data = bytearray(value.message)
            data[at % len(data)] ^= 1 << bit
            value.message = bytes(data)
            value.flipped = True
            lane.lost.add(value.number)

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
        raw = self._forgery(kind, counter, body, tag)
        before = self.arm.statistics()
        events = self.arm.receive_data(raw, self.now)
        assert events == [] or self.arm.state is ChannelState.CLOSED, events
        assert not any(isinstance(e, (SampleArrived, StopArrived)) for e in events)
        after = self.arm.statistics()
        assert after.samples_received == before.samples_received

    @staticmethod
    def _forgery(kind: TeleopKind, counter: int, body: bytes, tag: bytes) -> bytes:
        head = MAGIC + struct.pack("!BBI", TELEOP_VERSION, kind, counter)
        size = size_of(kind)
        return (head + body).ljust(size - TAG_SIZE, b"\0")[: size - TAG_SIZE] + tag

    @precondition(lambda self: self._at_boundary() and self.genuine and self.arm._bad_in_row < 6)
    @rule(which=st.integers(0, 10_000))
    def replay(self, which: int) -> None:
        raw = self.genuine[which % len(self.genuine)]
        if decode_header(raw)[1] > self.arm._rx_counter:
            return  # not yet delivered: that would be the genuine packet, early
        events = self.arm.receive_data(raw, self.now)
        assert not any(isinstance(e, (SampleArrived, StopArrived)) for e in events), events

    def _lane_attack(self, end: OperatorChannel | ArmChannel, message: bytes) -> tuple[int, int]:
        """Put ``message`` on the lane to ``end``: no event but the channel's end.
        Returns how lane_stale and the bad packets (any counter) moved."""
        before = end.statistics()
        events = end.receive_lane(message, self.now)
        assert events == [] or end.state is ChannelState.CLOSED, events
        assert not any(isinstance(e, VALUE_EVENTS) for e in events), events
        after = end.statistics()
        assert after.samples_received == before.samples_received
        assert after.replies_received == before.replies_received
        bad = sum(
            getattr(after, k) - getattr(before, k)
            for k in ("bad_packets", "tag_failures", "replays")
        )
        return after.lane_stale - before.lane_stale, bad

    @precondition(lambda self: self.lane_mode)
    @rule(
        to_arm=st.booleans(),
        how=st.sampled_from(
            ["forge", "garbage", "replay", "other channel", "reflect", "stream packet"]
        ),
        which=st.integers(0, 10_000),
        prefix=st.one_of(st.just(LANE_PREFIX), st.binary(min_size=0, max_size=6)),
        kind=st.sampled_from(TeleopKind),
        counter=st.integers(0, 2**32 - 1),
        body=st.binary(min_size=0, max_size=120),
        tag=st.binary(min_size=TAG_SIZE, max_size=TAG_SIZE),
    )
    def lane_attack(
        self,
        to_arm: bool,
        how: str,
        which: int,
        prefix: bytes,
        kind: TeleopKind,
        counter: int,
        body: bytes,
        tag: bytes,
    ) -> None:
        """The attacker on the lane.  Forged: behind this channel's prefix or
        another's (or a short one), a packet of any kind and counter with a guessed
        tag, or any bytes behind a header.  Genuine bytes where they do not belong:
        a message again (already taken, or overtaken), any message under another
        channel's prefix (one still on its way included), a message of the other
        direction, or a stream packet (HELLO, AUTH, STOP ... / CHALLENGE, GRANT)
        behind this channel's prefix."""
        lane, end = self._lane(to_arm)
        if end._bad_in_row >= 6:
            return  # the garbage limit is the channel's business, not this rule's
        open_before = end.state is ChannelState.OPEN
        if how in ("forge", "garbage"):
            if how == "forge":
                raw = self._forgery(kind, counter, body, tag)
            else:
                raw = (MAGIC + struct.pack("!BBI", TELEOP_VERSION, kind, counter) + body)[
                    : len(body)
                ]
            message = prefix + raw
            stale, bad = self._lane_attack(end, message)
            if open_before and message[: len(LANE_PREFIX)] != LANE_PREFIX:
                assert (stale, bad) == (1, 0), "another channel's message is stale, not an attack"
            else:
                assert stale + bad <= 1
            return
        opposite, _ = self._lane(not to_arm)
        values = (TeleopKind.SAMPLE, TeleopKind.REPLY)
        stream = [
            p
            for p in (self.genuine if to_arm else self.genuine_arm)
            if decode_header(p)[0] not in values
        ]
        pool = {
            "replay": lane.genuine,
            "other channel": lane.genuine,
            "reflect": opposite.genuine,
            "stream packet": [LANE_PREFIX + p for p in stream],
        }[how]
        if not pool:
            return
        message = pool[which % len(pool)]
        if how == "replay" and _counter(message) > end._rx_counter:
            return  # not yet taken: that would be the genuine message, late or early
        if how == "other channel":
            other = (prefix + bytes(len(LANE_PREFIX)))[: len(LANE_PREFIX)]
            if other == LANE_PREFIX:
                other = bytes([other[0] ^ 1]) + other[1:]
            message = other + message[len(LANE_PREFIX) :]
        stale, bad = self._lane_attack(end, message)
        if not open_before or how in ("replay", "other channel"):
            assert (stale, bad) == (1, 0), how  # dropped as stale, never punished
        else:
            assert (stale, bad) == (0, 1), how  # the wrong kind: a bad packet

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
                assert genuine
                self.stop_events += 1

    def _op_events(self, events: Sequence[TeleopEvent], *, genuine: bool) -> None:
        for ev in events:
            if isinstance(ev, ReplyReceived):
                assert genuine
                serial = int(ev.reply.force[0])
                assert (ev.reply.sample, ev.reply.status) == self.replies[serial]
                assert ev.reply.sample == 0 or ev.reply.sample in self.made
                self.replies_arrived.append(serial)
                if ev.reply.status is ReplyStatus.STOPPED and self.copies_when_confirmed is None:
                    self.copies_when_confirmed = self.op.statistics().stops_repeated

    @rule(busy=st.booleans())
    def control_tick(self, busy: bool) -> None:
        latest = self.arm.take_latest()
        if self.arm.state is not ChannelState.OPEN:
            return
        applied = latest[0] if latest is not None else None
        status = ReplyStatus.STOPPED if self.arm.stopped else ReplyStatus.FOLLOWING
        serial = len(self.replies) + 1  # in the force, to follow each reply to the operator
        self.replies[serial] = (applied.sample if applied else 0, status)
        self.arm.reply(
            Reply(
                applied.sample if applied else 0,
                status,
                ContactFlags(0),
                int(applied.mode) if applied else 0,
                0,
                applied.stamp if applied else 0.0,
                0.0,
                (float(serial), *ZERO6[1:]),
                ZERO6,
                ZERO6,
            )
        )
        self._arm_poll(busy)

    def _arm_poll(self, busy: bool) -> None:
        pending = self.arm.pending_reply
        if self.arm.poll(self.now, Backlog(56, 0.0) if busy else None):
            assert pending is not None
            number = int(pending.force[0])
            self.replies_sent.append(number)
            self._to_lane(self.arm, self.lane_to_op, number, self.replies_sent)
        else:
            assert self.arm.lane_to_send() is None
        self.to_op += self._arm_out()

    @precondition(lambda self: not self.damaged)
    @rule(lane_first=st.booleans())
    def drain(self, lane_first: bool) -> None:
        """Send what is pending and deliver everything, stream and lane, both ways
        (without loss: the simulated lane does not repeat a value, so a lost newest
        sample is never repaired, and the check is on the newest one not lost, which
        must arrive).  The lane's messages overtake the stream's or are overtaken by
        them."""
        self.poll("idle", 0.0)
        self.lane_to_arm.to_line(depth=LANE_DEPTH + 1)
        for first in (lane_first, not lane_first):
            if first:
                while self.lane_to_arm.line:
                    self._lane_deliver(True)
            else:
                self.deliver_to_arm(len(self.to_arm) or 1)
        sent = [n for n in self.sent_numbers if n not in self.lane_to_arm.lost]
        if self.arm.state is ChannelState.OPEN and self.stop_events == 0 and sent:
            assert self.arrived
            assert self.arrived[-1] == sent[-1]
        # The replies the same way: the operator's newest is the arm's newest not lost.
        if self.arm.state is ChannelState.OPEN:
            self._arm_poll(busy=False)
        self.lane_to_op.to_line(depth=LANE_DEPTH + 1)
        for first in (lane_first, not lane_first):
            if first:
                while self.lane_to_op.line:
                    self._lane_deliver(False)
            else:
                self.deliver_to_operator(len(self.to_op) or 1)
        sent = [n for n in self.replies_sent if n not in self.lane_to_op.lost]
        if self.op.state is ChannelState.OPEN and sent:
            assert self.replies_arrived
            assert self.replies_arrived[-1] == sent[-1]

    # -- invariants ------------------------------------------------------------------

    @invariant()
    def in_order_never_twice(self) -> None:
        assert self.arrived == sorted(set(self.arrived))
        assert self.replies_arrived == sorted(set(self.replies_arrived))

    @invariant()
    def every_offer_accounted_once(self) -> None:
        """Samples and replies: each sent, coalesced or pending, once; the lane's too."""
        s = self.op.statistics()
        pending = int(self.op.pending is not None)
        assert s.samples_sent + s.samples_coalesced + pending == (
            s.samples_offered - s.samples_after_stop
        )
        assert s.samples_sent == len(self.sent_numbers)
        a = self.arm.statistics()
        pending = int(self.arm.pending_reply is not None)
        assert a.replies_sent + a.replies_coalesced + pending == len(self.replies)
        assert a.replies_sent == len(self.replies_sent)
        for stats, lane in ((s, self.lane_to_arm), (a, self.lane_to_op)):
            assert (stats.lane_packets_out, stats.lane_replaced) == (lane.accepted, lane.replaced)
            if not self.lane_mode:
                assert stats.lane_packets_in == stats.lane_stale == 0

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
