"""The data packet length, measured rather than configured (PROTOCOL.md 4.7).

A packet's header and check are a fixed cost, so longer packets carry more of
the line as data -- until the line damages them: at a byte error rate ``q`` a
packet of ``n`` wire characters arrives intact with probability ``(1 - q)^n``
and the goodput of a length is ``carried(n) / n x (1 - q)^n``.  The best
length is about ``sqrt(overhead / q)``: all of the receive limit on a clean
line, about 384 characters at ``q = 1e-4`` and 96 at ``1e-3`` (the goodput
grid, bench/results/README.md).  Nothing tells the sender ``q``; its own
losses do.  :class:`LengthChooser` keeps the maximum-likelihood estimate --
packets lost per wire character sent, both decayed with a half-life of
:data:`HALF_LIFE` characters so that a line that changes is followed -- and
picks the best length under it.  A few losses are weak evidence: a 8 KiB
transfer at a byte error rate of 1e-4 sees one or two, and their estimate
swings between 0 and 5e-4.  So the estimate starts from
:data:`PRIOR_EXPOSURE` clean characters, and a step up is judged by a
cautious one (a quarter of a loss more, :data:`UP_LOSSES`) while a step down follows
the plain estimate: the goodput curve is flat near its best (within 3 % from
half to twice the best length), steep far from it.

Shorter takes effect at once (every packet at the old length risks the
error rate just measured); longer one step at a time, each step earned by a
packet of the current length acknowledged on its only copy (``clean``), at
most doubling: a line that has shown no loss yet has shown little else, and
a step too far costs the packets sent in one round trip before the losses
say so.  Sans-I/O: the endpoint reports what it sent, lost and got
acknowledged, and asks which length to cut next.

With corrected data packets agreed (PROTOCOL.md section 15) the choice is a
length *and* whether to add sums: a ``d`` packet survives one damaged
character per block (:func:`serialsocket._fec.survival`) for three
characters per block.  Its loss says less about ``q`` (only damage to its
header or check, or two hits in one block, lose it), so its exposure counts
only the characters whose damage it cannot repair at the rate estimated:
the estimate neither collapses while the sums hide the damage nor stays
high long after they stop paying.
"""

from __future__ import annotations

from collections.abc import Callable

from ._fec import survival

__all__ = ["HALF_LIFE", "LADDER", "PRIOR_EXPOSURE", "UP_LOSSES", "LengthChooser"]

LADDER = (96, 128, 192, 256, 384, 512, 768, 1024, 1536, 2048, 3072, 4096, 6144, 9024)
"""The lengths (MARK through CHECK) a measured packet length takes.  96 is the
longest normal packet (LEN up to 94): below it the extended header's three
characters are saved, which is why 96 beats 128 at a byte error rate of 1e-3."""

PRIOR_EXPOSURE = 4096
"""Clean wire characters the estimate starts from: the first loss after 1 KB
says 2e-4, not 1e-3, and two more are needed to say 6e-4."""

UP_LOSSES = 0.25
"""Losses added to the estimate a step up is judged by: with none seen, 128 to
256 at the first clean ACK, 512 after 0.5 KB, 1024 after about 14 KB.  (Half a
loss, 512 after 5 KB and 1024 after 31 KB, left an 8 KiB transfer on a clean
2400 bit/s line at 0.922-0.929 of the line in real time; a quarter,
0.932-0.935.  The goodput hints sweep: without hints 0.968 and 0.950 of the
limit at 1.3 and 20 s, from 0.945 and 0.942 at 36e28c0; exact hints unchanged.)"""

HALF_LIFE = 64 * 1024
"""Wire characters after which a loss counts half: about ten losses' worth of
evidence at a byte error rate of 1e-4, four and a half minutes at 2400 bit/s."""


class LengthChooser:
    """The length of the next data packet, from the losses seen (module docstring).

    Attributes:
        length: the length (MARK through CHECK) to cut new data packets to.
        correcting: new data packets carry sums (``d``, PROTOCOL.md 15):
            set only by :meth:`choose`, and only when given ``corrected``.
        check_length: characters of the block check in force (what sums
            cannot repair includes the check).
    """

    def __init__(self, start: int, check_length: int = 3) -> None:
        self.length = start
        self.correcting = False
        self.check_length = check_length
        self._losses = 0.0
        self._exposure = 0.0

    @property
    def byte_error_rate(self) -> float | None:
        """Packets lost per wire character sent (decayed, from
        :data:`PRIOR_EXPOSURE` clean ones), or None before any was sent."""
        return self._estimate(0.0) if self._exposure > 0 else None

    def _estimate(self, extra_losses: float) -> float:
        return (self._losses + extra_losses) / (self._exposure + PRIOR_EXPOSURE)

    def sent(self, wire_bytes: int, *, corrected: bool = False) -> None:
        """A data packet of ``wire_bytes`` characters went on the line (a
        first send or a resend); ``corrected``: a ``d`` packet, whose
        exposure is the characters it cannot repair (module docstring)."""
        decay = 0.5 ** (wire_bytes / HALF_LIFE)
        self._losses *= decay
        exposure = float(wire_bytes)
        if corrected:
            # The characters whose damage loses it at the rate estimated:
            # (1 - survival) / q, about its header, check and CR.
            q = max(self._estimate(0.0), 1.0 / HALF_LIFE)
            exposure = (1.0 - survival(wire_bytes - 1, q, self.check_length)) / q
        self._exposure = self._exposure * decay + exposure

    def lost(self) -> None:
        """A data packet is being resent: the line lost one (or its ACK)."""
        self._losses += 1.0

    def best(
        self,
        lower: int,
        upper: int,
        carried: Callable[[int], int],
        *,
        extra_losses: float = 0.0,
        corrected: Callable[[int], int] | None = None,
    ) -> tuple[int, bool]:
        """The length in ``lower..upper`` with the best goodput at the estimated
        error rate (with ``extra_losses`` added), and whether with sums:
        ``carried(n)`` is the data characters a packet of ``n`` carries,
        ``corrected(n)`` those of a ``d`` packet (None: sums not agreed).
        The lengths tried: the rungs of :data:`LADDER` in range, and ``upper``."""
        q = self._estimate(extra_losses)
        lengths = [n for n in LADDER if lower <= n < upper] + [upper]

        def goodput(option: tuple[int, bool]) -> float:
            n, sums = option
            if sums and corrected is not None:
                return corrected(n) / (n + 1) * survival(n, q, self.check_length)
            return carried(n) / (n + 1) * (1.0 - q) ** (n + 1)

        options = [(n, False) for n in lengths]
        if corrected is not None:
            options += [(n, True) for n in lengths]
        return max(options, key=goodput)

    def sums_pay(self, plain: int, with_sums: int) -> bool:
        """Whether a packet of ``plain`` characters (MARK through CHECK) is
        better sent as the ``d`` packet of ``with_sums`` carrying the same
        data: more of it arrives per character of line at the estimated
        error rate (a resend's form, PROTOCOL.md 15.5)."""
        q = self._estimate(0.0)
        bare = (1.0 - q) ** (plain + 1) / (plain + 1)
        return survival(with_sums, q, self.check_length) / (with_sums + 1) > bare

    def choose(
        self,
        lower: int,
        upper: int,
        carried: Callable[[int], int],
        *,
        clean: bool,
        corrected: Callable[[int], int] | None = None,
    ) -> int:
        """Set and return :attr:`length`: the best length (:meth:`best`) if it is
        shorter; else, when ``clean`` (a packet of the current length was just
        acknowledged on its only copy) and the cautious estimate's best is
        longer, one step towards that, at most twice the current length; with
        ``lower > upper``, ``upper``.  :attr:`correcting` becomes whether
        sums pay at that length under the plain estimate (never without
        ``corrected``)."""
        lower = min(lower, upper)
        current = min(max(self.length, lower), upper)
        down, _ = self.best(lower, upper, carried, corrected=corrected)
        if down < current:
            current = down
        elif clean:
            target, _ = self.best(
                lower, upper, carried, extra_losses=UP_LOSSES, corrected=corrected
            )
            if target > current:
                current = max(
                    (n for n in (*LADDER, target) if current < n <= min(target, 2 * current)),
                    default=current,
                )
        self.length = current
        self.correcting = (
            corrected is not None and self.best(current, current, carried, corrected=corrected)[1]
        )
        return current
