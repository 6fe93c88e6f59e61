"""The ARQ state machine of :mod:`fuzz.arq_machine`, deep: ``make fuzz`` runs it with
``HYPOTHESIS_PROFILE=deep`` (thousands of examples, fresh randomness each run).

``make test`` runs the same machine with the derandomized CI profile from
tests/serialsocket/test_arq_stateful.py.
"""

from __future__ import annotations

import pytest
from hypothesis import settings

from fuzz.arq_machine import ARQMachine

# 5000 runs of 80 steps take about a quarter of an hour, well past the suite-wide
# pytest-timeout meant for ordinary tests.
pytestmark = pytest.mark.timeout(3600)


class TestARQDeep(ARQMachine.TestCase):  # type: ignore[misc,valid-type]
    """The loaded profile's examples (deep: 5000), with longer runs than in CI: more
    room for a loss, a retransmission, and a second loss of the retransmission."""

    settings = settings(stateful_step_count=80)
