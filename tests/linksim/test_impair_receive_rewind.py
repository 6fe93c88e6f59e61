"""Regression: a receive at a time a hair earlier than the last one delivers nothing twice.

An in-memory link reader woken by its timer asks for the target time; its
next call asks for the clock, which can round just below that target.  The
delivery queue used to rewind to the earlier index and hand the same bytes
out again (duplicated bytes on a clean rate-limited line: the moon preset's
conformance check failed with corrupted packets and, at last, a dead link).
"""

from __future__ import annotations

from linksim import DirectionConfig
from linksim.link import LinkDirection


def test_receive_with_a_slightly_earlier_now_does_not_repeat_bytes() -> None:
    line = LinkDirection(DirectionConfig(rate=9600, delay=1.3), seed=0)
    line.send(b"abcdefgh", 0.0)
    t4 = 1.3 + 4 * 10 / 9600  # the 4th byte arrives exactly now
    assert line.receive(t4) == b"abcd"
    assert line.receive(t4 - 1e-12) == b""  # the clock rounded below the target
    assert line.receive(t4 + 1.0) == b"efgh"
    assert line.statistics().bytes_delivered == 8
