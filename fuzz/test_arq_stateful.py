"""The ARQ state machine of :mod:`fuzz.arq_machine`, deep: ``make fuzz`` runs it with
``HYPOTHESIS_PROFILE=deep`` (thousands of examples, fresh randomness each run).

``make test`` runs the same machine with the derandomized CI profile from
tests/serialsocket/test_arq_stateful.py.

Below it, deterministic runs of the machine that impair the first connection
request on purpose (duplicated, delayed, dropped, its answer dropped): the
early data it carries (PROTOCOL.md section 13) must arrive exactly once.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import settings

from fuzz.arq_machine import (
    DEFAULT_EARLY_DATA,
    LINGER,
    LIVENESS_TIMEOUT,
    MAX_EARLY_DATA,
    ARQMachine,
    Chunk,
)
from serialsocket import EndpointConfig, LocalProtocolError

# 5000 runs of 80 steps take about a quarter of an hour, well past the suite-wide
# pytest-timeout meant for ordinary tests.
pytestmark = pytest.mark.timeout(3600)


class TestARQDeep(ARQMachine.TestCase):  # type: ignore[misc,valid-type]
    """The loaded profile's examples (deep: 5000), with longer runs than in CI: more
    room for a loss, a retransmission, and a second loss of the retransmission."""

    settings = settings(stateful_step_count=80)


# -- early data through a resent, duplicated or delayed init ---------------------------


class _CountingMachine(ARQMachine):
    """The machine, counting the init copies that reach B."""

    def __init__(self) -> None:
        super().__init__()
        self.inits_delivered = 0

    def _deliver_head(self, direction: str) -> None:
        if direction == "ab" and self.lines[direction].chunks[0].data[3:4] == b"I":
            self.inits_delivered += 1
        super()._deliver_head(direction)


DELAY, RATE = 1.3, 2400.0


def _config(**overrides: Any) -> EndpointConfig:
    """A Moon-like line (1.3 s, 2400 bit/s) with the machine's liveness settings."""
    base: dict[str, Any] = {
        "one_way_delay": DELAY,
        "line_rate": RATE,
        "dead_after": LIVENESS_TIMEOUT,
        "connect_timeout": LIVENESS_TIMEOUT,
        "linger": LINGER,
        "send_buffer": 4096,
    }
    return EndpointConfig(**(base | overrides))


def _run_until(machine: ARQMachine, done: Callable[[], bool]) -> None:
    for _ in range(1000):
        if done():
            return
        assert machine._advance(), "nothing pending"
        machine.check_all()
    raise AssertionError("never happened")


def _duplicate_init(m: ARQMachine) -> None:
    first = m.lines["ab"].chunks[0]
    m.lines["ab"].chunks.insert(1, Chunk(first.arrival, first.data))


def _delay_init(m: ARQMachine) -> None:
    # Past A's init timer: A resends, and B gets the delayed copy, then the resend.
    line = m.lines["ab"]
    line.chunks[0].arrival += 10.0
    line.restore_order(0)


def _drop_init(m: ARQMachine) -> None:
    del m.lines["ab"].chunks[0]


def _drop_answer(m: ARQMachine) -> None:
    # B accepts (and delivers) at the first copy; its answer is lost, A resends,
    # and B, ESTABLISHED, answers the copy again.
    _run_until(m, lambda: bool(m.lines["ba"].chunks))
    del m.lines["ba"].chunks[0]


def _everything(m: ARQMachine) -> None:
    # Two copies, both delayed past A's init timer (A resends), more bytes
    # queued while connecting, the first answer lost: B reads three copies, the
    # last two while ESTABLISHED.
    _duplicate_init(m)
    _delay_init(m)
    assert m.ep["a"].send(b" and then more", m.now) == 14
    m.sent["a"] += b" and then more"
    _drop_answer(m)


_SCENARIOS: dict[str, tuple[Callable[[ARQMachine], None], int]] = {
    "duplicate": (_duplicate_init, 2),
    "delay": (_delay_init, 2),
    "drop": (_drop_init, 1),
    "drop_answer": (_drop_answer, 2),
    "everything": (_everything, 3),
}
"""Each impairment of the first init, and the init copies B then reads."""


@pytest.mark.parametrize("scenario", sorted(_SCENARIOS))
@pytest.mark.parametrize(
    ("early", "taken"),
    [
        (b"MOVE 1 2 3", 10),
        # More than fits: the init takes what its XEARLY field holds, half a
        # 128-character packet (62 characters: 34 of these bytes); the rest is data.
        (random.Random(1).randbytes(2000), 34),
    ],
    ids=["short", "long"],
)
@pytest.mark.parametrize(
    "listener",
    [{"early_data": DEFAULT_EARLY_DATA}, {"early_data": 0}, {"expedited": False}],
    ids=["takes", "takes-none", "no-xlanes"],
)
def test_early_data_is_delivered_once_whatever_happens_to_the_init(
    scenario: str, early: bytes, taken: int, listener: dict[str, Any]
) -> None:
    impair, copies = _SCENARIOS[scenario]
    m = _CountingMachine()
    configs = {"a": _config(early_data=MAX_EARLY_DATA), "b": _config(**listener)}
    m.start(configs, one_way_delay=DELAY, line_rate=RATE, early=early)
    assert m.sent["a"] == early
    impair(m)
    m.check_all()
    m.finish()  # Heals, closes, and checks both streams arrived exactly once.
    assert m.inits_delivered == copies
    sa, sb = m.ep["a"].statistics(), m.ep["b"].statistics()
    assert sa.early_sent == taken  # A cannot know whether B takes them.
    delivered = taken if listener.get("early_data") else 0  # The other two take none.
    assert (sa.early_delivered, sb.early_received) == (delivered, delivered)
    assert bytes(m.received["b"]) == bytes(m.sent["a"])
    assert bytes(m.received["b"]).startswith(early)


def test_the_fuzzers_early_data_bound_is_the_configs() -> None:
    EndpointConfig(early_data=MAX_EARLY_DATA)
    with pytest.raises(LocalProtocolError, match="early_data"):
        EndpointConfig(early_data=MAX_EARLY_DATA + 1)
