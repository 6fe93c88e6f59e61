"""Every ``--virtual`` run is the same run: two runs, byte-identical output.

Issue 19: eight identical ``linksim demo --virtual --json`` runs gave three
different results, because trio orders tasks woken together with its own
unseeded RNG.  ``linksim.link.run_virtual`` seeds it.
"""

from __future__ import annotations

import pytest

from linksim.bench import run_soak
from linksim.cli import main


def _twice(capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[str, str]:
    outputs = []
    for _ in range(2):
        status = main(argv)
        out, err = capsys.readouterr()
        assert status == 0, err
        outputs.append(out)
    return outputs[0], outputs[1]


@pytest.mark.parametrize("transport", ["serial", "tcp"])
def test_two_virtual_demo_runs_print_identical_json(
    capsys: pytest.CaptureFixture[str], transport: str
) -> None:
    first, second = _twice(capsys, ["demo", "--virtual", "--json", "--transport", transport])
    assert '"ok": true' in first
    assert first == second


def test_two_virtual_console_runs_print_identical_json(
    capsys: pytest.CaptureFixture[str],
) -> None:
    first, second = _twice(capsys, ["console", "--virtual", "--plain", "--json"])
    assert '"ok": true' in first
    assert first == second


def test_two_short_soaks_are_identical() -> None:
    first = run_soak(0.02, seed=5, outage_every=0.01)
    second = run_soak(0.02, seed=5, outage_every=0.01)
    a, b = first.as_dict(), second.as_dict()
    for report in (a, b):  # measured on the host, not in the run
        for key in ("cpu_seconds", "memory_samples"):
            report.pop(key, None)
    assert a == b
