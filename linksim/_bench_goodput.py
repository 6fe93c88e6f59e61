"""``linksim bench goodput``: ARQ goodput against the theoretical limit, on virtual time.

Two sans-I/O endpoints talk through two :class:`~linksim._impair.LinkDirection`
engines in a discrete-event loop: time jumps from one event (a byte arrival or
a timer) to the next, so an hour of a 2400 bit/s link costs a fraction of a
second and the result is exact and machine-independent.

Theoretical goodput (issue 3): line rate in bytes/s x (payload bytes carried
by a full data packet / wire bytes of that packet, MARK through EOL, for the
benchmark's data) x (1 - probability that a packet of that size is hit).
ACKs travel the other way and do not count against it.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import asdict, dataclass

from serialsocket import (
    EIGHT_BIT_CLEAN,
    PRINTABLE,
    BlockCheck,
    ConnectionAborted,
    Endpoint,
    EndpointConfig,
    LinkDead,
    State,
    data_capacity,
)

from ._bench_codec import sample_payload
from ._config import DirectionConfig, GilbertElliott, LinkConfig
from ._impair import LinkDirection

__all__ = ["GoodputResult", "add_arguments", "run_transfer", "theoretical_goodput"]


@dataclass(frozen=True, slots=True)
class GoodputResult:
    """One measured point.

    Attributes:
        window: configured window.
        max_len: maximum packet length (MARK through CHECK).
        rate: line rate, bit/s.
        delay: one-way delay, s.
        byte_error_rate: independent byte error probability per direction.
        payload: kind of data (binary/text).
        bytes: payload size.
        seconds: simulated time from connection to the last byte delivered.
        goodput: payload bytes per simulated second.
        theoretical: the limit for this line, packet size and data.
        efficiency: goodput / theoretical.
        retransmissions, timeouts, naks: sender-side counters.
        ok: every byte arrived exactly once, in order.
    """

    window: int
    max_len: int
    rate: float
    delay: float
    byte_error_rate: float
    payload: str
    profile: str
    bytes: int
    seconds: float
    goodput: float
    theoretical: float
    efficiency: float
    retransmissions: int
    timeouts: int
    naks: int
    ok: bool


def theoretical_goodput(
    payload: bytes,
    *,
    rate: float,
    bits_per_char: int,
    max_len: int,
    byte_error_rate: float,
    eight_bit: bool = False,
) -> float:
    """The issue's formula, with the packet efficiency measured on this very data."""
    encoding = EIGHT_BIT_CLEAN if eight_bit else PRINTABLE
    cap = data_capacity(max_len, BlockCheck.CRC16)
    fields = encoding.encode_fields(payload, cap, 1 << 30)
    full = fields[:-1] or fields
    carried = sum(used for _, used in full)
    wire = sum(len(f) + 7 + 3 + 1 for f, _ in full)  # extended header, CRC, EOL
    if max_len <= 96:
        wire -= 3 * len(full)  # normal header is 3 shorter
    per_packet_error = 1.0 - float((1.0 - byte_error_rate) ** (wire / len(full)))
    return rate / bits_per_char * carried / wire * (1 - per_packet_error)


def run_transfer(
    *,
    window: int,
    rate: float,
    delay: float,
    byte_error_rate: float,
    size: int,
    max_len: int = 128,
    payload_kind: str = "binary",
    eight_bit: bool = False,
    seed: int = 1,
    burst: bool = False,
) -> GoodputResult:
    """Send ``size`` bytes one way over an impaired line and measure the goodput."""
    direction = DirectionConfig(
        rate=rate,
        delay=delay,
        byte_error_rate=byte_error_rate,
        burst=GilbertElliott(p_good_to_bad=5e-5, p_bad_to_good=0.05, error_bad=0.3)
        if burst
        else None,
    )
    link = LinkConfig.symmetric(direction, seed=seed)
    cfg = EndpointConfig(
        one_way_delay=delay,
        line_rate=rate,
        window=window,
        max_packet_length=max_len,
        encoding=EIGHT_BIT_CLEAN if eight_bit else PRINTABLE,
        dead_after=1e9,
    )
    payload = sample_payload(payload_kind, size, seed)
    a, b = Endpoint(cfg), Endpoint(cfg)
    ab = LinkDirection(link.a_to_b, seed=link.seed, direction=0)
    ba = LinkDirection(link.b_to_a, seed=link.seed, direction=1)
    now = 0.0
    b.listen()
    a.connect(now)
    got = bytearray()
    pos = 0
    start: float | None = None
    # A generous bound on simulated time so a protocol bug cannot spin forever.
    quantum = 16 * 10 / rate
    limit = 50 * size / (rate / 10) + 1000 * (2 * delay + 1)
    while len(got) < size:
        if start is None and a.state is State.ESTABLISHED:
            start = now
        if a.state is State.ESTABLISHED and pos < size:
            pos += a.send(memoryview(payload)[pos:], now)
        ab.send(a.data_to_send(now), now)
        ba.send(b.data_to_send(now), now)
        timers = [
            t for ep in (a, b) for t in (ep.get_timer(), ep.get_send_timer()) if t is not None
        ]
        arrivals = [t for t in (ab.next_delivery(), ba.next_delivery()) if t is not None]
        if not (timers or arrivals) or now > limit:
            break
        # Read the line like a serial reader does, in small batches (16
        # character times), but never past a timer that is due first.
        wake = min(timers, default=math.inf)
        if arrivals:
            wake = min(wake, min(arrivals) + quantum)
        now = max(now, wake)
        b.receive_data(ab.receive(now), now)
        a.receive_data(ba.receive(now), now)
        for ep in (a, b):
            t = ep.get_timer()
            if t is not None and t <= now:
                ep.handle_timer(now)
        got += b.read(None, now)
        if any(isinstance(e, ConnectionAborted | LinkDead) for ep in (a, b) for e in ep.events()):
            break
    seconds = now - (start or 0.0)
    goodput = len(got) / seconds if seconds > 0 else 0.0
    theory = theoretical_goodput(
        payload,
        rate=rate,
        bits_per_char=10,
        max_len=max_len,
        byte_error_rate=byte_error_rate,
        eight_bit=eight_bit,
    )
    s = a.statistics()
    return GoodputResult(
        window=window,
        max_len=max_len,
        rate=rate,
        delay=delay,
        byte_error_rate=byte_error_rate,
        payload=payload_kind,
        profile="8bit" if eight_bit else "printable",
        bytes=size,
        seconds=round(seconds, 3),
        goodput=round(goodput, 3),
        theoretical=round(theory, 3),
        efficiency=round(goodput / theory, 4) if theory else 0.0,
        retransmissions=s.retransmissions,
        timeouts=s.timeouts,
        naks=s.naks_received,
        ok=bytes(got) == payload,
    )


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim bench goodput``."""
    ap.add_argument("--rate", type=float, default=2400.0, help="line rate, bit/s (default 2400)")
    ap.add_argument("--delay", type=float, default=1.3, help="one-way delay, s (default 1.3)")
    ap.add_argument("--ber", type=float, default=1e-4, help="byte error rate (default 1e-4)")
    ap.add_argument(
        "--window", type=int, action="append", help="window(s) to measure (default: 31 and 1)"
    )
    ap.add_argument("--max-len", type=int, default=128)
    ap.add_argument("--size", type=int, default=48_000, help="payload bytes per point")
    ap.add_argument("--payload", choices=["binary", "text"], default="binary")
    ap.add_argument("--eight-bit", action="store_true", help="8-bit-clean profile")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", action="store_true", help="print one JSON object and nothing else")


def main(args: argparse.Namespace) -> int:
    """Entry point for the CLI."""
    windows: Sequence[int] = args.window or [31, 1]
    results = [
        run_transfer(
            window=w,
            rate=args.rate,
            delay=args.delay,
            byte_error_rate=args.ber,
            size=args.size,
            max_len=args.max_len,
            payload_kind=args.payload,
            eight_bit=args.eight_bit,
            seed=args.seed,
        )
        for w in windows
    ]
    if args.json:
        json.dump({"benchmark": "goodput", "results": [asdict(r) for r in results]}, sys.stdout)
        sys.stdout.write("\n")
        return 0 if all(r.ok for r in results) else 1
    print(
        f"line {args.rate:g} bit/s, one-way delay {args.delay:g} s, byte error rate {args.ber:g}, "
        f"{args.size} bytes of {args.payload}, packets of {args.max_len}"
    )
    for r in results:
        print(
            f"  window {r.window:2d}: {r.goodput:8.1f} B/s of {r.theoretical:.1f} theoretical "
            f"({100 * r.efficiency:5.1f} %), {r.seconds:.0f} s simulated, "
            f"{r.retransmissions} retransmissions, {r.timeouts} timeouts, "
            f"{'exact' if r.ok else 'DATA MISMATCH'}"
        )
    if len(results) >= 2 and results[-1].goodput > 0:
        print(f"  ratio first/last: {results[0].goodput / results[-1].goodput:.2f}x")
    return 0 if all(r.ok for r in results) else 1
