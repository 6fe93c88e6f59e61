"""A token bucket, sans-I/O: how much a connection may read now, and when it may read more.

The arm's server gives every connection one (``ServerConfig.max_packet_rate``):
the pump reads no more bytes than the bucket holds and, when it is empty,
sleeps until a packet's worth has refilled.  Throttling the *reads* rather
than dropping packets keeps the protocol lossless -- an honest controller that
bursts past the limit is slowed, never loses a command -- and pushes the cost
back to the sender through the transport's own flow control (TCP's window, a
serial socket's advertised window): a flooding peer ends up blocked in its
own ``send``, and the arm spends at most ``rate`` packets' worth of decoding
per second on it.

Hand-written because it is a dozen lines and must run on whatever clock the
caller passes (trio's virtual clock in the tests); the rate-limiting libraries
on PyPI keep their own time or are asyncio-only.
"""

from __future__ import annotations

import math

__all__ = ["TokenBucket"]


class TokenBucket:
    """``rate`` units per second, at most ``burst`` saved up; starts full.

    Times are the caller's clock (seconds, non-decreasing).  A time earlier than
    one already seen is treated as that one, so a clock that steps back never
    mints tokens.
    """

    __slots__ = ("_stamp", "_tokens", "burst", "rate")

    def __init__(self, rate: float, burst: float, now: float) -> None:
        if not (rate > 0 and math.isfinite(rate)):
            raise ValueError(f"rate must be a finite number > 0, got {rate!r}")
        if not (burst >= 1 and math.isfinite(burst)):
            raise ValueError(f"burst must be a finite number >= 1, got {burst!r}")
        self.rate = float(rate)
        self.burst = float(burst)
        self._tokens = self.burst
        self._stamp = now

    def available(self, now: float) -> float:
        """Tokens that may be spent at ``now`` (refilled up to ``burst``)."""
        if now > self._stamp:
            self._tokens = min(self.burst, self._tokens + (now - self._stamp) * self.rate)
            self._stamp = now
        return self._tokens

    def spend(self, amount: float, now: float) -> None:
        """Take ``amount`` tokens.  May go negative (a read returned more than was
        asked of it); the debt is repaid before anything more is allowed."""
        self.available(now)
        self._tokens -= amount

    def wait_for(self, amount: float, now: float) -> float:
        """Seconds from ``now`` until ``amount`` (<= burst) tokens are available; 0 if they are."""
        missing = min(amount, self.burst) - self.available(now)
        return max(0.0, missing / self.rate)
