"""Shared plumbing for the atheris harnesses (``make fuzz`` runs each for a bounded time).

Each harness module defines ``one_input(data: bytes) -> None`` -- the property
under test, raising only on a real finding -- and calls :func:`run` from its
``__main__`` block.  The project's modules are imported inside
``atheris.instrument_imports()`` so that libFuzzer sees coverage of *our* code,
not just the harness.  Without atheris installed (the default test run) the
same ``one_input`` functions replay the committed corpus as plain regression
tests (tests/test_bad_input_fuzz_corpus.py).

Usage: ``python -m fuzz.<harness> [libFuzzer flags] fuzz/corpus/<harness>/``;
``-max_total_time=600`` bounds a run, ``-runs=N`` bounds it by executions.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

CORPUS = Path(__file__).parent / "corpus"


def run(one_input: Callable[[bytes], None]) -> None:
    """Hand ``one_input`` to libFuzzer with the command-line flags (never returns)."""
    import atheris

    atheris.Setup(sys.argv, one_input)
    atheris.Fuzz()


def corpus_inputs(harness: str) -> list[Path]:
    """The committed (and any locally grown) corpus files of one harness, sorted."""
    folder = CORPUS / harness
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.is_file() and not p.name.startswith("crash-"))
