"""The atheris harnesses' properties, replayed on their committed corpora (no atheris needed).

Each harness under fuzz/ raises only on a finding; running its ``one_input``
over every committed seed (and any regression input pinned here) keeps the
properties checked in ``make test`` between fuzzing campaigns.  A crash a
campaign finds is minimised and added to ``PINNED`` with the fix.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from fuzz import fuzz_arq_receive, fuzz_command_packet, fuzz_parser, fuzz_session
from fuzz._atheris import _without_array_leak, corpus_inputs

HARNESSES: dict[str, Callable[[bytes], None]] = {
    "fuzz_parser": fuzz_parser.one_input,
    "fuzz_arq_receive": fuzz_arq_receive.one_input,
    "fuzz_command_packet": fuzz_command_packet.one_input,
    "fuzz_session": fuzz_session.one_input,
}

PINNED: list[tuple[str, bytes]] = [
    # Inputs that once broke a harness's own plumbing (not the stack): kept so the
    # harnesses stay able to express them.
    ("fuzz_arq_receive", bytes.fromhex("190ad32300000000000000370102")),  # SOH in a data field
    # Found by fuzz_parser (2026-11-29), fixed in decode_fields: a token cut at the
    # end of one field and completed by the next (3-byte chunks) was accepted.
    ("fuzz_parser", b"\x00\x80\x08ab#Mcd"),
    ("fuzz_parser", b"\x00\x80\x08ab\x18Acd"),
    # Found by fuzz_parser (2026-11-29), fixed in encode_prefix: a run cut at the
    # end of its slice (capacity 6, two fields).
    ("fuzz_parser", b"\x00\x01\x00abcd\x00\x00\x00\x00\x00"),
    # Found by fuzz_arq_receive (2026-11-29), fixed in Endpoint._autotune: a round
    # trip measured as 0 and two data packets at one instant divided by zero.
    (
        "fuzz_arq_receive",
        bytes.fromhex("1e050080001e050080000000000261620100000102636401"),
    ),
]


@pytest.mark.parametrize("harness", sorted(HARNESSES))
def test_committed_seeds_exist_and_pass(harness: str) -> None:
    seeds = [p for p in corpus_inputs(harness) if p.name.startswith("seed-")]
    assert len(seeds) >= 3
    for path in seeds:
        HARNESSES[harness](path.read_bytes())


@pytest.mark.parametrize(("harness", "data"), PINNED)
def test_pinned_inputs(harness: str, data: bytes) -> None:
    HARNESSES[harness](data)


@pytest.mark.parametrize("harness", sorted(HARNESSES))
def test_harness_survives_edge_inputs(harness: str) -> None:
    for data in (b"", b"\x00", b"\xff" * 3, bytes(range(256)), b"\x01" * 600):
        HARNESSES[harness](data)


def test_keyed_session_harness_detects_a_bypass(monkeypatch: pytest.MonkeyPatch) -> None:
    """The session harness's property can fail: a server that skips the key is caught."""
    monkeypatch.setattr(fuzz_session, "KEY", None)
    with pytest.raises(AssertionError, match="without the key"):
        fuzz_session.one_input(b"\x00\x04\x04\x04\x04")


def test_comparison_hook_keeps_arrays_from_atheris() -> None:
    """atheris 3.0.0's native hook leaks non-bool comparison results (numpy
    arrays): the harnesses' wrapper compares arrays itself, the rest natively."""
    calls: list[tuple[object, object]] = []

    def native(left: object, right: object, op: int, idx: int, const: bool) -> object:
        calls.append((left, right))
        return left == right

    hook = _without_array_leak(native)
    assert hook(np.arange(3), 1, 2, 0, False).tolist() == [False, True, False]
    assert hook(1, np.arange(3), 5, 0, False).tolist() == [True, True, False]
    assert hook(3, 3, 2, 0, False) is True
    assert calls == [(3, 3)]
