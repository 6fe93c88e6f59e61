"""One goodput measurement: a bulk transfer between two sans-I/O endpoints on virtual time.

Two :class:`~serialsocket.Endpoint` objects talk through two
:class:`~linksim.link._impair.LinkDirection` engines in a discrete-event loop: time
jumps from one event (a byte arrival or a timer) to the next, so an hour of a
2400 bit/s line costs about a second of CPU and the result is exact and
machine-independent (the same inputs give the same bytes, times and counters
on any computer).

The theoretical limit (the ARQ issue's definition)::

    limit_Bps = line_Bps x carried / wire x (1 - P(packet hit))

``carried / wire`` is measured on the very payload of the point: the payload
is cut into data fields exactly as the sender cuts it (the data encoding and
block check two endpoints of this profile and maximum packet length agree on
in their init exchange -- the radix-91 packing or the escape code between two
telelink ends, serialsocket/PROTOCOL.md section 10 -- and the same maximum
packet length), every full packet is framed with its check and EOL, and the
bytes it carries are divided by the bytes it occupies on the line.
``P(packet hit)`` is the probability that at least one of the ``wire`` bytes
of such a packet is damaged: ``1 - (1 - byte_error_rate)^wire`` for
independent errors, the exact Gilbert-Elliott block probability otherwise.
ACKs travel the other way and do not count against the limit; a window of any
size cannot beat it, so ``ratio_to_limit`` measures what the ARQ (window,
timers, pacing, recovery) loses.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from linksim.link import DirectionConfig, GilbertElliott, LinkConfig, LinkDirection
from serialsocket import ConnectionAborted, Endpoint, EndpointConfig, LinkDead, State
from serialsocket.packets import (
    EIGHT_BIT_CLEAN,
    PRINTABLE,
    Encoding,
    Negotiated,
    Packet,
    build_packet,
    data_capacity,
)

__all__ = [
    "BENCH_BURST",
    "HINTS",
    "PROFILES",
    "Measurement",
    "agreed_parameters",
    "hinted",
    "limit_goodput",
    "packet_error_probability",
    "packet_sizes",
    "simulate",
]

BITS_PER_CHAR = 10
"""8N1: a start bit, eight data bits, a stop bit (what the real-peer figures used)."""

BENCH_BURST = GilbertElliott(p_good_to_bad=5e-5, p_bad_to_good=0.05, error_bad=0.3)
"""The burst case of the grid: the ``noisy-moon`` preset's fades (a fade every
20 000 bytes on average, 20 bytes long, hitting 30 % of the bytes inside it;
a long-run byte error rate of 3.0e-4) without its independent errors, so the
row shows what clustering alone does."""

PROFILES: dict[str, Encoding] = {"printable": PRINTABLE, "8bit": EIGHT_BIT_CLEAN}
"""Encoding profiles by the name used in rows: the default printable profile
(8th-bit prefixing; the line carries printable ASCII plus SOH and CR) and the
8-bit-clean profile both peers negotiate when the line carries all bytes."""


@dataclass(frozen=True, slots=True)
class Measurement:
    """What one simulated transfer measured.

    Attributes:
        delivered: payload bytes the receiver read, in order.
        seconds: virtual seconds from the connection being established (the
            first data may leave) to the last byte read; when the transfer did
            not complete within its time cap, to the cap.
        connect_seconds: virtual seconds of the connection handshake.
        complete: every payload byte arrived before the time cap.
        end: how the run ended: ``complete``, ``time cap``, ``link dead``
            (an endpoint's dead-link verdict), ``aborted`` or ``stalled``
            (no timer and nothing on the line: a protocol deadlock).
        ok: what arrived is exactly the start of the payload (nothing
            duplicated, reordered or damaged).
        retransmissions, timeouts, naks, fast_retransmits: sender counters.
        smoothed_rtt: the sender's final smoothed round trip, s (None if never
            sampled).
        effective_window: the sender's final effective window, packets.
        first_byte_seconds: virtual seconds from the connect call to the
            first payload byte read at the far end (time to first byte), or
            None if none arrived.
        long_sequence: the ends negotiated long sequence numbers.
    """

    delivered: int
    seconds: float
    connect_seconds: float
    complete: bool
    end: str
    ok: bool
    retransmissions: int
    timeouts: int
    naks: int
    fast_retransmits: int
    smoothed_rtt: float | None
    effective_window: int
    first_byte_seconds: float | None = None
    early_bytes: int = 0
    """Of ``delivered``, bytes read before the connector heard the answer
    (before ``seconds`` began: early data in the connection request, a first
    flight's packets behind it): left out of the goodput (:attr:`goodput`)."""
    long_sequence: bool = False

    @property
    def goodput(self) -> float:
        """Payload bytes/s after the connection was established (early data,
        which arrived during the handshake, is not counted)."""
        return (self.delivered - self.early_bytes) / self.seconds if self.seconds > 0 else 0.0


@functools.lru_cache(maxsize=64)
def agreed_parameters(encoding: Encoding, max_len: int, dense: bool = False) -> Negotiated:
    """What two endpoints configured with this profile and maximum packet
    length agree on, from a real init exchange between two
    :class:`~serialsocket.Endpoint` objects (so the limit follows the
    negotiation, dense encodings and CRC-32 included).  Without long
    sequence numbers: the two characters they add to a data packet are a
    cost of the protocol's choice, as its ACKs are, and the limit is the
    same whatever the hints made the endpoints choose.  ``dense``: both offer
    the dense encodings (PROTOCOL.md section 10), as the netcat does."""
    return agree(
        EndpointConfig(max_packet_length=max_len, encoding=encoding, long_window=None, dense=dense)
    )


def agree(config: EndpointConfig) -> Negotiated:
    """What two endpoints with ``config`` agree on, from a real init exchange."""
    a, b = Endpoint(config), Endpoint(config)
    b.listen()
    a.connect(0.0)
    b.receive_data(a.data_to_send(0.0), 0.0)
    a.receive_data(b.data_to_send(0.0), 0.0)
    assert a.parameters is not None, "two endpoints of one configuration always agree"
    return a.parameters


def packet_sizes(
    payload: bytes, encoding: Encoding, max_len: int, dense: bool = False
) -> tuple[float, float]:
    """Mean payload bytes carried and wire bytes occupied by a full data packet.

    ``encoding`` is the endpoints' configured profile; the payload is cut
    exactly as the sender cuts it with the data encoding and check the two
    ends agree on (:func:`agreed_parameters`); the last (possibly short)
    packet is left out unless it is the only one.  Wire bytes count MARK
    through CHECK plus the EOL (CR), i.e. everything the UART clocks out.
    """
    agreed = agreed_parameters(encoding, max_len, dense)
    cap = data_capacity(max_len, agreed.check)
    fields = agreed.encoding.encode_fields(payload, cap, 1 << 30)
    full = fields[:-1] or fields
    carried = sum(used for _, used in full)
    wire = sum(len(build_packet(Packet(seq=0, type="D", data=f), agreed.check)) for f, _ in full)
    return carried / len(full), wire / len(full)


def packet_error_probability(
    wire_bytes: float, byte_error_rate: float, burst: GilbertElliott | None = None
) -> float:
    """Probability that a packet of ``wire_bytes`` bytes has at least one byte damaged.

    Independent errors: ``1 - (1 - p)^n``.  With Gilbert-Elliott bursts (a
    two-state Markov chain stepped once per byte, started in its stationary
    distribution) and independent errors on top, the probability that all
    ``n`` bytes pass is ``pi D (T D)^(n-1) 1`` with ``D`` the per-state pass
    probabilities and ``T`` the transition matrix.
    """
    n = max(1, round(wire_bytes))
    if burst is None:
        return 1.0 - float((1.0 - byte_error_rate) ** n)
    a, c = burst.p_good_to_bad, burst.p_bad_to_good
    keep = 1.0 - byte_error_rate
    d = np.diag([keep * (1.0 - burst.error_good), keep * (1.0 - burst.error_bad)])
    t = np.array([[1.0 - a, a], [c, 1.0 - c]])
    pi = np.array([c, a]) / (a + c)
    survive = pi @ d @ np.linalg.matrix_power(t @ d, n - 1) @ np.ones(2)
    return 1.0 - float(survive)


def mean_byte_error_rate(byte_error_rate: float, burst: GilbertElliott | None) -> float:
    """The long-run fraction of damaged bytes (burst and independent errors together)."""
    if burst is None:
        return byte_error_rate
    a, c = burst.p_good_to_bad, burst.p_bad_to_good
    in_state = (c * burst.error_good + a * burst.error_bad) / (a + c)
    return 1.0 - (1.0 - in_state) * (1.0 - byte_error_rate)


def limit_goodput(
    payload: bytes,
    *,
    rate: float,
    max_len: int,
    encoding: Encoding,
    byte_error_rate: float,
    burst: GilbertElliott | None = None,
    dense: bool = False,
) -> tuple[float, float]:
    """The theoretical goodput (module docstring) and the packet error probability
    (``dense``: for the encoding two ends offering the dense ones agree on).

    Returns:
        ``(limit in payload bytes/s, probability that a full packet is hit)``.
    """
    carried, wire = packet_sizes(payload, encoding, max_len, dense)
    p_hit = packet_error_probability(wire, byte_error_rate, burst)
    return rate / BITS_PER_CHAR * carried / wire * (1.0 - p_hit), p_hit


HINTS = (
    "exact",
    "none",
    "wrong-delay-low",
    "wrong-delay-high",
    "wrong-rate-low",
    "wrong-rate-high",
)
"""What both ends are told about the line: the truth, nothing, or one value 10x off."""


def hinted(hints: str, delay: float, rate: float) -> tuple[float, float | None]:
    """The ``(one_way_delay, line_rate)`` the ends are given under ``hints``."""
    match hints:
        case "exact":
            return delay, rate
        case "none":
            return 0.0, None
        case "wrong-delay-low":
            return delay / 10, rate
        case "wrong-delay-high":
            return delay * 10 if delay > 0 else 1.0, rate
        case "wrong-rate-low":
            return delay, rate / 10
        case "wrong-rate-high":
            return delay, rate * 10
    raise ValueError(f"hints must be one of {', '.join(HINTS)}, got {hints!r}")


def simulate(
    payload: bytes,
    *,
    rate: float,
    delay: float,
    byte_error_rate: float,
    burst: GilbertElliott | None,
    window: int,
    max_len: int | None,
    encoding: Encoding,
    seed: int,
    time_cap: float,
    hints: str = "exact",
    dense: bool = False,
    first_flight: bool = False,
    correction: bool = False,
    max_packet_time: float | None = EndpointConfig().max_packet_time,
    far_eof: bool = False,
) -> Measurement:
    """Send ``payload`` from end a to end b over the impaired line; measure it.

    Both ends use the configuration a user of this line would write: the
    line's one-way delay and rate (which size every timer and the pacing),
    the window, the maximum packet length and the encoding profile; every
    other setting (timers, keepalive, ``dead_after``, buffers) is the
    default, so the figures are what a user gets.  A dead-link verdict or an
    abort ends the run early, reported in ``end``.

    Args:
        first_flight: end a sends what it has queued beyond its request's
            early data as a first flight (serialsocket/PROTOCOL.md 14), as
            the netcat does.
        correction: both ends offer corrected data packets
            (serialsocket/PROTOCOL.md 15), as the netcat does.
        max_packet_time: the longest line time of one data packet with the
            length measured (the library's default; the netcat sets None).
        far_eof: end b half-closes as soon as it is connected, as a netcat
            listener with nothing to send does (its EOF and the copies and
            resends of it cross the data, and end a acknowledges them).
        time_cap: stop after this many virtual seconds of data transfer and
            report what was delivered (``complete=False``); it bounds the
            CPU spent on hopeless combinations (long packets at high error
            rates), never a completing one.
    """
    direction = DirectionConfig(
        rate=rate,
        bits_per_char=BITS_PER_CHAR,
        delay=delay,
        byte_error_rate=byte_error_rate,
        burst=burst,
    )
    link = LinkConfig.symmetric(direction, seed=seed)
    hinted_delay, hinted_rate = hinted(hints, delay, rate)
    cfg = EndpointConfig(
        one_way_delay=hinted_delay,
        line_rate=hinted_rate,
        bits_per_char=BITS_PER_CHAR,
        window=window,
        max_packet_length=max_len,
        encoding=encoding,
        dense=dense,
        first_flight=first_flight,
        correction=correction,
        max_packet_time=max_packet_time,
    )
    size = len(payload)
    a, b = Endpoint(cfg), Endpoint(cfg)
    ab = LinkDirection(link.a_to_b, seed=link.seed, direction=0)
    ba = LinkDirection(link.b_to_a, seed=link.seed, direction=1)
    now = 0.0
    b.listen()
    # Queued before connecting, as a command is: the first bytes ride in the
    # connection request (serialsocket/PROTOCOL.md section 13).
    pos = a.send(payload, now)
    a.connect(now)
    got = bytearray()
    start: float | None = None
    # Read the line as a serial reader does, in small batches (16 character
    # times), but never past a timer that is due first: the batching keeps
    # the loop cheap (one wake per 16 bytes) while adding at most 16
    # character times to any reaction, as a real tty read would.
    quantum = 16 * BITS_PER_CHAR / rate
    cap_at = math.inf
    end = "complete"
    first_byte: float | None = None
    early = 0
    b_eof = False
    while len(got) < size:
        if far_eof and b.state is State.ESTABLISHED and not b_eof:
            b.send_eof(now)
            b_eof = True
        if start is None and a.state is State.ESTABLISHED:
            start = now
            cap_at = now + time_cap
            # Delivered before the connection was: early data, or a first
            # flight's packets (serialsocket/PROTOCOL.md sections 13, 14).
            early = len(got)
        if a.state in (State.CONNECTING, State.ESTABLISHED) and pos < size:
            pos += a.send(memoryview(payload)[pos:], now)
        ab.send(a.data_to_send(now), now)
        ba.send(b.data_to_send(now), now)
        timers = [
            t for ep in (a, b) for t in (ep.get_timer(), ep.get_send_timer()) if t is not None
        ]
        arrivals = [t for t in (ab.next_delivery(), ba.next_delivery()) if t is not None]
        if not (timers or arrivals):
            end = "stalled"
            break
        wake = min(timers, default=math.inf)
        if arrivals:
            wake = min(wake, min(arrivals) + quantum)
        if wake > cap_at or (start is None and wake > time_cap):
            now = min(max(now, wake), cap_at)
            end = "time cap"
            break
        now = max(now, wake)
        b.receive_data(ab.receive(now), now)
        a.receive_data(ba.receive(now), now)
        for ep in (a, b):
            t = ep.get_timer()
            if t is not None and t <= now:
                ep.handle_timer(now)
        got += b.read(None, now)
        if first_byte is None and got:
            first_byte = now
        events = [e for ep in (a, b) for e in ep.events()]
        if any(isinstance(e, LinkDead) for e in events):
            end = "link dead"
            break
        if any(isinstance(e, ConnectionAborted) for e in events):
            end = "aborted"
            break
    connect_seconds = start if start is not None else now
    s = a.statistics()
    return Measurement(
        delivered=len(got),
        seconds=now - connect_seconds,
        connect_seconds=connect_seconds,
        complete=len(got) == size,
        end="complete" if len(got) == size else end,
        ok=bytes(got) == payload[: len(got)],
        retransmissions=s.retransmissions,
        timeouts=s.timeouts,
        naks=s.naks_received,
        fast_retransmits=s.fast_retransmits,
        smoothed_rtt=s.smoothed_rtt,
        effective_window=s.effective_window,
        first_byte_seconds=first_byte,
        long_sequence=s.long_sequence,
        early_bytes=early,
    )
