"""Interop, issue 23: recovery, names, text mode and attributes against C-Kermit and G-Kermit.

Through an in-process ``linksim relay`` (with delay and byte errors where the
case says so), as test_kermit_interop.py does; the real programs are
Debian's ``kermit`` (C-Kermit 10.0) and ``gkermit`` (G-Kermit 2.01).  Each
case skips, saying why, when its program is absent.

* Recovery: a transfer is killed once the receiver holds about half the file,
  then resumed with RESEND (ours ``--resend``, C-Kermit ``resend``); the file
  ends byte-identical and only the remainder crossed the line.  G-Kermit has
  no RESEND (its CAPAS lacks 16), so ours sends it the whole file.
* Names: both sides at the Kermit default (names converted): a name goes out
  in common form and arrives lower-cased.
* Text mode: line ends travel as CR LF and arrive as LF, both ways; the
  counters show the CRs on the wire.
* Attributes: the date (C-Kermit sends one; ours sets the file's mtime to it).
"""

from __future__ import annotations

import dataclasses
import datetime
import os
import pathlib
import random

import pytest

from linksim.bench._kermit import TransferSetup, available, run_interrupted, run_transfer

_REASON = {
    "ckermit": "ckermit not installed: .ci/run installs it (apt-get install ckermit)",
    "gkermit": "gkermit not installed: .ci/run installs it (apt-get install gkermit)",
}
SIZE = 60_000
"""Bytes in the recovery file: about 5 s at 115200 bit/s, so the cut lands mid-way."""


def _need(*peers: str) -> None:
    for peer in peers:
        if not available(peer):
            pytest.skip(_REASON[peer])


def _dirs(tmp_path: pathlib.Path) -> tuple[pathlib.Path, pathlib.Path]:
    src, out = tmp_path / "src", tmp_path / "out"
    src.mkdir()
    out.mkdir()
    return src, out


# -- recovery --------------------------------------------------------------------


@pytest.mark.parametrize(("sender", "receiver"), [("ours", "ckermit"), ("ckermit", "ours")])
def test_killed_transfer_resumes_with_resend_and_sends_only_the_rest(
    tmp_path: pathlib.Path, sender: str, receiver: str
) -> None:
    _need("ckermit")
    src, out = _dirs(tmp_path)
    data = random.Random(23).randbytes(SIZE)
    path = src / "big.bin"
    path.write_bytes(data)
    setup = TransferSetup(
        sender=sender,
        receiver=receiver,
        window=8,
        packet_length=1000,
        delay=0.02,
        byte_error_rate=1e-5,
        rate=115_200,
        timeout=2,
        limit=60,
        seed=4,
    )
    held, result = run_interrupted(setup, path, out, cut=SIZE // 2)
    assert SIZE // 4 < held < SIZE, held  # really cut part-way
    assert (out / "big.bin").read_bytes() == data  # checked by run_interrupted too
    assert not list(out.glob("*.part"))
    ours = result.ours
    assert ours is not None
    # Only the remainder crossed the line; the rest counts as held.
    assert ours.resumed_bytes == held
    assert ours.file_bytes == SIZE - held
    if sender == "ours":
        assert ours.acknowledged_bytes == SIZE


def test_resend_to_g_kermit_sends_the_whole_file(tmp_path: pathlib.Path) -> None:
    _need("gkermit")
    src, out = _dirs(tmp_path)
    path = src / "g.bin"
    path.write_bytes(random.Random(5).randbytes(5000))
    (out / "g.bin").write_bytes(path.read_bytes()[:1000])  # a partial file, ignored
    setup = TransferSetup(sender="ours", receiver="gkermit", window=1, resend=True, limit=60)
    result = run_transfer(setup, [path], out)
    assert result.ours is not None
    assert (result.ours.resumed_bytes, result.ours.file_bytes) == (0, 5000)


# -- names -----------------------------------------------------------------------------


NAME_PEERS = [
    ("ours", "ckermit"),
    ("ckermit", "ours"),
    ("ours", "gkermit"),
    ("gkermit", "ours"),
]


@pytest.mark.parametrize(("sender", "receiver"), NAME_PEERS)
def test_names_go_in_common_form_and_arrive_lower_cased(
    tmp_path: pathlib.Path, sender: str, receiver: str
) -> None:
    _need(*(p for p in (sender, receiver) if p != "ours"))
    src, out = _dirs(tmp_path)
    path = src / "Data.File.bin"
    path.write_bytes(bytes(range(256)) * 4)
    setup = TransferSetup(sender=sender, receiver=receiver, window=1, literal_names=False, limit=60)
    run_transfer(setup, [path], out)
    assert [p.name for p in out.iterdir()] == ["data_file.bin"]
    assert (out / "data_file.bin").read_bytes() == path.read_bytes()


# -- text mode --------------------------------------------------------------------------


TEXT = b"".join(b"line %d: kermit text\n" % i for i in range(800)) + b"last line, no newline"
LINES = TEXT.count(b"\n")


@pytest.mark.parametrize(("sender", "receiver"), NAME_PEERS)
def test_text_mode_converts_line_ends_both_ways(
    tmp_path: pathlib.Path, sender: str, receiver: str
) -> None:
    _need(*(p for p in (sender, receiver) if p != "ours"))
    src, out = _dirs(tmp_path)
    path = src / "notes.txt"
    path.write_bytes(TEXT)
    setup = TransferSetup(
        sender=sender,
        receiver=receiver,
        window=1 if "gkermit" in (sender, receiver) else 8,
        text=True,
        delay=0.02,
        byte_error_rate=1e-5,
        limit=60,
    )
    result = run_transfer(setup, [path], out)
    assert (out / "notes.txt").read_bytes() == TEXT  # LF here, LF there
    ours = result.ours
    assert ours is not None
    # CR LF on the wire: one more byte per line than the file holds.
    assert ours.file_bytes == len(TEXT) + LINES


# -- attributes: the date -----------------------------------------------------------------


@pytest.mark.parametrize(("sender", "receiver"), [("ours", "ckermit"), ("ckermit", "ours")])
def test_the_date_attribute_sets_the_modification_time(
    tmp_path: pathlib.Path, sender: str, receiver: str
) -> None:
    _need("ckermit")
    src, out = _dirs(tmp_path)
    path = src / "dated.bin"
    path.write_bytes(b"x" * 3000)
    when = datetime.datetime(2024, 2, 29, 13, 14, 15).timestamp()
    os.utime(path, (when, when))
    setup = TransferSetup(sender=sender, receiver=receiver, window=8, limit=60)
    run_transfer(setup, [path], out)
    assert (out / "dated.bin").stat().st_mtime == when


# -- FORCE-3 ---------------------------------------------------------------------------------


@pytest.mark.parametrize(("sender", "receiver"), [("ours", "ckermit"), ("ckermit", "ours")])
def test_force3_with_c_kermit(tmp_path: pathlib.Path, sender: str, receiver: str) -> None:
    """C-Kermit's SET BLOCK-CHECK 5 on its side, ours --check 5 as sender: a
    CRC-16 on every packet, S and its ACK included."""
    _need("ckermit")
    src, out = _dirs(tmp_path)
    path = src / "f3.bin"
    path.write_bytes(random.Random(3).randbytes(20_000))
    setup = TransferSetup(
        sender=sender,
        receiver=receiver,
        window=8,
        force3=sender == "ours",
        extra_ckermit=("set block-check 5",),
        delay=0.02,
        byte_error_rate=1e-5,
        limit=60,
    )
    result = run_transfer(setup, [path], out)
    assert result.ours is not None
    assert result.ours.check == 3
    # The CRC-checked S was read (else nothing would have moved) and CRC-16
    # is in force.


# -- streaming ---------------------------------------------------------------------------------


@pytest.mark.parametrize(("sender", "receiver"), NAME_PEERS)
def test_streaming_on_a_clean_line(tmp_path: pathlib.Path, sender: str, receiver: str) -> None:
    """C-Kermit (``set reliable on``, ``set streaming on``) and G-Kermit (its
    default) stream with ours when both offer it: no ACK per D packet."""
    _need(*(p for p in (sender, receiver) if p != "ours"))
    src, out = _dirs(tmp_path)
    path = src / "stream.bin"
    path.write_bytes(random.Random(9).randbytes(200_000))
    setup = TransferSetup(sender=sender, receiver=receiver, window=8, streaming=True, limit=60)
    result = run_transfer(setup, [path], out)
    ours = result.ours
    assert ours is not None
    # S, F, A, Z, B: the only packets answered (ours as sender) or sent (ours as receiver).
    if sender == "ours":
        assert ours.packets_received == 5, ours
    else:
        assert ours.packets_sent == 5, ours
    assert (ours.naks_sent, ours.naks_received, ours.timeouts) == (0, 0, 0)


# -- PSEND ---------------------------------------------------------------------------------------


def test_c_kermit_psend_to_ours_delivers_the_part_from_the_offset(tmp_path: pathlib.Path) -> None:
    _need("ckermit")
    src, out = _dirs(tmp_path)
    data = random.Random(11).randbytes(10_000)
    path = src / "part.bin"
    path.write_bytes(data)
    setup = TransferSetup(sender="ckermit", receiver="ours", window=8, limit=60)
    setup = dataclasses.replace(setup, extra_ckermit=(f"psend {path} 3000", "exit \\v(status)"))
    run_transfer(dataclasses.replace(setup, literal_names=False), [path], out)
    assert (out / "part.bin").read_bytes() == data[3000:]
