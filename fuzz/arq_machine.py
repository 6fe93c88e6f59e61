"""A hypothesis state machine that fuzzes two ARQ endpoints over a hostile model wire.

The model
---------
Endpoint A connects, endpoint B listens.  Between them run two independent
one-way lines ("ab" carries A's bytes to B, "ba" the reverse).  Each line is a
FIFO of :class:`Chunk` s -- byte strings with an arrival time -- that models a
UART (``line_rate``, 10 bits per character, or instantaneous when the rate is
None) followed by a fixed propagation delay.  What an endpoint writes is cut
into one chunk per packet (at each MARK), so rules can name "the third packet
on the line".

Before connecting, A may queue bytes with ``send`` (nothing, a few bytes, text,
or more than its drawn ``early_data`` bound): its init carries the first of
them as early data (PROTOCOL.md section 13), which B delivers on accepting
when its own configuration takes early data (``early_data`` not 0, and the
XLANES field the expedited lane brings); otherwise, and for whatever did not
fit, they go as ordinary data.  When more is queued than the init carries and
A's configuration says so, those bytes go instead as a first flight of data
packets right behind the init (section 14), which B takes or skips whole.  The
line rules below drop, duplicate, delay and damage the init like any other
packet, so it is resent and arrives in copies.

Hypothesis then interleaves application calls, time, and impairments:

* the application sends (random bytes, long runs, control and prefix
  characters, as much as ``send_buffer_free`` allows), reads, and half-closes;
  it also sends and reads expedited messages (PROTOCOL.md section 11) and
  offers and reads latest values (section 12), when the ends agreed on those
  lanes;
* time advances to the next timer or arrival, or a named line delivers its
  head chunk (timers due before that arrival fire first, in order: time never
  runs backwards and no timer is skipped);
* the line drops a chunk or a slice of one, flips one bit, inserts garbage,
  duplicates a chunk, splits one into two reads, or delays one;
* a side whose port drops unsent bytes (drawn: ``Endpoint.line_discards``)
  has its line flushed whenever an expedited packet cuts in (PROTOCOL.md
  11): the chunks not yet begun vanish and the one leaving the UART is cut
  short, as a ``tcflush`` does, and the endpoint must resend what it cut.

The line never *reorders*: every impairment keeps arrival times
non-decreasing along the FIFO.  A duplicate is inserted directly after its
original, which is exactly what a retransmission looks like on the wire.  It
arrives with its original and takes no line time: a copy made beyond the slow
line (a relay repeating a packet on a fast hop).  The peer answers every copy,
so a burst of them backs its line up with ACKs that then come back to back --
bunched ACKs, which a stalled receiver makes too, and which the rate estimator
must not take for a faster line (tests/serialsocket/test_rate_duplicates.py).
Replaying a stale copy much later is deliberately outside the model: with
sequence numbers mod 64 and windows up to 31, a packet replayed after the
receiver moved on by more than 32 packets is indistinguishable from a new one
-- for this protocol and for Kermit alike -- so such a failure would be the
model's fault, not the endpoint's.  For the same reason the block check is
CRC-16 or CRC-32 (drawn per side; agreed between two dense ends), which catch
every 1-, 2- or 3-bit error in a packet (the additive 6- and 12-bit checks
can be fooled by two compensating flips).  (With corrected data packets
agreed, two flips in one block of a ``d`` packet make the repair try a third
change, and CRC-16 misses a four-bit error about once in 65 536 such
packets: PROTOCOL.md 15.4's price, far rarer than anything a run meets.)
Each side also draws its line
profile (printable or 8-bit), whether it offers the dense encodings, and
XON/XOFF: the ends then talk the Kermit prefix profile, the radix-91 packing
or the escape code (PROTOCOL.md section 10), so all of them cross the wire.

Liveness is kept out of the impairment phase by configuration: ``dead_after``
and ``connect_timeout`` are 10**6 s and retries are unlimited, so no amount of
damage lets an endpoint give up.  At the end of every example, ``teardown``
heals the line (chunks already on it stay, possibly damaged; nothing new is
impaired), half-closes each side once everything it sent is acknowledged, and
runs the simulation until both endpoints are CLOSED, reading everything.

Three endpoint bugs this machine found are fixed, and each has an ordinary
regression test in tests/serialsocket/test_arq_stateful.py: the init packet did
not fit the smallest packet lengths (``EndpointConfig`` now refuses lengths it
cannot connect with), the derived linger ended before the peer's backed-off EOF
retransmission, and a selective ACK of the EOF with earlier data lost closed the
connection with that data never resent.  Nothing is stepped around: the machine
draws the smallest accepted length and half-closes at any moment.

Properties
----------
After every step (``@invariant``):

* per direction, the bytes the receiver's application has read are a prefix of
  the bytes the sender's ``send`` accepted -- which alone rules out loss in
  the middle, duplication, reordering and corruption;
* an endpoint that reports EndOfStream has delivered everything its peer sent,
  and the peer did call ``send_eof``;
* once a side has every packet acknowledged, its peer has delivered every byte;
* early data is taken all or nothing and once: B's ``early_received`` is 0 or
  A's ``early_sent`` (never twice that, whatever copies of the init arrive),
  A drops the bytes from its queue (``early_delivered``) exactly when B took
  them, and B takes them exactly when its configuration allows;
* expedited messages are read whole, once each and in the order sent;
* latest values are read in the order offered (each carries a per-side
  counter), each at most once, possibly with gaps, and each is one the peer
  offered; once a side's lane is settled (nothing waiting, the newest value
  sent acknowledged), its peer has delivered the last value it offered;
* no endpoint is FAILED or DEAD, and none reported ConnectionAborted or LinkDead;
* no timer stays due after it was handled (a busy loop in a real event loop);
* Connected, EndOfStream and ConnectionClosed are each reported at most once.

After healing (``teardown``): both sides read exactly what the other sent
(stream and expedited lane), the last latest value each read is the last one
its peer offered (a graceful close waits for its acknowledgement), each
reported Connected, EndOfStream and ConnectionClosed exactly once, and both
reached State.CLOSED within a bounded number of events and simulated time.

No endpoint call may raise: any exception fails the example.  Time is explicit
(``self.now``); nothing reads a clock or sleeps.
"""

from __future__ import annotations

import itertools
import math
import random
from dataclasses import dataclass, field

from hypothesis import strategies as st
from hypothesis.stateful import (
    RuleBasedStateMachine,
    initialize,
    invariant,
    precondition,
    rule,
)

from serialsocket import (
    MAX_WINDOW,
    Connected,
    ConnectionAborted,
    ConnectionClosed,
    EndOfStream,
    Endpoint,
    EndpointConfig,
    Event,
    LinkDead,
    LocalProtocolError,
    State,
)
from serialsocket.argtypes import ENDPOINT_LENGTH
from serialsocket.packets import EIGHT_BIT_CLEAN, MAX_PACKET_LENGTH, PRINTABLE, BlockCheck

__all__ = [
    "DEFAULT_EARLY_DATA",
    "FINISH_MAX_EVENTS",
    "LINGER",
    "LIVENESS_TIMEOUT",
    "MAX_EARLY_DATA",
    "ARQMachine",
    "Chunk",
    "Line",
    "early_payloads",
    "payloads",
    "split_packets",
]

DEFAULT_EARLY_DATA = EndpointConfig().early_data
"""Bytes of early data an endpoint takes by default."""

MAX_EARLY_DATA = 512
"""The most ``EndpointConfig.early_data`` accepts (it refuses 513;
fuzz/test_arq_stateful.py checks that this is the bound)."""

LIVENESS_TIMEOUT = 1e6
"""``dead_after`` and ``connect_timeout`` for both endpoints (seconds): far beyond
any simulated time an example reaches, so impairments never end a connection."""

LINGER = LIVENESS_TIMEOUT / 10
"""Explicit ``linger`` for both endpoints (seconds).  The derived default is
``dead_after`` (10**6 s here), longer than ``FINISH_MAX_SECONDS``, so a side
lingering to the end would fail the finish bound; a tenth of it still outlasts
any backoff ceiling of the peer's EOF retransmission (that the derived default
does too on real lines is ``test_linger_outlasts_peer_eof_retransmission``)."""

IMPAIRMENT_HORIZON = LIVENESS_TIMEOUT / 10
"""Before healing, time never passes this instant.  Simulated idleness is free:
without a bound, a few ``advance_time`` steps jump from idle probe to idle probe
(``dead_after / 4`` apart), the line drops the answers, and the link is rightly
declared dead.  With it, no silence before healing nears ``dead_after``, and
healing plus closing (``FINISH_MAX_SECONDS``) ends before it, too."""

FINISH_MAX_EVENTS = 50_000
"""Events (timer firings plus chunk arrivals) the healed link may take to close.
The largest transfer left at healing is a full send buffer each way (64 KiB, the
largest drawn; early data only moves up to 512 of those bytes into the init).
At the smallest length (38: 31 data characters with CRC-16) in the printable
profile without the dense encodings, random bytes take 1.78 characters each:
17 bytes a packet, 3,800 data packets a side, 7,600 in all; each costs its
arrival, its ACK's arrival and, at 300 bit/s, a pacing timer: 3 events, about
23,000 (measured: 22,764; 15,300 with the rate unknown).  A stream of 8-bit
controls (3 characters a byte, 5 bytes a packet) took 39,296; more than this
bound means a livelock."""

FINISH_MAX_SECONDS = LIVENESS_TIMEOUT / 2
"""Simulated seconds the healed link may take to close.  Generous on purpose: a
window update lost before healing is only repaired by the idle probe, which
fires after ``dead_after / 4``."""

FINISH_STALL_EVENTS = 1_000
"""Events the healed link may process in a row without progress (a state change,
a byte delivered or acknowledged, a window sliding) before we call it stuck,
beyond one per chunk still on the lines.  Draining a line full of duplicates
and noise takes far fewer; a connection that retransmits into a void forever
hits this long before the time limit.  (Without the allowance per chunk, a
bulk transfer of 38-character packets held behind a chunk delayed 60 s, its
sender filling the idle line with copies meanwhile, was called stuck with
1112 chunks still to arrive: the deep profile's one failure, at b3ae3f7.)"""

SMALLEST_LENGTH = ENDPOINT_LENGTH.lo
"""The smallest ``max_packet_length`` drawn: the smallest ``EndpointConfig``
accepts, because the 38-character init packet must fit (shorter lengths are
refused with LocalProtocolError; ``test_smallest_packet_length_can_connect``)."""

TIMER_SPIN_LIMIT = 64
"""Consecutive ``handle_timer`` calls at one instant before we call it a spin:
a timer that stays due after it was handled (and output flushed) would make a
real event loop busy-wait."""

SIDES = ("a", "b")
DIRECTIONS = ("ab", "ba")

_SPECIAL = b"\x00\x01\x0d\x0a\x1b\x7f\x80\x81\x8d\xff#&~ "
"""Bytes the prefix encoding treats specially: controls, MARK, CR, DEL, 8th-bit
controls, and the default QCTL/QBIN/REPT prefix characters."""

LATEST_COUNTER = 8
"""Bytes of the big-endian counter that starts each latest value (1, 2, ... per
side): it makes every value unique and tells its place in the series."""

LATEST_TAIL_MAX = 52
"""Random bytes after the counter: values of 8..60 bytes, which fit one packet
at most drawn lengths (a value that does not is refused with ValueError)."""


def split_packets(data: bytes) -> list[bytes]:
    """Cut an endpoint's output into packets at each MARK (SOH)."""
    starts = [i for i, byte in enumerate(data) if byte == 1 and i > 0]
    bounds = [0, *starts, len(data)]
    return [data[x:y] for x, y in itertools.pairwise(bounds) if y > x]


def payloads(max_size: int = 600) -> st.SearchStrategy[bytes]:
    """Application payloads: random bytes, long runs (repeat compression), and
    mixes of the characters the encoding must quote."""
    runs = st.builds(
        lambda byte, n: bytes([byte]) * n,
        st.integers(0, 255),
        st.integers(1, max_size),
    )
    special = st.lists(st.sampled_from(list(_SPECIAL)), max_size=max_size).map(bytes)
    mixed = st.lists(st.one_of(st.binary(max_size=40), runs, special), max_size=6).map(
        lambda parts: b"".join(parts)[:max_size]
    )
    return st.one_of(st.binary(max_size=max_size), runs, special, mixed)


@dataclass(slots=True)
class Chunk:
    """Bytes on the line and the instant they finish arriving at the far end;
    ``start`` is when they began leaving the sender's UART (-inf for bytes
    an impairment made: an output flush never drops those)."""

    arrival: float
    data: bytes
    start: float = -math.inf


@dataclass(slots=True)
class Line:
    """One direction of the wire: a UART with a rate, then a fixed delay; FIFO.

    ``chunks`` is kept sorted by arrival time (never reordered); impairment
    helpers call :meth:`restore_order` after changing an arrival time.
    """

    delay: float
    rate: float | None
    bits: int = 10
    free_at: float = 0.0
    chunks: list[Chunk] = field(default_factory=list)

    def transmit(self, now: float, data: bytes) -> None:
        """Put bytes written at ``now`` on the line, behind whatever is queued."""
        start = max(now, self.free_at)
        self.free_at = start + (0.0 if self.rate is None else len(data) * self.bits / self.rate)
        arrival = self.free_at + self.delay
        if self.chunks:
            arrival = max(arrival, self.chunks[-1].arrival)
        self.chunks.append(Chunk(arrival, data, start))

    def discard(self, now: float) -> None:
        """The sender's port dropped what it had not sent at ``now`` (an
        output flush, PROTOCOL.md 11): chunks not yet begun go, the one
        leaving the UART is cut after the character in the shift register
        (the far end sees a truncated packet)."""
        if self.rate is None or self.free_at <= now:
            return
        char = self.bits / self.rate
        kept: list[Chunk] = []
        free_at = now
        for chunk in self.chunks:
            if chunk.start == -math.inf or chunk.start + len(chunk.data) * char <= now:
                kept.append(chunk)  # already left (or made by an impairment)
            elif chunk.start <= now:
                sent = min(len(chunk.data), math.floor((now - chunk.start) / char) + 1)
                cut = chunk.start + sent * char
                kept.append(
                    Chunk(
                        chunk.arrival - (len(chunk.data) - sent) * char,
                        chunk.data[:sent],
                        chunk.start,
                    )
                )
                free_at = max(free_at, cut)
        self.chunks = kept
        self.restore_order(0)
        self.free_at = free_at

    def restore_order(self, start: int) -> None:
        """Push later arrivals back so none overtakes chunk ``start``."""
        for i in range(max(start, 1), len(self.chunks)):
            prev = self.chunks[i - 1].arrival
            if self.chunks[i].arrival < prev:
                self.chunks[i].arrival = prev

    def head_arrival(self) -> float | None:
        return self.chunks[0].arrival if self.chunks else None


_LENGTHS = st.one_of(
    st.sampled_from([SMALLEST_LENGTH, 40, 94, 95, 96, 128, 1000, MAX_PACKET_LENGTH]),
    st.integers(SMALLEST_LENGTH, 600),
)
_DELAYS = st.sampled_from([0.0, 0.001, 0.02, 0.25, 1.3])
_RATES = st.sampled_from([None, None, 300.0, 2400.0, 9600.0, 115200.0])
_ENCODINGS = st.sampled_from([PRINTABLE, EIGHT_BIT_CLEAN])
_CHECKS = st.sampled_from([BlockCheck.CRC16, BlockCheck.CRC16, BlockCheck.CRC32])
"""CRC-32 in a third of the draws: asked for by one side, it is agreed
between two dense ends (PROTOCOL.md section 10.2)."""
_LONG_WINDOWS = st.sampled_from([None, 32, 100, 4095, 131071])
_EARLY_DATA = st.one_of(
    st.sampled_from([0, 1, 16, DEFAULT_EARLY_DATA, MAX_EARLY_DATA]),
    st.integers(0, MAX_EARLY_DATA),
)
"""``EndpointConfig.early_data``: none (a listener that takes none, a connector
that sends none), a byte, the default, the most, or anything between."""


def early_payloads() -> st.SearchStrategy[bytes]:
    """What the connector queues before connecting (PROTOCOL.md section 13): often
    nothing, a short command, text, the payloads above, or a random block longer
    than any early-data bound (up to three times ``MAX_EARLY_DATA``), whose tail
    goes as ordinary data."""
    text = st.text(max_size=80).map(lambda s: s.encode())
    block = st.builds(
        lambda seed, n: random.Random(seed).randbytes(n),
        st.integers(0, 2**32 - 1),
        st.integers(1, 3 * MAX_EARLY_DATA),
    )
    return st.one_of(st.just(b""), st.binary(min_size=1, max_size=16), text, payloads(700), block)


@st.composite
def endpoint_configs(
    draw: st.DrawFn, *, one_way_delay: float, line_rate: float | None
) -> EndpointConfig:
    """One side's configuration; the physical line (delay, rate) is shared."""
    return EndpointConfig(
        # Window 31 (half the draws) offers long sequence numbers (PROTOCOL.md
        # section 9) with the drawn long window; both sides offering uses them.
        window=draw(st.one_of(st.just(MAX_WINDOW), st.integers(1, MAX_WINDOW))),
        long_window=draw(_LONG_WINDOWS),
        max_packet_length=draw(_LENGTHS),
        encoding=draw(_ENCODINGS),
        # The dense encodings (escape code or radix 91, by the line) are used
        # when both sides offer them: three draws in four each.
        dense=draw(st.sampled_from([True, True, True, False])),
        # The expedited lane (PROTOCOL.md section 11): used when both offer it.
        expedited=draw(st.sampled_from([True, True, True, False])),
        # The latest-value lane (section 12): used when both offer it and the
        # expedited lane (it rides on the same XLANES offer).
        latest=draw(st.sampled_from([True, True, True, False])),
        check=draw(_CHECKS),
        # Early data (section 13): sent by a connector with the XLANES field
        # (expedited) and early_data not 0, taken by a listener likewise; any
        # other pair sends the bytes as ordinary data.
        early_data=draw(_EARLY_DATA),
        # The first flight (section 14): sent by a connector with more queued
        # than its init carries, taken by a listener that can read it.
        first_flight=draw(st.sampled_from([True, True, False])),
        takes_first_flight=draw(st.sampled_from([True, True, True, False])),
        # Corrected data packets (section 15): agreed when both offer them
        # (with the expedited lane's XLANES and a CRC); a sender adds sums
        # once the losses it has seen make them pay.
        correction=draw(st.sampled_from([True, True, False])),
        xon_xoff=draw(st.booleans()),
        one_way_delay=one_way_delay,
        line_rate=line_rate,
        send_buffer=draw(st.one_of(st.integers(1, 64), st.integers(1, 8192), st.just(64 * 1024))),
        receive_buffer=draw(st.integers(2 * MAX_PACKET_LENGTH, 3 * MAX_PACKET_LENGTH)),
        dead_after=LIVENESS_TIMEOUT,
        connect_timeout=LIVENESS_TIMEOUT,
        linger=LINGER,
    )


_side = st.sampled_from(SIDES)
_direction = st.sampled_from(DIRECTIONS)
_index = st.integers(0, 1 << 16)
"""Chunk positions are drawn wide and reduced modulo the queue length."""


class ARQMachine(RuleBasedStateMachine):
    """Two endpoints, a model wire, and the invariants described in the module doc."""

    def __init__(self) -> None:
        super().__init__()
        self.now = 0.0
        self.ep: dict[str, Endpoint] = {}
        self.lines: dict[str, Line] = {}
        self.sent: dict[str, bytearray] = {s: bytearray() for s in SIDES}
        self.received: dict[str, bytearray] = {s: bytearray() for s in SIDES}
        self.xsent: dict[str, list[bytes]] = {s: [] for s in SIDES}
        """Expedited messages each side's send_expedited took, in order."""
        self.xreceived: dict[str, list[bytes]] = {s: [] for s in SIDES}
        self.lsent: dict[str, list[bytes]] = {s: [] for s in SIDES}
        """Latest values each side's send_latest took, in order: value ``n``
        (from 1) starts with ``n`` as an 8-byte big-endian counter."""
        self.lreceived: dict[str, list[bytes]] = {s: [] for s in SIDES}
        """Latest values each side's read_latest returned, in order."""
        self.events: dict[str, list[Event]] = {s: [] for s in SIDES}
        self.healed = False
        self._eof_called = dict.fromkeys(SIDES, False)
        self.early_queued = 0
        """Bytes A's ``send`` took before ``connect``: the most its init may carry."""

    # -- plumbing ---------------------------------------------------------------------

    @staticmethod
    def _peer(side: str) -> str:
        return "b" if side == "a" else "a"

    @staticmethod
    def _out_line(side: str) -> str:
        return "ab" if side == "a" else "ba"

    def _flush(self) -> None:
        """Move what each endpoint wants to write onto its line, one chunk per packet,
        and collect its events."""
        for side in SIDES:
            ep = self.ep[side]
            data = ep.data_to_send(self.now)
            if ep.take_discard():
                self.lines[self._out_line(side)].discard(self.now)
            for packet in split_packets(data):
                self.lines[self._out_line(side)].transmit(self.now, packet)
            self.events[side].extend(ep.events())

    def _timers(self, side: str) -> list[float]:
        """The protocol timer and the pacing (send) timer of one endpoint."""
        ep = self.ep[side]
        return [t for t in (ep.get_timer(), ep.get_send_timer()) if t is not None]

    def _next_timer(self) -> float | None:
        timers = [t for s in SIDES for t in self._timers(s)]
        return min(timers) if timers else None

    def _fire_timers_until(self, until: float) -> None:
        """Fire every timer due at or before ``until``, in time order."""
        spins = 0
        while (timer := self._next_timer()) is not None and timer <= until:
            if timer <= self.now:
                spins += 1
                assert spins <= TIMER_SPIN_LIMIT, (
                    f"timer spin at t={self.now}: "
                    f"{[(s, self.ep[s].state, self._timers(s)) for s in SIDES]}"
                )
            else:
                spins = 0
                self.now = timer
            for side in SIDES:
                due = self.ep[side].get_timer()
                if due is not None and due <= self.now:
                    self.ep[side].handle_timer(self.now)
            self._flush()  # Also what a due send timer asks for.

    def _deliver_head(self, direction: str) -> None:
        """Let time run to the head chunk's arrival and hand it to the receiver."""
        line = self.lines[direction]
        self._fire_timers_until(line.chunks[0].arrival)
        chunk = line.chunks.pop(0)
        self.now = max(self.now, chunk.arrival)
        receiver = self.ep["b" if direction == "ab" else "a"]
        receiver.receive_data(chunk.data, self.now)
        self._flush()

    def _next_event_time(self) -> float | None:
        times = [t for t in (self.lines[d].head_arrival() for d in DIRECTIONS) if t is not None]
        timer = self._next_timer()
        if timer is not None:
            times.append(timer)
        return min(times) if times else None

    def _advance(self) -> bool:
        """Process the single earliest event; False when nothing is pending."""
        t = self._next_event_time()
        if t is None:
            return False
        for direction in DIRECTIONS:
            if self.lines[direction].head_arrival() == t:
                self._deliver_head(direction)
                return True
        self._fire_timers_until(max(t, self.now))
        return True

    def _read_all(self) -> None:
        for side in SIDES:
            self.received[side] += self.ep[side].read(None, self.now)
            while (message := self.ep[side].read_expedited()) is not None:
                self.xreceived[side].append(message)
            self._read_latest(side)
        self._flush()

    def _read_latest(self, side: str) -> None:
        readable = self.ep[side].latest_readable
        value = self.ep[side].read_latest()
        assert (value is not None) == readable, (side, readable, value)
        if value is not None:
            self.lreceived[side].append(value)
        assert not self.ep[side].latest_readable, side
        assert self.ep[side].read_latest() is None, side

    def _can_send(self, side: str) -> bool:
        ep = self.ep[side]
        return (
            ep.state not in (State.LINGER, State.CLOSED, State.FAILED, State.DEAD)
            and not self._eof_called[side]
        )

    # -- set-up -----------------------------------------------------------------------

    @initialize(
        data=st.data(),
        one_way_delay=_DELAYS,
        line_rate=_RATES,
        early=early_payloads(),
    )
    def setup(
        self, data: st.DataObject, one_way_delay: float, line_rate: float | None, early: bytes
    ) -> None:
        configs = {
            side: data.draw(
                endpoint_configs(one_way_delay=one_way_delay, line_rate=line_rate),
                label=f"config_{side}",
            )
            for side in SIDES
        }
        discards = {side: data.draw(st.booleans(), label=f"discards_{side}") for side in SIDES}
        self.start(
            configs,
            one_way_delay=one_way_delay,
            line_rate=line_rate,
            early=early,
            discards=discards,
        )

    def start(
        self,
        configs: dict[str, EndpointConfig],
        *,
        one_way_delay: float,
        line_rate: float | None,
        early: bytes = b"",
        discards: dict[str, bool] | None = None,
    ) -> None:
        """B listens; A queues ``early`` (what its send buffer takes) and connects.
        ``discards``: which sides' ports drop unsent bytes when an expedited
        packet cuts in (``Endpoint.line_discards``; the line obliges)."""
        self.ep = {side: Endpoint(configs[side]) for side in SIDES}
        for side, on in (discards or {}).items():
            self.ep[side].line_discards = on
        self.lines = {d: Line(delay=one_way_delay, rate=line_rate) for d in DIRECTIONS}
        self.ep["b"].listen()
        a = self.ep["a"]
        free = a.send_buffer_free
        taken = a.send(early, self.now)
        assert taken == min(len(early), free), (taken, len(early), free)
        self.sent["a"] += early[:taken]
        self.early_queued = taken
        a.connect(self.now)
        self._flush()

    # -- choosing among what is possible ----------------------------------------------

    def _senders(self) -> list[str]:
        return [s for s in SIDES if self._can_send(s)]

    def _closers(self) -> list[str]:
        # Any moment, data outstanding or not: an EOF selectively acknowledged
        # before lost data must not close the connection.
        return self._senders()

    def _busy_lines(self) -> list[str]:
        return [d for d in DIRECTIONS if self.lines[d].chunks]

    def _pick_line(self, data: st.DataObject) -> list[Chunk]:
        direction = data.draw(st.sampled_from(self._busy_lines()), label="direction")
        return self.lines[direction].chunks

    # -- application ------------------------------------------------------------------

    @precondition(lambda self: bool(self._senders()))
    @rule(data=st.data(), payload=payloads())
    def app_send(self, data: st.DataObject, payload: bytes) -> None:
        side = data.draw(st.sampled_from(self._senders()), label="side")
        ep = self.ep[side]
        free = ep.send_buffer_free
        taken = ep.send(payload, self.now)
        assert taken == min(len(payload), free), (taken, len(payload), free)
        self.sent[side] += payload[:taken]
        self._flush()

    @precondition(lambda self: bool(self._senders()))
    @rule(
        data=st.data(),
        seed=st.integers(0, 2**32 - 1),
        size=st.integers(1, 3 * MAX_PACKET_LENGTH),
        compressible=st.booleans(),
    )
    def app_send_bulk(self, data: st.DataObject, seed: int, size: int, compressible: bool) -> None:
        """Offer a large block (up to the receive buffer's size): fills send buffers
        and, when the reader lags, closes the peer's advertised window."""
        side = data.draw(st.sampled_from(self._senders()), label="side")
        rng = random.Random(seed)
        if compressible:
            block = b"".join(bytes([rng.randrange(256)]) * rng.randrange(1, 500) for _ in range(64))
            block = (block * (size // max(len(block), 1) + 1))[:size]
        else:
            block = rng.randbytes(size)
        ep = self.ep[side]
        free = ep.send_buffer_free
        taken = ep.send(block, self.now)
        assert taken == min(size, free), (taken, size, free)
        self.sent[side] += block[:taken]
        self._flush()

    @rule(side=_side, n=st.one_of(st.none(), st.integers(0, 2000)))
    def app_read(self, side: str, n: int | None) -> None:
        before = self.ep[side].readable
        got = self.ep[side].read(n, self.now)
        assert len(got) == (before if n is None else min(n, before))
        self.received[side] += got
        self._flush()

    def _lane_senders(self) -> list[str]:
        return [s for s in SIDES if self.ep[s].state is State.ESTABLISHED and self.ep[s].expedited]

    @precondition(lambda self: bool(self._lane_senders()))
    @rule(data=st.data(), message=st.binary(min_size=1, max_size=300))
    def app_send_expedited(self, data: st.DataObject, message: bytes) -> None:
        """An urgent message on the lane: overtakes the stream, arrives once."""
        side = data.draw(st.sampled_from(self._lane_senders()), label="side")
        refused: Exception | None = None
        try:
            self.ep[side].send_expedited(message, self.now)
        except (LocalProtocolError, ValueError) as exc:
            refused = exc
        if refused is not None:
            # Only a full lane, or a message too long for short packets, is refused.
            why = str(refused)
            assert "wait" in why or "packets" in why, why
            return
        self.xsent[side].append(message)
        self._flush()

    @rule(side=_side)
    def app_read_expedited(self, side: str) -> None:
        while (message := self.ep[side].read_expedited()) is not None:
            self.xreceived[side].append(message)
        self._flush()

    def _latest_senders(self) -> list[str]:
        return [
            s
            for s in SIDES
            if self.ep[s].state is State.ESTABLISHED
            and self.ep[s].latest
            and not self.ep[s].closing
        ]

    @precondition(lambda self: bool(self._latest_senders()))
    @rule(
        data=st.data(),
        tails=st.lists(st.binary(max_size=LATEST_TAIL_MAX), min_size=1, max_size=3),
    )
    def app_send_latest(self, data: st.DataObject, tails: list[bytes]) -> None:
        """Offer one to three latest values in a row (the later ones replace an
        earlier one still waiting for the line).  Each is unique and ordered:
        an 8-byte big-endian counter per side, then random bytes."""
        side = data.draw(st.sampled_from(self._latest_senders()), label="side")
        ep = self.ep[side]
        for tail in tails:
            value = (len(self.lsent[side]) + 1).to_bytes(LATEST_COUNTER, "big") + tail
            waiting = ep.latest_waiting
            coalesced = ep.statistics().latest_coalesced
            refused: Exception | None = None
            try:
                ep.send_latest(value, self.now)
            except (LocalProtocolError, ValueError) as exc:
                refused = exc
            if refused is not None:
                # Only a value too long for one packet at short lengths is refused.
                why = str(refused)
                assert isinstance(refused, ValueError), why
                assert "fit one packet" in why, why
                continue
            self.lsent[side].append(value)
            stats = ep.statistics()
            assert ep.latest_waiting, side
            assert stats.latest_offered == len(self.lsent[side]), (stats, len(self.lsent[side]))
            # An offer replacing a value still waiting for the line is counted.
            assert stats.latest_coalesced == coalesced + waiting, (stats, coalesced, waiting)
        self._flush()

    @rule(side=_side)
    def app_read_latest(self, side: str) -> None:
        self._read_latest(side)
        self._flush()

    @precondition(lambda self: bool(self._closers()))
    @rule(data=st.data())
    def half_close(self, data: st.DataObject) -> None:
        side = data.draw(st.sampled_from(self._closers()), label="side")
        self.ep[side].send_eof(self.now)
        self._eof_called[side] = True
        self._flush()

    # -- time ---------------------------------------------------------------------------

    def _soon(self, t: float | None) -> bool:
        return t is not None and t <= IMPAIRMENT_HORIZON

    def _deliverable(self) -> list[str]:
        return [d for d in DIRECTIONS if self._soon(self.lines[d].head_arrival())]

    @precondition(lambda self: self._soon(self._next_event_time()))
    @rule()
    def advance_time(self) -> None:
        """Process the earliest pending event (a timer or an arrival)."""
        self._advance()

    @precondition(lambda self: bool(self._deliverable()))
    @rule(data=st.data())
    def deliver_next(self, data: st.DataObject) -> None:
        """Deliver the head of a chosen line now, even if the other line's head is due
        earlier (that one is simply later than it could have been)."""
        direction = data.draw(st.sampled_from(self._deliverable()), label="direction")
        self._deliver_head(direction)

    # -- impairments (only before the line heals) -----------------------------------

    @precondition(lambda self: not self.healed and bool(self._busy_lines()))
    @rule(data=st.data(), index=_index)
    def drop(self, data: st.DataObject, index: int) -> None:
        """Lose one chunk (a packet, or a piece of one after a split)."""
        chunks = self._pick_line(data)
        del chunks[index % len(chunks)]

    @precondition(lambda self: not self.healed and bool(self._busy_lines()))
    @rule(data=st.data(), index=_index, start=_index, length=st.integers(1, 40))
    def drop_bytes(self, data: st.DataObject, index: int, start: int, length: int) -> None:
        """Lose a run of bytes inside one chunk (a UART overrun)."""
        chunks = self._pick_line(data)
        pos = index % len(chunks)
        chunk = chunks[pos]
        cut = start % len(chunk.data)
        chunk.data = chunk.data[:cut] + chunk.data[cut + length :]
        if not chunk.data:
            del chunks[pos]

    @precondition(lambda self: not self.healed and bool(self._busy_lines()))
    @rule(data=st.data(), index=_index, bit=st.integers(0, 1 << 20))
    def corrupt(self, data: st.DataObject, index: int, bit: int) -> None:
        """Flip one bit of one chunk."""
        chunks = self._pick_line(data)
        chunk = chunks[index % len(chunks)]
        if chunk.data:
            bit %= 8 * len(chunk.data)
            damaged = bytearray(chunk.data)
            damaged[bit // 8] ^= 1 << (bit % 8)
            chunk.data = bytes(damaged)

    @precondition(lambda self: not self.healed)
    @rule(
        direction=_direction,
        index=_index,
        garbage=st.one_of(
            st.binary(min_size=1, max_size=64),
            st.lists(st.sampled_from(list(_SPECIAL)), min_size=1, max_size=16).map(bytes),
        ),
    )
    def insert_garbage(self, direction: str, index: int, garbage: bytes) -> None:
        """Line noise between (or, after a split, inside) packets."""
        line = self.lines[direction]
        chunks = line.chunks
        pos = index % (len(chunks) + 1)
        if pos < len(chunks):
            arrival = chunks[pos].arrival
        elif chunks:
            arrival = chunks[-1].arrival
        else:
            arrival = self.now + line.delay
        chunks.insert(pos, Chunk(arrival, garbage))

    @precondition(lambda self: not self.healed and bool(self._busy_lines()))
    @rule(data=st.data(), index=_index)
    def duplicate(self, data: st.DataObject, index: int) -> None:
        """Deliver a chunk twice in a row (never later: see the module doc)."""
        chunks = self._pick_line(data)
        pos = index % len(chunks)
        chunks.insert(pos + 1, Chunk(chunks[pos].arrival, chunks[pos].data))

    @precondition(lambda self: not self.healed and bool(self._busy_lines()))
    @rule(
        data=st.data(), index=_index, cut=_index, lag=st.sampled_from([0.0, 0.001, 0.1, 1.0, 5.0])
    )
    def split(self, data: st.DataObject, index: int, cut: int, lag: float) -> None:
        """Cut a chunk in two reads, the second ``lag`` seconds after the first."""
        direction = data.draw(st.sampled_from(self._busy_lines()), label="direction")
        line = self.lines[direction]
        pos = index % len(line.chunks)
        chunk = line.chunks[pos]
        if len(chunk.data) >= 2:
            at = 1 + cut % (len(chunk.data) - 1)
            line.chunks[pos : pos + 1] = [
                Chunk(chunk.arrival, chunk.data[:at]),
                Chunk(chunk.arrival + lag, chunk.data[at:]),
            ]
            line.restore_order(pos + 1)

    @precondition(lambda self: not self.healed and bool(self._busy_lines()))
    @rule(
        data=st.data(),
        index=_index,
        seconds=st.sampled_from([0.001, 0.05, 0.5, 2.0, 10.0, 60.0]),
    )
    def delay(self, data: st.DataObject, index: int, seconds: float) -> None:
        """Hold one chunk back (and, since the line never reorders, all behind it)."""
        direction = data.draw(st.sampled_from(self._busy_lines()), label="direction")
        line = self.lines[direction]
        pos = index % len(line.chunks)
        line.chunks[pos].arrival += seconds
        line.restore_order(pos)

    # -- invariants --------------------------------------------------------------------

    @invariant()
    def delivered_is_prefix_of_sent(self) -> None:
        for side in SIDES:
            got, sent = self.received[side], self.sent[self._peer(side)]
            assert got == sent[: len(got)], (
                f"{side} read bytes the peer never sent at offset "
                f"{_first_difference(got, sent)} (read {len(got)}, peer sent {len(sent)})"
            )

    @invariant()
    def expedited_messages_arrive_once_and_in_order(self) -> None:
        for side in SIDES:
            got, sent = self.xreceived[side], self.xsent[self._peer(side)]
            assert got == sent[: len(got)], (
                f"{side} read expedited messages the peer did not send in that order: "
                f"{len(got)} read, {len(sent)} sent"
            )

    @invariant()
    def latest_values_arrive_in_order_at_most_once(self) -> None:
        for side in SIDES:
            offered = self.lsent[self._peer(side)]
            last = 0
            for value in self.lreceived[side]:
                n = int.from_bytes(value[:LATEST_COUNTER], "big")
                assert n > last, f"{side} read latest value {n} after {last}"
                assert n <= len(offered), f"{side} read latest value {n} of {len(offered)}"
                assert offered[n - 1] == value, (
                    f"{side} read a latest value its peer never offered: number {n}, {value!r}"
                )
                last = n

    @invariant()
    def settled_latest_value_was_delivered(self) -> None:
        for side in SIDES:
            offered = self.lsent[side]
            if offered and self.ep[side].latest_settled:
                # The newest value sent is acknowledged and nothing newer waits: the
                # peer delivered the last value offered -- unread in its inbox (then
                # nothing newer can replace it before it is read: the invariant
                # above checks whatever is read) or the last one it read.
                peer = self._peer(side)
                got = self.lreceived[peer]
                assert self.ep[peer].latest_readable or (got and got[-1] == offered[-1]), (
                    f"{side}'s latest lane is settled but {peer} last read "
                    f"{got[-1] if got else None!r}, not {offered[-1]!r}"
                )

    @invariant()
    def end_of_stream_means_everything_arrived(self) -> None:
        for side in SIDES:
            if any(isinstance(e, EndOfStream) for e in self.events[side]):
                peer = self._peer(side)
                assert self._eof_called[peer], f"{side} saw EOF that {peer} never sent"
                stats = self.ep[side].statistics()
                assert stats.bytes_delivered == len(self.sent[peer]), (
                    f"{side} saw EOF after {stats.bytes_delivered} of {len(self.sent[peer])} bytes"
                )
            if self.ep[side].at_eof:
                assert self.received[side] == self.sent[self._peer(side)]

    @invariant()
    def early_data_is_delivered_once(self) -> None:
        """The early-data counters agree with each other and with PROTOCOL.md 13.

        Which bytes arrive, in order and once, is ``delivered_is_prefix_of_sent``'s
        and the finish's business (the early bytes are the head of ``sent["a"]``);
        this pins the path they took: a resent or duplicated init never delivers
        them again, and the connector drops them from its queue exactly when the
        listener took them."""
        a, b = self.ep["a"], self.ep["b"]
        sa, sb = a.statistics(), b.statistics()
        # Only a connector sends early data; only a listener takes it.
        assert sb.early_sent == sb.early_delivered == sa.early_received == 0, (sa, sb)
        bound = min(self.early_queued, a.config.early_data)
        assert sa.early_sent <= bound, (sa.early_sent, bound)
        if (
            a.state is not State.IDLE
            and bound
            and a.config.init_lanes() is not None
            and not sa.flight_announced
        ):
            # A connector with XLANES and queued bytes puts some in its init
            # (unless they go as a first flight behind it: section 14).
            assert sa.early_sent > 0, (sa, bound)
        if sa.flight_announced or a.config.init_lanes() is None:
            assert sa.early_sent == 0, sa
        # All or nothing, once: a second delivery would double early_received.
        assert sa.early_delivered in (0, sa.early_sent), sa
        assert sb.early_received in (0, sa.early_sent), (sa.early_sent, sb.early_received)
        assert sb.early_received <= sb.bytes_delivered, sb
        if sa.early_delivered:
            # The answer's bit 2 never claims a delivery that did not happen.
            assert sb.early_received == sa.early_sent, (sa, sb)
        takes = b.config.expedited and b.config.early_data > 0
        if not takes:
            assert sb.early_received == 0, sb
        elif b.state not in (State.IDLE, State.LISTEN):
            # B accepted an init; every copy carries the same early bytes.
            assert sb.early_received == sa.early_sent, (sa, sb)
        if a.state not in (State.IDLE, State.CONNECTING):
            # A read the answer: it says delivered exactly when B delivered.
            assert sa.early_delivered == sb.early_received, (sa, sb)

    @invariant()
    def first_flight_is_all_or_nothing(self) -> None:
        """A first flight (PROTOCOL.md 14) is taken whole or not at all, within
        its announcement; which bytes arrive, once and in order, is the
        other invariants' business."""
        a, b = self.ep["a"], self.ep["b"]
        sa, sb = a.statistics(), b.statistics()
        assert sb.flight_announced == sb.flight_packets == 0, sb  # only a connector flies
        assert sa.flight_packets <= sa.flight_announced, sa
        assert sa.flight_refused in (0, sa.flight_packets), sa
        if sa.flight_announced and not (a.config.first_flight and a.config.init_lanes()):
            raise AssertionError(f"a flight announced against the configuration: {sa}")
        if sa.flight_refused and a.state is not State.CONNECTING:
            # Not taken: its numbers were skipped, on both sides alike.
            assert sa.send_next > sa.flight_announced, sa

    @invariant()
    def sums_only_when_agreed(self) -> None:
        """Only a side that agreed on corrected data packets (PROTOCOL.md 15)
        sends ``d`` or repair packets, and only a side that agreed repairs
        any or answers a repair packet."""
        for side in SIDES:
            st_ = self.ep[side].statistics()
            if not st_.correction:
                assert st_.corrected_sent == 0, (side, st_)
                assert st_.repaired == 0, (side, st_)
                assert st_.repairs_sent == st_.repairs_failed == 0, (side, st_)
            assert st_.repaired <= st_.packets_received, (side, st_)

    @invariant()
    def connection_stays_alive(self) -> None:
        for side in SIDES:
            assert self.ep[side].state not in (State.FAILED, State.DEAD), (
                side,
                self.ep[side].state,
                self.events[side],
            )
            bad = [e for e in self.events[side] if isinstance(e, ConnectionAborted | LinkDead)]
            assert not bad, (side, bad)
            for kind in (Connected, EndOfStream, ConnectionClosed):
                assert sum(isinstance(e, kind) for e in self.events[side]) <= 1, (
                    side,
                    self.events[side],
                )

    @invariant()
    def accounting_is_consistent(self) -> None:
        for side in SIDES:
            stats = self.ep[side].statistics()
            assert stats.bytes_delivered == len(self.received[side]) + self.ep[side].readable
            assert stats.bytes_acknowledged <= len(self.sent[side])
            ep = self.ep[side]
            # Every value offered was replaced while waiting, handed to the line,
            # or still waits; every value delivered was read, replaced unread, or
            # waits to be read.
            assert stats.latest_offered == len(self.lsent[side])
            assert stats.latest_offered == (
                stats.latest_coalesced + stats.latest_sent + ep.latest_waiting
            ), stats
            assert stats.latest_received == (
                len(self.lreceived[side]) + stats.latest_superseded + ep.latest_readable
            ), stats
            if self.ep[side].all_acknowledged and self.ep[side].state is not State.IDLE:
                # Acknowledgements never lie: once every packet is acknowledged, the
                # peer holds all of them, hence has delivered every byte in order.
                # (A selective ACK alone proves less: the packet may wait, buffered,
                # behind a gap, so bytes_acknowledged may exceed bytes_delivered.)
                peer = self.ep[self._peer(side)].statistics()
                assert peer.bytes_delivered == len(self.sent[side]), (
                    side,
                    peer.bytes_delivered,
                    len(self.sent[side]),
                )

    # -- the end: heal, close, check everything arrived ------------------------------

    def teardown(self) -> None:
        if not self.ep:
            return  # set-up itself failed: that error is the report.
        self.finish()

    def finish(self) -> None:
        """Heal the line, half-close both sides, and run until both are CLOSED."""
        self.healed = True
        start = self.now
        last_progress, idle = self._progress(), 0
        for _ in range(FINISH_MAX_EVENTS):
            for side in self._closers():
                self.ep[side].send_eof(self.now)
                self._eof_called[side] = True
            self._read_all()
            self.check_all()
            if all(self.ep[s].state is State.CLOSED for s in SIDES):
                break
            assert self._advance(), f"nothing pending but not closed: {self._describe()}"
            assert self.now - start <= FINISH_MAX_SECONDS, f"too slow: {self._describe()}"
            progress = self._progress()
            idle = 0 if progress != last_progress else idle + 1
            last_progress = progress
            # Chunks still on the lines each take an event to arrive, and a
            # line held back by a long delay fills with idle copies meanwhile
            # (bounded: two per packet in flight): neither is a stall.
            on_lines = sum(len(self.lines[d].chunks) for d in DIRECTIONS)
            assert idle < FINISH_STALL_EVENTS + on_lines, f"stuck after healing: {self._describe()}"
        else:
            raise AssertionError(f"no clean close after healing: {self._describe()}")
        for side in SIDES:
            peer = self._peer(side)
            assert self.received[side] == self.sent[peer]
            assert self.xreceived[side] == self.xsent[peer]
            # Every latest value was offered while ESTABLISHED and not closing, and
            # a graceful close waits for the newest one's acknowledgement.
            assert self.ep[peer].latest_settled, peer
            offered = self.lsent[peer]
            if offered:
                got = self.lreceived[side]
                assert got, f"{side} read none of {len(offered)} latest values"
                assert got[-1] == offered[-1], (
                    f"{side} last read latest value {got[-1]!r}, "
                    f"not {offered[-1]!r} ({len(got)} of {len(offered)} read)"
                )
            assert self.ep[side].at_eof
            assert self.ep[side].all_acknowledged
            kinds = [type(e) for e in self.events[side]]
            assert kinds == [Connected, EndOfStream, ConnectionClosed], (side, kinds)

    def _progress(self) -> tuple[object, ...]:
        """What changes whenever the connection moves forward."""
        out: list[object] = []
        for side in SIDES:
            stats = self.ep[side].statistics()
            out += [
                stats.state,
                stats.send_base,
                stats.receive_expected,
                stats.bytes_delivered,
                stats.bytes_acknowledged,
                len(self.events[side]),
            ]
        return tuple(out)

    def check_all(self) -> None:
        """Every invariant, for use outside hypothesis's own invariant checks."""
        self.delivered_is_prefix_of_sent()
        self.expedited_messages_arrive_once_and_in_order()
        self.latest_values_arrive_in_order_at_most_once()
        self.settled_latest_value_was_delivered()
        self.end_of_stream_means_everything_arrived()
        self.early_data_is_delivered_once()
        self.connection_stays_alive()
        self.accounting_is_consistent()

    def _describe(self) -> str:
        parts = [f"t={self.now:.3f}"]
        for side in SIDES:
            ep = self.ep[side]
            parts.append(
                f"{side}: {ep.state.value} timers={self._timers(side)} "
                f"sent={len(self.sent[side])} read={len(self.received[side])} "
                f"latest offered={len(self.lsent[side])} read={len(self.lreceived[side])} "
                f"events={[type(e).__name__ for e in self.events[side]]} {ep.statistics()}"
            )
        for d in DIRECTIONS:
            parts.append(f"line {d}: {len(self.lines[d].chunks)} chunks")
        return "\n".join(parts)


def _first_difference(a: bytes | bytearray, b: bytes | bytearray) -> int:
    for i, (x, y) in enumerate(zip(a, b, strict=False)):
        if x != y:
            return i
    return min(len(a), len(b))
