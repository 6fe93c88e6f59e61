"""The sans-I/O impairment engine: one :class:`LinkDirection` per direction of a line.

Bytes enter with :meth:`LinkDirection.send` at time ``now`` and leave with
:meth:`LinkDirection.receive`; the caller owns the clock.  Nothing here sleeps,
reads a clock, touches a file descriptor or uses global randomness -- both the
in-memory trio channel and the pty relay drive the same object.

Timing model (exact, no accumulated rounding).  With ``c = bits_per_char /
rate`` seconds per character, the bytes of one write at ``t`` start
serialising at ``s = max(t, previous departure)``; byte ``k`` (0-based within
the write) leaves the UART at ``s + (k + 1)·c`` and arrives at
``(s + delay) + (k + 1)·c``, plus its jitter.  Arrival times never decrease (a
serial line never reorders), so a jittered byte can hold back those behind it.
A byte written at ``t`` on an idle line therefore arrives at exactly
``t + delay + c``.

Damage, per byte, in this order: outage (lost if on the wire during an
outage), scripted faults, Gilbert-Elliott bursts, independent loss, random
corruption, then noise insertion after the byte.  Lost bytes still occupied the
line, so they never change the timing of the others.  Each impairment draws
from its own numpy ``Generator`` derived from ``SeedSequence([seed,
direction, k])``: the same seed and the same writes (sizes and times) give the
same output byte for byte, and enabling one impairment does not change the
pattern of another.  All per-byte work is vectorised over a whole write.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ._config import DirectionConfig, FaultAction, ScriptedFault

__all__ = ["DirectionStatistics", "LinkDirection"]

_F64 = npt.NDArray[np.float64]
_U8 = npt.NDArray[np.uint8]
_BOOL = npt.NDArray[np.bool_]
_I64 = npt.NDArray[np.int64]

_GE_BATCH = 256
"""Good-bad sojourn pairs drawn at a time by the Gilbert-Elliott walk."""


@dataclass(frozen=True, slots=True)
class DirectionStatistics:
    """Counters of one direction (bytes unless stated otherwise).

    ``bytes_sent`` counts writes; ``bytes_delivered`` what :meth:`receive`
    handed out (including inserted bytes); ``bytes_in_flight`` what is decided
    but not yet delivered; ``bytes_held`` what waits for a scripted-fault match
    to be settled.  ``bytes_discarded`` what a :meth:`LinkDirection.discard`
    (an output flush) dropped before it left the UART.  ``bytes_delayed``
    counts delivered-to-be bytes that arrive later than they were written,
    ``max_latency``/``total_latency`` are seconds from write to arrival over
    those bytes.  ``bursts`` is the number of
    Gilbert-Elliott bad states that met at least one byte (a fade on an idle
    line harms nothing and is not counted) and ``burst_bytes`` the bytes sent
    in one.
    """

    bytes_sent: int = 0
    bytes_delivered: int = 0
    bytes_in_flight: int = 0
    bytes_held: int = 0
    bytes_dropped: int = 0
    dropped_loss: int = 0
    dropped_burst: int = 0
    dropped_outage: int = 0
    dropped_scripted: int = 0
    bytes_corrupted: int = 0
    corrupted_random: int = 0
    corrupted_burst: int = 0
    corrupted_scripted: int = 0
    bytes_inserted: int = 0
    inserted_noise: int = 0
    inserted_scripted: int = 0
    bytes_delayed: int = 0
    max_latency: float = 0.0
    total_latency: float = 0.0
    bursts: int = 0
    burst_bytes: int = 0
    faults_fired: int = 0
    bytes_discarded: int = 0


def _find_all(buf: bytes, pattern: bytes, wildcard: int | None) -> list[int]:
    """Start positions of ``pattern`` in ``buf`` (``wildcard`` bytes match anything)."""
    out: list[int] = []
    first = pattern[:1]
    i = buf.find(first)
    while i >= 0:
        if i + len(pattern) > len(buf):
            break
        if all(p == wildcard or p == buf[i + j] for j, p in enumerate(pattern)):
            out.append(i)
        i = buf.find(first, i + 1)
    return out


def _proper_prefix_suffix(buf: bytes, pattern: bytes, wildcard: int | None) -> int:
    """Length of the longest suffix of ``buf`` that is a proper prefix of ``pattern``."""
    for k in range(min(len(pattern) - 1, len(buf)), 0, -1):
        tail = buf[len(buf) - k :]
        if all(p == wildcard or p == tail[j] for j, p in enumerate(pattern[:k])):
            return k
    return 0


class _Segment:
    """Decided bytes awaiting delivery; ``times`` is one float when they all
    arrive together, ``deps`` when each finishes leaving the UART (one float
    when they all left at once: a line without a rate)."""

    __slots__ = ("data", "deps", "offset", "times")

    def __init__(self, data: bytes, times: _F64 | float, deps: _F64 | float) -> None:
        self.data = data
        self.times = times
        self.deps = deps
        self.offset = 0  # bytes already delivered

    def departed_by(self, now: float) -> int:
        """Index after the last byte that has left the UART by ``now``."""
        d = self.deps
        if isinstance(d, float):
            return len(self.data) if d <= now else 0
        return int(np.searchsorted(d, now, side="right"))

    def truncate(self, end: int) -> None:
        """Keep the first ``end`` bytes (not before ``offset``): the rest was
        discarded before it left the UART."""
        self.data = self.data[:end]
        if not isinstance(self.times, float):
            self.times = self.times[:end]
        if not isinstance(self.deps, float):
            self.deps = self.deps[:end]

    def last_arrival(self) -> float:
        t = self.times
        return t if isinstance(t, float) else float(t[-1])

    def first_arrival(self) -> float:
        t = self.times
        return t if isinstance(t, float) else float(t[self.offset])

    def arrived_by(self, now: float) -> int:
        """Index after the last byte that has arrived by ``now`` (never before ``offset``).

        ``now`` may be a hair earlier than a previous call's (a reader woken
        by its timer uses the target time, the next call the clock, which
        can round just below it); bytes already delivered stay delivered.
        """
        t = self.times
        if isinstance(t, float):
            return len(self.data) if t <= now else self.offset
        return max(self.offset, int(np.searchsorted(t, now, side="right")))


class _FaultState:
    """Progress of one scripted fault through the stream."""

    __slots__ = ("done", "dropping", "fault", "seen")

    def __init__(self, fault: ScriptedFault) -> None:
        self.fault = fault
        self.seen = 0  # occurrences of starts_with so far
        self.done = False  # fired (and, for a packet drop, the packet ended)
        self.dropping = False  # inside the target packet of a packet drop


class LinkDirection:
    """One direction of an impaired serial line (sans-I/O, see the module docstring).

    ``now`` values passed in must not decrease.
    """

    def __init__(self, config: DirectionConfig, *, seed: int, direction: int = 0) -> None:
        self.config = config
        self._c = config.char_time
        children = np.random.SeedSequence([seed, direction]).spawn(7)
        gens = [np.random.Generator(np.random.PCG64(s)) for s in children]
        (self._rng_loss, self._rng_err, self._rng_noise, self._rng_walk) = gens[:4]
        (self._rng_hit, self._rng_jitter, self._rng_fault) = gens[4:]
        self._last_departure = -math.inf
        self._last_arrival = -math.inf
        self._sent = 0
        self._decided = 0  # absolute index of the first byte not yet through the faults
        self._held = b""
        self._held_deps: _F64 = np.empty(0)
        self._held_arrivals: _F64 = np.empty(0)
        self._held_writes: _F64 = np.empty(0)
        self._segments: deque[_Segment] = deque()  # delivery queue, arrival order
        self._in_flight = 0
        self._faults = [_FaultState(f) for f in config.faults]
        self._corrupt_at: dict[int, int] = {}  # absolute position -> xor (packet CORRUPT)
        # Gilbert-Elliott walk, in character slots of line time (see _burst_states):
        # upcoming sojourn lengths, the first of which may be partly used.
        self._ge_runs = np.empty(0, dtype=np.int64)
        self._ge_first_bad = False
        self._ge_first_counted = False  # the partly used first run already met a byte
        self._ge_next_bad = False
        self._ge_slot: int | None = None  # the next slot the walk has not passed
        self._counts: dict[str, int] = {
            k: 0 for k in DirectionStatistics.__slots__ if k not in ("max_latency", "total_latency")
        }
        self._max_latency = 0.0
        self._total_latency = 0.0

    # -- queries --------------------------------------------------------------

    def transmit_done_at(self) -> float:
        """When the UART finishes serialising everything written so far (-inf if never)."""
        return self._last_departure

    def queued(self, now: float) -> int:
        """Bytes written but not yet fully serialised at ``now`` (the UART backlog)."""
        if self._c == 0.0 or self._last_departure <= now:
            return 0
        return math.ceil((self._last_departure - now) / self._c - 1e-9)

    def drained_at(self, backlog: int) -> float:
        """The time at which at most ``backlog`` bytes remain queued in the UART."""
        return self._last_departure - backlog * self._c

    def pending(self) -> int:
        """Bytes accepted but not yet delivered (in flight, plus any held back)."""
        # Counted from the delivery queue itself, not from a running counter:
        # EOF delivery waits for this to reach zero, so it must be exact.
        return self._queued_bytes() + len(self._held)

    def _queued_bytes(self) -> int:
        """Bytes decided and queued for delivery but not yet received."""
        return sum(len(seg.data) - seg.offset for seg in self._segments)

    def in_outage(self, now: float) -> bool:
        """True while a scheduled outage cuts the signal at ``now``."""
        return any(o.start <= now < o.end for o in self.config.outages)

    def next_delivery(self) -> float | None:
        """The earliest arrival time of undelivered bytes, or None when nothing is pending."""
        if self._segments:
            return self._segments[0].first_arrival()
        return None

    def statistics(self) -> DirectionStatistics:
        """A snapshot of the counters."""
        c = self._counts
        c["bytes_in_flight"] = self._queued_bytes()
        c["bytes_held"] = len(self._held)
        c["bytes_dropped"] = (
            c["dropped_outage"] + c["dropped_scripted"] + c["dropped_burst"] + c["dropped_loss"]
        )
        c["bytes_inserted"] = c["inserted_noise"] + c["inserted_scripted"]
        return DirectionStatistics(
            **c, max_latency=self._max_latency, total_latency=self._total_latency
        )

    # -- data path ------------------------------------------------------------

    def receive(self, now: float) -> bytes:
        """All bytes that have arrived by ``now`` (inclusive), in order; may be empty."""
        out: list[bytes] = []
        while self._segments:
            seg = self._segments[0]
            end = seg.arrived_by(now)
            if end > seg.offset:
                out.append(seg.data[seg.offset : end])
            if end < len(seg.data):
                seg.offset = end
                break
            self._segments.popleft()
        result = b"".join(out)
        self._in_flight -= len(result)
        self._counts["bytes_delivered"] += len(result)
        return result

    def send(self, data: bytes | bytearray | memoryview, now: float) -> None:
        """Put ``data`` on the line at ``now`` (the UART queues it behind earlier bytes)."""
        n = len(data)
        if n == 0:
            return
        raw = bytes(data)
        self._counts["bytes_sent"] += n
        self._sent += n
        start = max(now, self._last_departure)
        delay = self.config.delay
        if self._c:
            steps = self._c * np.arange(1, n + 1, dtype=np.float64)
            deps = start + steps
            arrivals = (start + delay) + steps
            self._last_departure = float(deps[-1])
        else:
            deps = np.full(n, start)
            arrivals = np.full(n, start + delay)
            self._last_departure = start
        writes = np.full(n, float(now))
        if self._held:
            raw = self._held + raw
            deps = np.concatenate([self._held_deps, deps])
            arrivals = np.concatenate([self._held_arrivals, arrivals])
            writes = np.concatenate([self._held_writes, writes])
        hold = self._hold_length(raw)
        if hold:
            cut = len(raw) - hold
            self._held, raw = raw[cut:], raw[:cut]
            self._held_deps, deps = deps[cut:], deps[:cut]
            self._held_arrivals, arrivals = arrivals[cut:], arrivals[:cut]
            self._held_writes, writes = writes[cut:], writes[:cut]
        else:
            self._held = b""
        if raw:
            self._decide(raw, deps, arrivals, writes)

    def flush(self) -> None:
        """Settle bytes held back for a scripted-fault match: no more writes will follow."""
        if self._held:
            raw, deps, arrivals, writes = (
                self._held,
                self._held_deps,
                self._held_arrivals,
                self._held_writes,
            )
            self._held = b""
            self._decide(raw, deps, arrivals, writes)

    def discard(self, now: float) -> int:
        """Drop every byte written and not yet serialised at ``now``, as a
        serial port's output flush (``tcflush(TCOFLUSH)``) does; the
        character in the shift register still goes.  What was dropped never
        reaches the far end (its fate, already drawn, is void).  Returns the
        bytes dropped (counted in ``bytes_discarded``)."""
        cutoff = now + self._c  # the character being shifted out finishes
        if self._c == 0.0 or self._last_departure <= cutoff:
            return 0
        dropped = 0
        if self._held:
            keep = int(np.searchsorted(self._held_deps, cutoff, side="right"))
            dropped += len(self._held) - keep
            self._held = self._held[:keep]
            self._held_deps = self._held_deps[:keep]
            self._held_arrivals = self._held_arrivals[:keep]
            self._held_writes = self._held_writes[:keep]
        segments = self._segments
        while segments:
            seg = segments[-1]
            # Delivered bytes have arrived, so they left the UART long ago.
            end = max(seg.departed_by(cutoff), seg.offset)
            if end >= len(seg.data):
                break
            gone = len(seg.data) - end
            dropped += gone
            self._in_flight -= gone
            if end == 0:
                segments.pop()
                continue
            seg.truncate(end)
            break
        self._last_departure = cutoff
        self._last_arrival = segments[-1].last_arrival() if segments else -math.inf
        self._counts["bytes_discarded"] += dropped
        return dropped

    # -- internals -------------------------------------------------------------

    def _hold_length(self, buf: bytes) -> int:
        """Bytes at the end of ``buf`` that might start a not-yet-complete packet match."""
        hold = 0
        for st in self._faults:
            f = st.fault
            if f.packet is not None and not st.done and len(f.starts_with) > 1:
                hold = max(hold, _proper_prefix_suffix(buf, f.starts_with, f.wildcard))
        return hold

    def _decide(self, raw: bytes, deps: _F64, arrivals: _F64, writes: _F64) -> None:
        """Fix the fate and arrival time of a run of bytes and queue them for delivery."""
        cfg = self.config
        n = len(raw)
        base = self._decided
        self._decided += n
        counts = self._counts
        clean = cfg.is_lossless and cfg.jitter == 0.0
        if clean and self._c == 0.0 and not self._held:
            # Fast path (clean, no rate): the whole write arrives at one instant.
            at = max(float(arrivals[-1]), self._last_arrival)
            self._last_arrival = at
            self._queue(raw, at, writes, float(deps[-1]))
            return
        if cfg.jitter:
            arrivals = arrivals + self._rng_jitter.random(n) * cfg.jitter
        if clean:
            arrivals = np.maximum.accumulate(np.maximum(arrivals, self._last_arrival))
            self._last_arrival = float(arrivals[-1])
            self._queue(raw, arrivals, writes, deps)
            return

        values = np.frombuffer(raw, dtype=np.uint8).copy()
        keep = np.ones(n, dtype=np.bool_)
        xor = np.zeros(n, dtype=np.uint8)
        inserts: list[tuple[int, bytes]] = []

        # 1. Outages: lost if the wire interval [dep - c, arrival] meets [start, end).
        signal = np.ones(n, dtype=np.bool_)
        for o in cfg.outages:
            signal &= ~(((deps - self._c) < o.end) & (arrivals >= o.start))
        counts["dropped_outage"] += int(n - signal.sum())
        keep &= signal

        # 2. Scripted faults.
        if self._faults or self._corrupt_at:
            self._apply_faults(raw, base, keep, xor, inserts)

        # 3. Gilbert-Elliott bursts.
        if cfg.burst is not None:
            bad = self._burst_states(deps)
            counts["burst_bytes"] += int(bad.sum())
            p = np.where(bad, cfg.burst.error_bad, cfg.burst.error_good)
            hit = (self._rng_hit.random(n) < p) & keep
            if cfg.burst.drop:
                counts["dropped_burst"] += int(hit.sum())
                keep &= ~hit
            else:
                k = int(hit.sum())
                xor[hit] ^= self._rng_hit.integers(1, 256, size=k, dtype=np.uint8)
                counts["corrupted_burst"] += k

        # 4. Independent loss.
        if cfg.loss:
            lost = (self._rng_loss.random(n) < cfg.loss) & keep
            counts["dropped_loss"] += int(lost.sum())
            keep &= ~lost

        # 5. Random corruption.
        if cfg.byte_error_rate:
            err = (self._rng_err.random(n) < cfg.byte_error_rate) & keep
            k = int(err.sum())
            xor[err] ^= self._rng_err.integers(1, 256, size=k, dtype=np.uint8)
            counts["corrupted_random"] += k

        damaged = (xor != 0) & keep
        counts["bytes_corrupted"] += int(damaged.sum())
        values ^= xor

        # 6. Noise after a byte (only where there is signal), then assembly.
        noise = np.zeros(n, dtype=np.bool_)
        if cfg.noise:
            noise = (self._rng_noise.random(n) < cfg.noise) & signal
        emitted = keep.astype(np.int64) + noise
        ends = np.cumsum(emitted)
        starts = ends - emitted
        total = int(ends[-1]) if n else 0
        out = np.empty(total, dtype=np.uint8)
        times = np.empty(total, dtype=np.float64)
        out_writes = np.empty(total, dtype=np.float64)
        out_deps = np.empty(total, dtype=np.float64)
        kept_at = starts[keep]
        out[kept_at] = values[keep]
        times[kept_at] = arrivals[keep]
        out_writes[kept_at] = writes[keep]
        out_deps[kept_at] = deps[keep]
        k = int(noise.sum())
        if k:
            noise_at = starts[noise] + keep[noise]
            out[noise_at] = self._rng_noise.integers(0, 256, size=k, dtype=np.uint8)
            times[noise_at] = arrivals[noise]
            out_writes[noise_at] = np.inf  # inserted bytes are not counted as delayed
            out_deps[noise_at] = deps[noise]
            counts["inserted_noise"] += k
        if inserts:
            where = np.concatenate([np.full(len(d), starts[i]) for i, d in inserts])
            blob = np.frombuffer(b"".join(d for _, d in inserts), dtype=np.uint8)
            t_ins = np.concatenate([np.full(len(d), arrivals[i]) for i, d in inserts])
            out = np.insert(out, where, blob)
            times = np.insert(times, where, t_ins)
            out_writes = np.insert(out_writes, where, np.full(len(blob), np.inf))
            d_ins = np.concatenate([np.full(len(d), deps[i]) for i, d in inserts])
            out_deps = np.insert(out_deps, where, d_ins)
            counts["inserted_scripted"] += len(blob)
        if len(out) == 0:
            return
        times = np.maximum.accumulate(np.maximum(times, self._last_arrival))
        self._last_arrival = float(times[-1])
        self._queue(out.tobytes(), times, out_writes, out_deps)

    def _queue(self, data: bytes, times: _F64 | float, writes: _F64, deps: _F64 | float) -> None:
        """Queue decided bytes for delivery and account their latency."""
        self._segments.append(_Segment(data, times, deps))
        self._in_flight += len(data)
        latency = times - writes
        real = np.isfinite(latency)
        delayed = latency[real & (latency > 0)]
        self._counts["bytes_delayed"] += len(delayed)
        if len(delayed):
            self._total_latency += float(delayed.sum())
            self._max_latency = max(self._max_latency, float(delayed.max()))

    def _apply_faults(
        self, raw: bytes, base: int, keep: _BOOL, xor: _U8, inserts: list[tuple[int, bytes]]
    ) -> None:
        """Mark scripted faults hitting ``raw`` (absolute positions ``base``...)."""
        n = len(raw)
        c = self._counts
        for st in self._faults:
            f = st.fault
            if st.done and not st.dropping:
                continue
            if f.byte is not None:
                if base <= f.byte < base + n:
                    self._hit(f, f.byte - base, keep, xor, inserts)
                    st.done = True
                continue
            matches = _find_all(raw, f.starts_with, f.wildcard)
            scan_from = 0
            if st.dropping:
                # Continue dropping the target packet begun in an earlier write.
                stop, ended = self._packet_end(raw, 0, matches, f)
                self._drop_range(keep, 0, stop)
                st.dropping = not ended
                st.done = ended
                scan_from = stop
            if st.done:
                continue
            for m in matches:
                if m < scan_from:
                    continue
                st.seen += 1
                if st.seen != f.packet:
                    continue
                c["faults_fired"] += 1
                st.done = True
                if f.action is FaultAction.DROP:
                    stop, ended = self._packet_end(raw, m + 1, matches, f)
                    self._drop_range(keep, m, stop)
                    st.dropping = not ended
                elif f.action is FaultAction.INSERT:
                    inserts.append((m, f.data))
                else:
                    self._corrupt_at[base + m + f.offset] = f.xor
                break
        for pos in [p for p in self._corrupt_at if base <= p < base + n]:
            if keep[pos - base]:
                xor[pos - base] ^= self._corrupt_at[pos]
                c["corrupted_scripted"] += 1
            del self._corrupt_at[pos]

    def _hit(
        self, f: ScriptedFault, i: int, keep: _BOOL, xor: _U8, inserts: list[tuple[int, bytes]]
    ) -> None:
        self._counts["faults_fired"] += 1
        if f.action is FaultAction.DROP:
            self._drop_range(keep, i, i + 1)
        elif f.action is FaultAction.INSERT:
            inserts.append((i, f.data))
        elif keep[i]:
            xor[i] ^= f.xor
            self._counts["corrupted_scripted"] += 1

    @staticmethod
    def _packet_end(raw: bytes, frm: int, matches: list[int], f: ScriptedFault) -> tuple[int, bool]:
        """Index after the packet that continues at ``frm`` (its end byte, or the next
        start) and whether it ended within ``raw`` (else it goes on in the next write)."""
        stop, ended = len(raw), False
        if f.end is not None:
            e = raw.find(bytes([f.end]), frm)
            if e >= 0:
                stop, ended = e + 1, True
        later = [m for m in matches if m >= frm]
        if later and later[0] < stop:
            stop, ended = later[0], True
        return stop, ended

    def _drop_range(self, keep: _BOOL, lo: int, hi: int) -> None:
        seg = keep[lo:hi]
        self._counts["dropped_scripted"] += int(seg.sum())
        seg[:] = False

    def _burst_states(self, deps: _F64) -> _BOOL:
        """The Gilbert-Elliott state (True = bad) of bytes leaving the UART at ``deps``.

        The chain steps once per *character time* of the line, whether or not a
        byte is being sent: a fade is a property of the channel, so it lasts the
        same wall-clock time on a busy data direction and on a sparse ACK
        direction.  (Stepping per byte sent made a 10-byte fade on a line
        carrying one ACK a second last minutes.)  Back-to-back bytes occupy
        consecutive slots, so under continuous traffic this is the per-byte chain
        of the config's docstring.  On a line without a rate there is no
        character time, and the chain steps once per byte.
        """
        n = len(deps)
        prev = self._ge_slot
        if self._c > 0.0:
            slots = np.rint(deps / self._c).astype(np.int64)
            if prev is None:
                prev = int(slots[0])
            # Strictly increasing, at least one slot apart (rounding never merges two bytes).
            steps = np.maximum(np.diff(slots, prepend=prev - 1), 1)
            slots = (prev - 1) + np.cumsum(steps)
        else:
            if prev is None:
                prev = 0
            slots = prev + np.arange(n, dtype=np.int64)
        burst = self.config.burst
        assert burst is not None
        # Idle stretches far longer than a good-bad cycle are crossed in one
        # exact step (below) instead of by drawing every sojourn in them.
        far = int(64 * (1.0 / burst.p_good_to_bad + 1.0 / burst.p_bad_to_good))
        # Idle slots before each byte (``prev`` is the first slot not yet walked).
        idle = np.diff(slots, prepend=prev - 1) - 1
        gaps = np.flatnonzero(idle > far)
        states = np.empty(n, dtype=np.bool_)
        pos, start = prev, 0
        for stop in [*gaps.tolist(), n]:
            if stop > start:
                hits = slots[start:stop] - pos
                states[start:stop] = self._ge_walk(int(hits[-1]) + 1, hits)
                pos = int(slots[stop - 1]) + 1
            if stop < n:
                self._ge_jump(int(slots[stop]) - pos)
                pos = int(slots[stop])
            start = stop
        self._ge_slot = pos
        return states

    def _ge_jump(self, gap: int) -> None:
        """Cross ``gap`` idle slots at once: the state after them is drawn from the
        chain's exact ``gap``-step transition, and by the geometric law's lack of
        memory the sojourn it is in starts afresh."""
        burst = self.config.burst
        assert burst is not None
        a, b = burst.p_good_to_bad, burst.p_bad_to_good
        bad_now = self._ge_first_bad if len(self._ge_runs) else self._ge_next_bad
        stationary = a / (a + b)
        p_bad = stationary + (float(bad_now) - stationary) * (1.0 - a - b) ** gap
        self._ge_runs = np.empty(0, dtype=np.int64)
        self._ge_next_bad = bool(self._rng_walk.random() < p_bad)
        self._ge_first_counted = False

    def _ge_walk(self, length: int, hits: _I64) -> _BOOL:
        """Walk ``length`` slots; the states at the offsets ``hits`` (sorted, distinct).

        ``bursts`` counts the bad sojourns that met at least one byte.
        """
        burst = self.config.burst
        assert burst is not None
        runs = self._ge_runs
        if len(runs) == 0:
            self._ge_first_bad = self._ge_next_bad
            self._ge_first_counted = False
        # Sojourns are drawn in batches of a fixed size, only when needed: the
        # random stream then does not depend on how the traffic was split into
        # writes, so neither do the bursts.
        batches = [runs]
        have = int(runs.sum())
        while have < length:
            good = self._rng_walk.geometric(burst.p_good_to_bad, size=_GE_BATCH)
            bad = self._rng_walk.geometric(burst.p_bad_to_good, size=_GE_BATCH)
            pair = np.empty(2 * _GE_BATCH, dtype=np.int64)
            first, second = (bad, good) if self._ge_next_bad else (good, bad)
            pair[0::2] = first
            pair[1::2] = second
            batches.append(pair)
            have += int(pair.sum())
        if len(batches) > 1:
            runs = np.concatenate(batches)
        cum = np.cumsum(runs)
        j = int(np.searchsorted(cum, length, side="left"))
        run_bad = ((np.arange(j + 1) % 2) == 1) != self._ge_first_bad
        which = np.searchsorted(cum, hits, side="right")  # the run each hit falls in
        met = np.zeros(j + 1, dtype=np.bool_)
        met[which] = True
        first_counted = self._ge_first_counted
        new = met.copy()
        new[0] &= not first_counted
        self._counts["bursts"] += int((run_bad & new).sum())
        left = int(cum[j]) - length
        rest = runs[j:].copy()
        if left:
            rest[0] = left
            self._ge_first_bad = bool(run_bad[-1])
            self._ge_first_counted = bool(met[j]) or (j == 0 and first_counted)
        else:
            rest = rest[1:]
            self._ge_first_bad = not bool(run_bad[-1])
            self._ge_first_counted = False
        # The state of the run that follows the last queued one (runs alternate).
        self._ge_next_bad = self._ge_first_bad != (len(rest) % 2 == 1)
        self._ge_runs = rest
        states: _BOOL = run_bad[which]
        return states
