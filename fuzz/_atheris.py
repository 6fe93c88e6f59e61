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

import operator
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

CORPUS = Path(__file__).parent / "corpus"

_COMPARE = (operator.lt, operator.le, operator.eq, operator.ne, operator.gt, operator.ge)
"""Python's rich comparisons in COMPARE_OP order (the op number atheris passes)."""


def _without_array_leak(native: Callable[..., Any]) -> Callable[..., Any]:
    """atheris's comparison hook, with numpy arrays compared directly.

    atheris 3.0.0's native ``_trace_cmp`` keeps one reference to a comparison
    result that is not a bool, so every elementwise ``array == x`` in
    instrumented code (the codecs compare arrays on every field) leaked the
    result array: fuzz_parser's RSS grew ~14 KB an input and libFuzzer stopped
    at its 2048 MB limit after 141 000 inputs (2026-11-29); replayed without
    atheris, the same inputs hold traced memory flat.  An array comparison
    gives libFuzzer no operands to learn from anyway.
    """

    def trace_cmp(left: object, right: object, op: int, idx: int, const: bool) -> Any:
        if isinstance(left, np.ndarray) or isinstance(right, np.ndarray):
            return _COMPARE[op](left, right)
        return native(left, right, op, idx, const)

    return trace_cmp


def run(one_input: Callable[[bytes], None]) -> None:
    """Hand ``one_input`` to libFuzzer with the command-line flags (never returns).

    atheris binds its native comparison hook when fuzzing starts, so the hook
    is wrapped (:func:`_without_array_leak`) from inside the first input on.
    """
    import atheris

    hook: list[Callable[..., Any]] = []

    def guarded(data: bytes) -> None:
        if not hook or atheris._trace_cmp is not hook[0]:
            hook[:] = [_without_array_leak(atheris._trace_cmp)]
            atheris._trace_cmp = hook[0]
        one_input(data)

    atheris.Setup(sys.argv, guarded)
    atheris.Fuzz()


def corpus_inputs(harness: str) -> list[Path]:
    """The committed (and any locally grown) corpus files of one harness, sorted."""
    folder = CORPUS / harness
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.is_file() and not p.name.startswith("crash-"))
