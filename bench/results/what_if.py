"""What-if experiment behind the serialsocket changes (not part of the package).

Historical: what_if.txt was measured on the ARQ code before the four changes
landed (serialsocket as of c934c84; they are now commits 308cab9, 203eef9,
57ea56a and 4312bd4).  Run against today's code every column equals "now",
because each patch re-applies behaviour that is already there; the file is
kept as the record of why each change was made and what it measured.

Runs chosen goodput points on virtual time with serialsocket as it is, then
with four proposed changes applied cumulatively.  The changes are patched into
this process only; nothing on disk changes.  Every figure is exact and
machine-independent, like every goodput row.

1. ``nak-ack`` (serialsocket/_sender.py, ``Sender.on_nak``): the stop-and-wait
   rule NAK(n+1) = ACK(n) must also advance ``peer_cum`` to n+1.  Today it
   acknowledges packet n but leaves ``peer_cum`` at n, so ``room()`` stays 0
   and the sender deadlocks until a keepalive probe's answer (never, with
   ``dead_after`` large; ``dead_after / 4`` of silence by default).
2. ``nak-now`` (serialsocket/_endpoint.py, ``_on_packet`` -> ``on_nak``): a NAK
   is honoured once ``2 x one_way_delay + transmit_time(ACK)`` has passed since
   the last copy finished leaving the UART.  Today the threshold is
   ``physical_rtt(full packet)``, which adds the packet's own transmit time a
   second time: every NAK for a damaged packet arrives just under it and is
   ignored, so stop-and-wait waits for the timeout instead.
3. ``wider-window`` (serialsocket/_endpoint.py, ``_compute_effective_window``):
   the bandwidth-delay bound ``ceil(2 x rtt / tx) + 2`` is just short of the
   selective-repeat repair horizon (the lost packet, the packet that reveals
   the gap, the two packets queued ahead of the resend, the resend, two round
   trips); ``ceil(3 x rtt / tx) + 5`` covers it and a lost resend.
4. ``backoff-reset`` (serialsocket/_endpoint.py ``_on_ack`` / _rtt.py): an ACK
   of new data, even for a retransmitted packet, clears the timer backoff.
   Today only a valid RTT sample (Karn) does, so with frequent losses the
   backoff carries over to the next packet and grows to the 60 s ceiling.

    .venv/bin/python bench/results/what_if.py > bench/results/what_if.txt
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from linksim.bench import Point, run_point
from serialsocket import _endpoint, _sender
from serialsocket._packet import Packet

E = _endpoint.Endpoint
S = _sender.Sender
ORIGINAL: dict[str, Any] = {
    "on_nak": S.on_nak,
    "_on_packet": E._on_packet,
    "_compute_effective_window": E._compute_effective_window,
    "_on_ack": E._on_ack,
}

POINTS = [
    # rate, one-way delay, byte error rate, burst, window, max packet length
    Point(2400, 1.3, 1e-4, False, 1, 128),  # the paper's baseline
    Point(2400, 1.3, 1e-3, False, 1, 128),
    Point(2400, 0.0, 1e-3, False, 1, 128),
    Point(2400, 2.5, 1e-3, False, 1, 128),
    Point(9600, 1.3, 1e-3, False, 1, 128),
    Point(2400, 1.3, 1e-4, False, 16, 128),  # the base row (default window)
    Point(2400, 1.3, 1e-3, False, 16, 128),
    Point(2400, 1.3, 0.0, True, 16, 128),
    Point(2400, 2.5, 1e-4, False, 16, 128),
    Point(2400, 2.5, 1e-3, False, 31, 128),
    Point(1200, 1.3, 1e-3, False, 31, 128),
    Point(9600, 0.27, 1e-3, False, 31, 128),
    Point(9600, 1.3, 1e-4, False, 31, 128),
    Point(9600, 1.3, 1e-4, False, 31, 256),
    Point(9600, 1.3, 1e-3, False, 31, 256),
]


def nak_ack(self: _sender.Sender, seq_mod: int, now: float, min_rtt: float) -> None:
    """Change 1: NAK(n+1) = ACK(n) also tells us the peer expects n+1."""
    nxt = self.next
    ORIGINAL["on_nak"](self, seq_mod, now, min_rtt)
    last = nxt - 1
    if self.window == 1 and seq_mod == nxt % 64 and last not in self.outstanding:
        self.peer_cum = max(self.peer_cum, nxt)


def nak_now(self: _endpoint.Endpoint, packet: Packet, now: float) -> None:
    """Change 2: the NAK threshold is two one-way delays plus an ACK's transmit time."""
    if packet.type == "N":
        cfg = self.config
        self._min_rtt = lambda: 2 * cfg.one_way_delay + cfg.transmit_time(10)  # type: ignore[method-assign]
        try:
            ORIGINAL["_on_packet"](self, packet, now)
        finally:
            del self._min_rtt
        return
    ORIGINAL["_on_packet"](self, packet, now)


def wider_window(self: _endpoint.Endpoint) -> int:
    """Change 3: three round trips of packets plus five."""
    window = self._sender.window
    tx = self.config.transmit_time(self._full_wire)
    if tx <= 0:
        return window
    rtt = self._rtt.srtt if self._rtt.srtt is not None else self._min_rtt()
    return max(1, min(window, math.ceil(3 * max(rtt, self._min_rtt()) / tx) + 5))


def backoff_reset(self: _endpoint.Endpoint, packet: Packet, now: float) -> None:
    """Change 4: an ACK of new data clears the backoff."""
    before = self._sender.bytes_acked
    ORIGINAL["_on_ack"](self, packet, now)
    if self._sender.bytes_acked > before:
        self._rtt.backoff = 0


CHANGES: list[tuple[str, type, str, Callable[..., Any]]] = [
    ("nak-ack", S, "on_nak", nak_ack),
    ("nak-now", E, "_on_packet", nak_now),
    ("wider-window", E, "_compute_effective_window", wider_window),
    ("backoff-reset", E, "_on_ack", backoff_reset),
]


def _restore() -> None:
    S.on_nak = ORIGINAL["on_nak"]  # type: ignore[method-assign]
    for name in ("_on_packet", "_compute_effective_window", "_on_ack"):
        setattr(E, name, ORIGINAL[name])


def main() -> None:
    """One line per point: ratio_to_limit with the changes applied cumulatively."""
    names = ["now"] + [f"+{name}" for name, *_ in CHANGES]
    print("virtual time (exact); ratio_to_limit, changes applied cumulatively left to right")
    print("(an asterisk: the transfer did not finish within the benchmark's time cap)")
    print(
        f"{'baud':>5} {'delay':>5} {'errors':>7} {'win':>3} {'len':>4} "
        + "".join(f"{n:>15}" for n in names)
    )
    for p in POINTS:
        cells = []
        _restore()
        for step in range(len(CHANGES) + 1):
            if step:
                _, owner, attr, fn = CHANGES[step - 1]
                setattr(owner, attr, fn)
            r = run_point(p)
            cells.append(f"{r['ratio_to_limit']:.3f}{'' if r['complete'] else '*'}")
        _restore()
        errors = "burst" if p.burst else f"{p.ber:g}"
        print(
            f"{p.baud:>5} {p.delay:>5g} {errors:>7} {p.window:>3} {p.max_len:>4} "
            + "".join(f"{c:>15}" for c in cells),
            flush=True,
        )


if __name__ == "__main__":
    main()
