"""Interop: our Kermit file transfer against C-Kermit and G-Kermit through ``linksim relay``.

Every transfer runs the real programs (Debian's ``ckermit`` and ``gkermit``,
installed by .ci/run) on one pty of an in-process relay and ours on the other,
and compares every received file byte for byte.  The matrix, per peer and per
direction:

* clean line, window 1, 94-character packets (normal packets only);
* 7-bit line (the peer on parity space, ours asking for 8th-bit prefixes),
  window 8, long packets;
* 0.1 s delay each way and a byte error rate of 1e-4, window 8 (G-Kermit has
  no windows, so 1), 1000-character packets (slow: marked so).

The Earth-Moon line (1.3 s one way, 1e-3, 2400 and 9600 bit/s, windows 8 and
16; issue 17 finding 9) is in test_kermit_moon.py, through the command line,
where the exit status is checked against what arrived.

Files: every byte value, long runs of NUL, prefix characters and 0xFE/0xFF,
random binary, and text with CRLF/LF line ends.  They are small (~20 KB) so
the delayed cases stay within a few seconds each.
"""

from __future__ import annotations

import pathlib
import random

import pytest

try:  # linksim's sub-package layout (being committed alongside)
    from linksim.bench._kermit import TransferSetup, available, run_transfer
except ModuleNotFoundError:  # the flat layout before it
    from linksim._bench_kermit import TransferSetup, available, run_transfer  # type: ignore[no-redef]
from serialsocket.kermit import KermitStatistics

_REASON = {
    "ckermit": "ckermit not installed: .ci/run installs it (apt-get install ckermit); "
    "that failed or was not run",
    "gkermit": "gkermit not installed: .ci/run installs it (apt-get install gkermit); "
    "that failed or was not run",
}


def _files(directory: pathlib.Path, size: int) -> list[pathlib.Path]:
    """A binary file (every byte value, long runs, random) and a text file, ~size bytes each."""
    rng = random.Random(size)
    binary = (
        bytes(range(256)) * 4
        + b"\x00" * 500
        + b"#" * 200
        + b"~" * 150
        + b"&" * 100
        + b"\xfe" * 300
        + b"\xff" * 200
        + b"\x01\r\n" * 50
    )
    binary += rng.randbytes(max(0, size - len(binary)))
    words = [b"kermit", b"packet", b"line", b"\r\n", b"\n", b"        ", b"#include", b"~~~~"]
    text = b" ".join(rng.choice(words) for _ in range(size // 6))[:size]
    directory.mkdir()
    paths = [directory / "all-bytes.bin", directory / "notes.txt"]
    for path, data in zip(paths, (binary, text), strict=True):
        path.write_bytes(data)
    return paths


def _transfer(tmp_path: pathlib.Path, setup: TransferSetup, size: int) -> KermitStatistics:
    for peer in (setup.sender, setup.receiver):
        if not available(peer):
            pytest.skip(_REASON[peer])
    files = _files(tmp_path / "src", size)
    out = tmp_path / "out"
    out.mkdir()
    result = run_transfer(setup, files, out)  # raises on failure or on any differing byte
    for f in files:
        assert (out / f.name).read_bytes() == f.read_bytes()
    assert result.ours is not None
    assert result.ours.files == len(files)
    assert result.ours.file_bytes == sum(f.stat().st_size for f in files)
    # Both peers offer repeat counts; the files have long runs.
    assert result.ours.repeat_prefix == "~"
    return result.ours


PAIRS = [
    ("ours", "ckermit"),
    ("ckermit", "ours"),
    ("ours", "gkermit"),
    ("gkermit", "ours"),
]


@pytest.mark.parametrize(("sender", "receiver"), PAIRS)
def test_clean_line_window_1_normal_packets(
    tmp_path: pathlib.Path, sender: str, receiver: str
) -> None:
    setup = TransferSetup(sender=sender, receiver=receiver, window=1, packet_length=94, limit=60)
    stats = _transfer(tmp_path, setup, 20_000)
    assert stats.eighth_bit_prefix is None  # an 8-bit line: no 8th-bit prefixing
    assert (stats.window, stats.packet_length) == (1, 94)


@pytest.mark.parametrize(("sender", "receiver"), PAIRS)
def test_seven_bit_line_uses_8th_bit_prefixing(
    tmp_path: pathlib.Path, sender: str, receiver: str
) -> None:
    setup = TransferSetup(
        sender=sender, receiver=receiver, window=8, packet_length=1000, seven_bit=True, limit=60
    )
    assert _transfer(tmp_path, setup, 20_000).eighth_bit_prefix == "&"


@pytest.mark.slow
@pytest.mark.parametrize(("sender", "receiver"), PAIRS)
def test_delayed_noisy_line_window_8_long_packets(
    tmp_path: pathlib.Path, sender: str, receiver: str
) -> None:
    setup = TransferSetup(
        sender=sender,
        receiver=receiver,
        window=8,
        packet_length=1000,
        delay=0.1,
        byte_error_rate=1e-4,
        timeout=3,
        limit=120,
    )
    # G-Kermit is stop-and-wait (no windows): every 1000-character packet costs
    # a 0.2 s round trip, so it gets smaller files.
    gkermit = "gkermit" in (sender, receiver)
    stats = _transfer(tmp_path, setup, 8_000 if gkermit else 20_000)
    assert stats.window == (1 if gkermit else 8)
