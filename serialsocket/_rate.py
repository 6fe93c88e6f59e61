"""The line's rate and the queue in front of it, measured from the ACK clock (sans-I/O).

A serial path is a fixed-rate line behind first-in-first-out queues the
endpoint cannot see: the UART's FIFO, the tty buffer, a pty relay holding
tens of KB.  Hints (``line_rate``) say how fast the line drains them; they
may be missing or wrong by ten times.  This module measures what the hints
only guess, as TCP BBR does, and the endpoint paces, sizes its window and
times its repairs from the measurement:

Delivery rate
    Every byte we hand to the line -- data, ACKs, NAKs -- passes the same
    queue.  When the first copy of packet P is acknowledged, every byte
    handed up to P's end has left the line; so has every byte handed up to
    the packet acknowledged last before P was sent (the *delivery point*
    P's mark remembers).  The bytes between the two left in the time
    between the two ACKs: the path's delay is in both and cancels.  If the
    line idled in between, the sample is below its rate, never above it
    (apart from jitter, which an interval of about a round trip averages
    out), so the estimate is the largest recent sample.  Unless the first
    ACK waited at the far end -- behind the peer's other ACKs, or in a
    receiver that stalled and then read a burst: the ACKs then come back to
    back, spaced by the peer's line, and their interval is short by the
    wait.  The bytes were handed to our line over the time between the two
    packets' handing, too, and a sample may show the line only a little
    faster than that (:data:`SEND_SLACK`).

Queue lag
    A packet's round trip is measured from when the pacer's model says it
    left the UART.  When the model drains faster than the line (no rate
    known, or a rate hint too high) the packet really left later, and its
    round trip exceeds the path's base round trip by the time it waited:
    the queue the model did not know about.  When the model drains slower
    than the line (a rate hint too low) the packet left *earlier* than
    modelled and its round trip comes out shorter than the path allows:
    proof that the line is faster than assumed.

How the estimate moves (:meth:`RateEstimator.on_delivery`):

* no rate known: the first run of queued deliveries sets it (an unpaced
  sender that never builds a queue needs no rate: nothing waits anywhere);
* up, whenever a sample shows more than the estimate (the line delivered
  it, so it can), and doubled, at most once a round trip, while packets
  arrive sooner than the path's base round trip allows (the model is too
  slow and the pacer holds back what the line could carry);
* down to the measured rate only while the queue proves the line busy at
  both ends of the sample's interval (an idle application or a shut window
  also makes samples low, and must not slow the pacer);
* up to what a *rate pair* shows (:meth:`RateEstimator.on_pair`): two
  packets handed at once leave back to back, and their ACKs come back one
  real transmit time apart -- the only sample a pacer holding an idle line
  to a rate hint that is too low can take; without a rate, the first pair
  sets it;
* back down to where it was when a retransmission timer fires after a raise
  that no later busy run has confirmed (:meth:`RateEstimator.on_timeout`):
  bunched ACKs can fake a sample or a busy run, and once every packet is
  resent before its ACK nothing else would ever measure the line again.

The peer's ACKs share its line with its own data: an ACK that waited behind
a reply packet arrives late, the next one early, and the round trip grows
with a queue that is not ours.  So an interval in which the peer's data
arrived (:meth:`RateEstimator.reverse`) neither counts as queued nor gives a
sample: the ACK clock measures our line only while the way back is quiet.
(An arm server's replies made a 9600 bit/s line look like 1400 bit/s, and
the pacer held an emergency stop back for seconds.)

Nothing here reads a clock: every method takes ``now``.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from ._packet import _slot_setter

__all__ = ["RateEstimator", "RateMark"]

RAISE_MARGIN = 1.05
"""A sample must beat the estimate by 5 % to raise it (jitter is not speed)."""

LOWER_MARGIN = 0.9
"""The estimate drops to the measured rate only when that is 10 % below it."""

BUSY_RUN_PACKETS = 3
"""Deliveries after the first of a queued run before its rate counts,
unless they span :data:`BUSY_RUN_SPAN` already."""

BUSY_REFINE = 0.002
"""A busy run's rate replaces the estimate when they differ by more than this."""

BUSY_RUN_SPAN = 0.25
"""Seconds a queued run must span to count after one delivery: long against
the jitter of a tty read, short against a slow line's packet time."""

RAMP_MIN = 2.0
"""Least factor the rate grows by when packets arrive earlier than modelled."""

RAMP_MAX = 4.0
"""Most it grows by in one round trip (a queue of three times the line's
round trip at most, which the next busy run measures and drains)."""

LOOSE_SEED_DELIVERIES = 4
"""Deliveries (with the way back quiet) that tighten a listener's seeded
reference round trip before :meth:`RateEstimator.fast_evidence` uses it."""

SEND_SLACK = 1.1
"""A delivery sample may show the line this much faster than its bytes were
handed over, and no more: a queue draining does that (a pacer whose rate was
measured a few per cent low); ACKs that waited at the far end and came back
bunched show the peer's ACK clock, not our line (up to the ratio of a data
packet to an ACK, 2.4 times a 300 bit/s line with 39-character packets)."""

PAIR_FASTER_THAN_HINT = 1.5
"""A rate pair (:meth:`RateEstimator.on_pair`) must show the line this many
times faster than a hinted rate to raise it: a pair read 10 ms off at
9600 bit/s is 10 % off, and a raise past a right hint costs the short UART
queue."""

PAIR_FASTER = 1.2
"""... and this many times faster than a measured or raised rate: an ACK of
the pair's first packet that waited behind another on the way back makes the
pair look faster (a 2400 bit/s line measured at 275), and every raise past
the line builds a queue a busy run must drain."""

MAX_FILTER_ROUND_TRIPS = 10
"""Samples older than this many round trips leave the windowed maximum."""


@dataclass(frozen=True, slots=True)
class RateMark:
    """What the estimator knew when a packet's first copy was handed to the line.

    Attributes:
        handed_end: bytes handed to the line up to and including this packet.
        point_time: when the delivery point was reached (an ACK's arrival).
        point_handed: ``handed_end`` of the packet acknowledged at that point.
        point_queued: that packet had waited in a queue (the line was busy).
        point_sent: when that packet (its first copy) was handed to the line.
        sent_at: when this packet was handed to the line.
        epoch: the estimate's version when this packet was sent.
    """

    handed_end: int
    point_time: float
    point_handed: int
    point_queued: bool
    point_sent: float
    sent_at: float
    epoch: int


_new = object.__new__
_SET_HANDED_END = _slot_setter(RateMark, "handed_end")
_SET_POINT_TIME = _slot_setter(RateMark, "point_time")
_SET_POINT_HANDED = _slot_setter(RateMark, "point_handed")
_SET_POINT_QUEUED = _slot_setter(RateMark, "point_queued")
_SET_POINT_SENT = _slot_setter(RateMark, "point_sent")
_SET_SENT_AT = _slot_setter(RateMark, "sent_at")
_SET_EPOCH = _slot_setter(RateMark, "epoch")
"""The slots' setters (see :meth:`RateEstimator.mark`; a test checks that
every field is set)."""


class RateEstimator:
    """Delivery-rate and queue-lag estimation for one connection.

    Rates are in wire characters per second.

    Args:
        hint: the configured rate, where estimation starts (None: unknown).
    """

    def __init__(self, hint: float | None) -> None:
        self.hint = hint
        self.rate: float | None = hint
        """The rate the endpoint paces at and times by (None: unknown)."""
        self.measured: float | None = None
        """The windowed maximum of the delivery samples (None before one)."""
        self.queue_delay = 0.0
        """Seconds the last acknowledged packet waited in a queue the model
        did not know about (0 when the model and the line agree)."""
        self.base_rtt: float | None = None
        """The path's round trip from a packet leaving the UART to its ACK,
        without queueing: the least seen, from the init exchange on."""
        self.init_rtt: float | None = None
        """The init exchange's round trip, measured from the init being
        handed to the line: the one sample no rate model touched.  Tightened
        by any packet's time from handing to ACK, which no model touches
        either (:meth:`on_delivery`)."""
        self.busy_change = False
        """The last :meth:`on_delivery` set the rate from a busy line (exact)."""
        self.samples = 0
        self.raises = 0
        self.lowers = 0
        self._handed = 0
        self._point_time: float | None = None
        self._point_handed = 0
        self._point_queued = False
        self._point_sent = 0.0
        self._max: deque[tuple[float, float]] = deque()
        self._epoch = 0
        self._offset_epoch = -1
        self._pushed = False
        self._raised_from: float | None = None
        """The rate before the first raise no busy run has confirmed since: a
        ramp on early ACKs, a sample above the rate, or a busy run faster
        than it (ACKs bunched at the far end can fake the last two)."""
        self._raised_at = -math.inf
        """When :attr:`_raised_from` was set: only a busy run that starts
        after it confirms the raise (the run that raised is no witness)."""
        self.pull_back = 0.0
        """Seconds the pacer's model should move earlier (set by :meth:`on_delivery`)."""
        self._init_bytes = 0
        self._last_queued = False
        self._run: tuple[float, int, int, float] | None = None
        """A queued run: its first delivery's time, that packet's
        ``handed_end``, deliveries since, and when that packet was handed over."""
        self._reverse_at = -math.inf
        self._void_at = -math.inf
        self.last_delivery: tuple[float, RateMark] | None = None
        """When the last first copy was acknowledged, and its mark."""
        self._loose = 0
        """Deliveries left before a seeded :attr:`init_rtt` is trusted as the
        reference of :meth:`fast_evidence` (0: trusted; -1: never)."""

    # -- what the endpoint tells us --------------------------------------------------

    def start(self, now: float, base_rtt: float | None) -> None:
        """The connection is established at ``now``: this is the first
        delivery point (everything handed so far was the init exchange).

        ``base_rtt`` is the init exchange's round trip, if one was measured:
        an upper bound of the path's base round trip (it includes the two
        init packets' transmit times)."""
        self._point_time = now
        self._point_handed = self._handed
        self._point_queued = False
        # The packet delivered at this point is the init, handed one round
        # trip ago (or, unmeasured, no earlier than now for all we know).
        self._point_sent = now - (base_rtt or 0.0)
        self._init_bytes = self._handed
        if base_rtt is not None:
            self.base_rtt = self.init_rtt = base_rtt

    def answered(self, base_rtt: float | None, init_bytes: int) -> None:
        """The init's answer came after :meth:`start` was called at the
        init (a first flight went behind it, PROTOCOL.md 14, its packets
        the first after the delivery point): ``base_rtt`` as in
        :meth:`start`, and ``init_bytes`` the characters of the init's
        copies (what :meth:`start` counts as the init exchange's)."""
        self._init_bytes = init_bytes
        if base_rtt is not None:
            self.base_rtt = self.init_rtt = base_rtt

    def seed_base(self, upper_bound: float, *, trusted_later: bool = True) -> None:
        """An upper bound of the base round trip: a listener's, from its init
        answer to the connector's next packet, or a connector's whose init was
        resent (from its first copy).  ``trusted_later`` False: the bound only
        judges samples plausible and never becomes the reference of
        :meth:`fast_evidence` (a connector's first deliveries wait in the
        queue its first window built, so they cannot tighten it: seeded 0.65 s
        long at 2400 bit/s and 1.3 s, it ramped the rate up every few round
        trips and ended in a timeout storm)."""
        if self.init_rtt is None:
            # Only a bound: the connector may have sent its first packet a
            # while after our answer arrived.  A reference too long would
            # make every sample look early and ramp the rate up (an arm
            # server seeded 0.27 s long paced at 8 times a 9600 bit/s line),
            # so the first deliveries tighten it before it is trusted.
            self.init_rtt = upper_bound
            self._loose = LOOSE_SEED_DELIVERIES if trusted_later else -1
        if self.base_rtt is None:
            self.base_rtt = upper_bound

    def reverse(self, now: float) -> None:
        """A packet carrying the peer's data arrived: the ACKs behind it on
        the peer's line were delayed by it, not by ours."""
        self._reverse_at = now

    def void(self, now: float) -> None:
        """The port dropped bytes it had not sent (an expedited packet cut
        in): samples across ``now`` would count them as delivered."""
        self._void_at = now

    @property
    def reverse_at(self) -> float:
        """When the peer's data last arrived (-inf: never)."""
        return self._reverse_at

    def hand(self, wire_bytes: int) -> None:
        """Count bytes handed to the line (every packet, any kind)."""
        self._handed += wire_bytes

    def mark(self, now: float) -> RateMark | None:
        """The mark for a packet's first copy, handed just now (after :meth:`hand`).
        None before the connection is established."""
        if self._point_time is None:
            return None
        # RateMark(...) written out through the slots: once per packet, and
        # a frozen dataclass's keyword __init__ costs three times as much.
        mark = _new(RateMark)
        _SET_HANDED_END(mark, self._handed)
        _SET_POINT_TIME(mark, self._point_time)
        _SET_POINT_HANDED(mark, self._point_handed)
        _SET_POINT_QUEUED(mark, self._point_queued)
        _SET_POINT_SENT(mark, self._point_sent)
        _SET_SENT_AT(mark, now)
        _SET_EPOCH(mark, self._epoch)
        return mark

    @property
    def handed(self) -> int:
        """Bytes handed to the line so far."""
        return self._handed

    def plausible(self, rtt: float, rttvar: float | None = None) -> bool:
        """Could the path really have carried a packet and its ACK this fast?

        Not faster than the init exchange, less the two init packets'
        transmit times it paid and a data packet's ACK does not.  A shorter
        sample is the model's error (it put the departure too late: a queue
        drained at a rate measured a little low) or an ACK for an older
        packet with the same wire number; taken as the path's base it would
        make every later round trip look queued and every timer too short.

        With ``rttvar`` the question is whether the sample *proves* an
        early departure: the init's answer and this ACK were each read up
        to one read batch late, so a sample short by less than the jitter
        allowance of :meth:`fast_evidence` proves nothing.  (At 9600 bit/s
        and 0.27 s one way, an ACK read 2 ms after it arrived against an
        init answer read 16 ms late came out 1 ms "impossible"; taken as
        evidence of a faster line it doubled the rate every few seconds,
        and the queue that built timed out every packet in flight.)
        """
        if self.init_rtt is None:
            return True
        if self.rate is None or self._loose:
            return rtt >= self.init_rtt / 2
        slack = 0.01 if rttvar is None else 0.01 + self._jitter(rttvar)
        return rtt >= self.init_rtt - 2 * self._init_bytes / self.rate - slack

    def _jitter(self, rttvar: float) -> float:
        """The jitter allowed a round trip against the init's: the measured
        variation, but no more than 50 ms and 1 % of the path -- before any
        plausible sample the variation is the seed's half round trip, which
        would hide every deficit."""
        return min(rttvar, 0.05 + 0.01 * (self.init_rtt or 0.0))

    def fast_evidence(self, rtt: float, model_tx: float, rttvar: float) -> bool:
        """A round trip this short means the packet left before the model said.

        The init exchange's round trip is the reference (or a packet's, from
        handing to ACK, if shorter): it was measured from the moment the init
        was handed to the line, so no model is in it, and it includes two
        init packets' transmit times that a data packet's ACK does not pay.
        A paced packet's modelled departure is up to three of its transmit
        times after it was handed over (two packets queued ahead of it in
        the model); on a line k times faster than the model it really left
        after one real transmit time, so its round trip comes out about
        (3k - 1) real transmit times short -- more than the one modelled
        transmit time allowed here for every k above about 1.2, and never
        for k = 1.

        Args:
            rtt: the sample, from the model's departure time to the ACK.
            model_tx: the model's transmit time of that packet.
            rttvar: the round-trip variation (jitter allowance).
        """
        if self.init_rtt is None or self.rate is None or self._loose:
            return False
        return rtt < self.init_rtt - (model_tx + self._jitter(rttvar) + 0.01)

    def on_delivery(
        self,
        mark: RateMark,
        now: float,
        rtt: float,
        srtt: float | None,
        *,
        fast: bool,
        wire_bytes: int = 0,
    ) -> bool:
        """The first copy of the packet with ``mark`` was acknowledged at ``now``.

        Args:
            rtt: its round-trip sample (from the model's departure time).
            srtt: the smoothed round trip (the filter's time scale).
            wire_bytes: the packet's length on the wire.
            fast: the sample is early: :meth:`fast_evidence` held, or it is
                not :meth:`plausible` (the model's departure was too late).

        Returns:
            True when :attr:`rate` changed.
        """
        changed = False
        queued = False
        self.busy_change = False
        self.last_delivery = (now, mark)
        if not fast and (self.base_rtt is None or rtt < self.base_rtt) and self.plausible(rtt):
            self.base_rtt = rtt
        # The peer's data crossed the interval: its ACKs were timed by its line.
        tainted = max(self._reverse_at, self._void_at) > mark.point_time
        if self._loose > 0 and not fast and not tainted and self.init_rtt is not None:
            # A seed still to be trusted: the first deliveries tighten it.
            # A bound never to be trusted (-1) is not moved by these model-
            # timed samples: a model running late makes them short, each
            # passes as plausible against half the bound, and the bound
            # ratcheted down sample by sample -- a connector with no hints,
            # whose init was resent, judged 0.004 s "plausible" on a 2.6 s
            # path after 1250 s, its smoothed round trip fell to 0.6 s, the
            # window with it, and the line ran at 0.87 of the limit where it
            # had run at 0.97 (2400 bit/s, 1.3 s, 1e-4).  The handing-to-ACK
            # time tightens it below, with no model in it.
            self.init_rtt = min(self.init_rtt, rtt)
            self._loose -= 1
        if tainted:
            self._run = None
            self._last_queued = False
            self.queue_delay = 0.0
        elif self.base_rtt is not None and not fast:
            lag = rtt - self.base_rtt
            # Jitter and the model's rounding are not a queue: 50 ms plus 5 %
            # of the path (a fraction alone would hide a real queue on a
            # long path, an absolute alone would see one in every relay).
            queued = lag > 0.05 + 0.05 * self.base_rtt
            # Two in a row: one late ACK is a lost ACK or a burst of jitter
            # as often as a queue.
            self.queue_delay = lag if queued and self._last_queued else 0.0
            self._last_queued = queued
        busy = None if tainted else self._busy_sample(mark, now, queued)
        # The bytes between the two delivery points were handed over in the
        # time between their packets' handing, and left the line in the time
        # between their ACKs -- unless the ACKs were bunched: an ACK that
        # waited at the far end (behind the peer's other ACKs, or its
        # receiver stalled and then read a burst) makes the next interval
        # short by the wait.  ACKs for 39-character packets sent back to back
        # at 16 characters each "measured" a 300 bit/s line at 1170 bit/s,
        # and pacing at that flooded it.  The line cannot carry bytes before
        # they are handed to it, so a sample shows at most SEND_SLACK times
        # the rate they were handed at.  (BBR's delivery-rate estimation
        # takes the longer interval outright; here a pacer whose rate was
        # measured 4 % low then never learned better.)
        interval = max(now - mark.point_time, (mark.sent_at - mark.point_sent) / SEND_SLACK)
        if not tainted and mark.handed_end > mark.point_handed and interval > 0:
            sample = (mark.handed_end - mark.point_handed) / interval
            self.samples += 1
            self._push(sample, now, srtt)
            measured = self._max[0][1]
            self.measured = measured
            if busy is not None and self._confirms(busy, now):
                self._raised_from = None  # a measurement, not a guess, from here
            if busy is not None and (
                self.rate is None or abs(busy - self.rate) > BUSY_REFINE * self.rate
            ):
                # The line was busy all along: this is its rate, up or down
                # (refined as the run grows: a rate 1 % low misplaces the end
                # of a minute of queue by 0.6 s).
                if self.rate is not None and busy > self.rate * RAISE_MARGIN:
                    # Faster than the rate in use while a queue waits: the
                    # line, or ACKs that waited at the far end and came back
                    # to back (a stalled receiver read a burst and answered
                    # it: a 300 bit/s line "measured" at 1770 bit/s, and the
                    # pacer flooded it).  A raise, until a later run confirms it.
                    self.raises += 1
                    self._raising(now)
                elif self.rate is not None and busy < self.rate * LOWER_MARGIN:
                    self.lowers += 1
                self.rate = busy
                self.busy_change = True
                changed = True
            elif self.rate is not None and measured > self.rate * RAISE_MARGIN:
                self._raising(now)
                self.rate = measured
                self.raises += 1
                changed = True
        self.pull_back = 0.0
        # An early ACK after the peer's data crossed the interval is that
        # data's doing (the ACK behind a reply arrives late, the next one
        # early), not a faster line: on a 9600 bit/s line with an arm's
        # telemetry coming back, such ACKs ramped the rate to four times the
        # line, and the timers it drove fired on every packet.
        if fast and not tainted and self.rate is not None and mark.epoch == self._epoch:
            if self._offset_epoch != self._epoch and self._pushed:
                # The model put this packet's departure too late.  First
                # assume an offset (the end of a long queue misplaced by a
                # rate a little off): pull the model back once and watch
                # the packets sent after that.
                reference = self.base_rtt if self.base_rtt is not None else self.init_rtt
                self.pull_back = max((reference or 0.0) - rtt, 0.0)
                self._epoch += 1
                self._offset_epoch = self._epoch
                self._pushed = False
            else:
                # Sent after the model was pulled back, and early again: the
                # model drains slower than the line and the pacer holds back
                # what the line could carry.  Double, until the queue (or a
                # busy run's measurement) says stop -- but never past a few
                # times what the line was measured to deliver: a pacer that
                # holds data back delivers at about the rate it paces at, so
                # the bound lets that grow as fast as before, while a sender
                # with little to send (one small packet a round trip, each
                # "early") proves nothing about the line, and ramping on it
                # took 2400 bit/s to 10^300 and overflowed the buffer sizing.
                ceiling = max(self.rate, RAMP_MAX * (self.measured or 0.0))
                ramped = min(self.rate * self._ramp(mark, now, wire_bytes), ceiling)
                if ramped > self.rate:
                    self._raising(now)
                    self.rate = ramped
                    self.raises += 1
                    changed = True
        if mark.handed_end >= self._point_handed:
            self._point_time = now
            self._point_handed = mark.handed_end
            self._point_queued = queued
            self._point_sent = mark.sent_at
        if self.init_rtt is not None and now - mark.sent_at < self.init_rtt:
            # From handing a packet over to its ACK, like the init exchange,
            # with no model in it: the path is no longer than that.  An init
            # answer that was held up (60 s, on a 115 200 bit/s line) made
            # every later round trip "impossible" -- all early, none a
            # sample: the base round trip stayed 60 s, no queue could show,
            # and the rate ramped to four times the line for good.
            self.init_rtt = now - mark.sent_at
        if changed:
            self._epoch += 1
        return changed

    def on_pair(self, wire_bytes: int, spacing: float, sent_at: float, now: float) -> bool | None:
        """Two packets handed to the line at ``sent_at``, back to back, were
        acknowledged ``spacing`` seconds apart, the second (``wire_bytes``
        long) at ``now``: the line sent it in about that time.

        Returns None when the pair tells nothing (ACKs read together, or the
        peer's data crossed the interval and spaced them by its line), True
        when the rate was set (without one, to what the pair showed) or raised
        (to what the pair showed, at most
        :data:`RAMP_MAX` times: ACKs bunched at the far end fake speed, and
        the raise is undone by a timeout no busy run has answered, like any
        other), False when the line is no faster than the rate in use (within
        :data:`PAIR_FASTER_THAN_HINT` of a hint, :data:`PAIR_FASTER` of any
        other).
        """
        if spacing <= 0 or max(self._reverse_at, self._void_at) > sent_at:
            return None
        # Never below what the ACK clock has already seen the line deliver.
        line = max(wire_bytes / spacing, self.measured or 0.0)
        if self.rate is None:
            # No rate known and two packets went at once: the first measure
            # of the line, a round trip after the first burst (a busy run
            # needs a queue the round trip shows, 30 s of it at 300 s one
            # way).  Too high (ACKs bunched), it builds a queue that a busy
            # run measures.
            self.rate = line
            self._epoch += 1
            return True
        if line <= self.rate * (PAIR_FASTER_THAN_HINT if self.rate == self.hint else PAIR_FASTER):
            return False
        self._raising(now)
        self.rate = min(line, RAMP_MAX * self.rate)
        self.raises += 1
        self._epoch += 1
        self._rebase()
        return True

    def _rebase(self) -> None:
        """The rate was raised past a low one: judge the base round trip again.

        A sample is plausible down to the init's round trip less the init
        packets' transmit times *at the rate in use*, and at a rate hint ten
        times low that is seconds of slack: a packet the model put 5 s late
        became the base (35.3 s on a 40 s path), every round trip after it
        looked queued, the pacer was pushed later on each, and the packets
        after each push looked early enough to ramp the rate to four times
        the line (0.58 of the limit at 20 s)."""
        if self.base_rtt is None or self.init_rtt is None or not self.rate:
            return
        floor = self.init_rtt - 2 * self._init_bytes / self.rate
        self.base_rtt = max(self.base_rtt, min(floor, self.init_rtt))

    def _raising(self, now: float) -> None:
        """The rate is about to be raised at ``now``: remember where from,
        unless an earlier raise is still unconfirmed."""
        if self._raised_from is None:
            self._raised_from = self.rate
            self._raised_at = now

    def _confirms(self, busy: float, now: float) -> bool:
        """A busy run measured ``busy``: does it confirm the rate in use?  Any
        measurement at or below it does; one that raises it does not, nor
        does the run that made the raise (it is no witness of itself)."""
        if self.rate is None or busy > self.rate * RAISE_MARGIN:
            return False
        started = self._run[0] if self._run is not None else now
        return busy < self.rate * LOWER_MARGIN or started >= self._raised_at

    def _busy_sample(self, mark: RateMark, now: float, queued: bool) -> float | None:
        """The line's rate over a run of deliveries that all waited in a queue.

        While packets queue, the line never idles between their departures,
        so the bytes handed between two of them left in exactly the time
        between their ACKs.  Measured from the run's first delivery, the span
        grows with the run and jitter in any one ACK fades; a run of fewer
        than :data:`BUSY_RUN_PACKETS` deliveries gives nothing yet.
        """
        if not queued:
            self._run = None
            return None
        if self._run is not None and max(self._reverse_at, self._void_at) > self._run[0]:
            self._run = None  # the peer's data arrived within the run: start again
        if self._run is None:
            self._run = (now, mark.handed_end, 0, mark.sent_at)
            return None
        t0, h0, n, s0 = self._run
        n += 1
        self._run = (t0, h0, n, s0)
        if mark.handed_end <= h0 or now <= t0:
            return None
        if n < BUSY_RUN_PACKETS and now - t0 < BUSY_RUN_SPAN:
            return None
        busy = (mark.handed_end - h0) / (now - t0)
        span = (mark.sent_at - s0) / SEND_SLACK
        if self.rate is not None and busy > self.rate and span > now - t0:
            # A raise, but no faster than the bytes were handed over either
            # (ACKs bunched at the far end: see on_delivery).  Only a raise:
            # bytes handed in a burst long before drain at the line's rate,
            # and their handing says nothing of it.
            busy = max(self.rate, (mark.handed_end - h0) / span)
        return busy

    def _push(self, sample: float, now: float, srtt: float | None) -> None:
        horizon = MAX_FILTER_ROUND_TRIPS * (srtt or 0.0)
        while self._max and self._max[-1][1] <= sample:
            self._max.pop()
        self._max.append((now, sample))
        while len(self._max) > 1 and now - self._max[0][0] > horizon:
            self._max.popleft()

    def _ramp(self, mark: RateMark, now: float, wire_bytes: int) -> float:
        """How much faster than the model the line is, judged from one early
        packet: between :data:`RAMP_MIN` and :data:`RAMP_MAX` times.

        From handing the packet over to its ACK took its real transmit time
        (the line is faster than the model, so nothing queued ahead of it)
        plus the path's base round trip, which the init exchange bounds from
        above; what is left is the packet's real transmit time, or less.  At
        long delays this reaches the line in two round trips where doubling
        needs four -- at Mars, 40 minutes each.
        """
        if self.rate is None or self.init_rtt is None or wire_bytes <= 0:
            return RAMP_MIN
        tx = now - mark.sent_at - self.init_rtt
        if tx <= 0:
            return RAMP_MAX
        return min(max(wire_bytes / tx / self.rate, RAMP_MIN), RAMP_MAX)

    def on_timeout(self) -> bool:
        """A retransmission timer fired.  If the rate was raised -- ramped on
        early ACKs, or set by a sample or a busy run faster than it -- and no
        busy run has confirmed it since, the raise is the likelier culprit
        than the line: the model drains faster than the line, and the queue
        it does not see delays every ACK past its timer.  (With the peer's
        data on the way back -- an arm's telemetry -- that queue never shows
        as queue lag, so nothing else corrects it: at 9600 bit/s and no delay
        a rate ramped to twice the line stayed there, every timer fired, and
        the duplicates starved the session for its dead time.  And once every
        packet is resent before its ACK, none gives a sample: a 300 bit/s
        line whose ACKs came back bunched after a stall was paced at six
        times its rate, and the timeouts never stopped.)  Back to the larger
        of the rate before the raise and what was measured; returns whether
        the rate changed."""
        if self._raised_from is None or self.rate is None:
            return False
        back = max(self._raised_from, min(self.measured or 0.0, self.rate))
        self._raised_from = None
        if back >= self.rate:
            return False
        self.rate = back
        self.lowers += 1
        self._epoch += 1
        return True

    def pushed(self) -> None:
        """The endpoint moved the pacer's model later (a queue was found):
        an early packet after this may be that move's error, not speed."""
        self._pushed = True

    def line_free_at(self, now: float, mark: RateMark) -> float | None:
        """When the line will have sent everything handed so far, judged from
        the packet with ``mark`` acknowledged at ``now`` (None: no rate or no
        base round trip).  The packet left the line one base round trip ago;
        what was handed after it drains at :attr:`rate` from then on."""
        if self.rate is None or self.base_rtt is None:
            return None
        left = now - self.base_rtt
        # At no less than the line was seen to deliver: a busy run that
        # measured a 9600 bit/s line at 312 bit/s for 0.2 s while 12 KB were
        # queued put the queue's end 38 s out, no later raise moved it back,
        # and the pacer held NAKed resends for 20 s until the close gave up.
        drains = max(self.rate, self.measured or 0.0)
        return left + (self._handed - mark.handed_end) / drains
