"""``linksim bench transfer``: the limit it prints, the rows it reads, one real
transfer delivered (correctness only: no wall-clock figure is asserted)."""

from __future__ import annotations

import json
import random
import subprocess
import sys
from typing import Any

import pytest

from linksim.bench import TRANSFER_ROWS, TransferRow, parse_transfer_row
from linksim.bench import _line_table as table
from linksim.bench._transfer import limit_goodput
from linksim.cli import _bench as bench_cli
from linksim.cli import main
from serialsocket.packets import EIGHT_BIT_CLEAN, PRINTABLE

MOON_1E4 = TRANSFER_ROWS[2]  # 2400/1.3/1e-4/auto
PRINTABLE_1E4 = TRANSFER_ROWS[5]  # 2400/1.3/1e-4/printable


def _payload(row: TransferRow, seed: int = 1) -> bytes:
    return random.Random(seed).randbytes(row.default_size)


# -- the limit -------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("row", "encoding"), [(MOON_1E4, EIGHT_BIT_CLEAN), (PRINTABLE_1E4, PRINTABLE)]
)
def test_limit_is_goodput_s_for_a_classic_peer(row: TransferRow, encoding: object) -> None:
    """With the dense encodings and the sums off, the limit is limit_goodput's,
    to the last bit: the same definitions, only the agreed encoding differs."""
    payload = _payload(row)
    classic = table.line_limit(row, payload, dense=False, correction=False)
    assert classic.encoding == "prefix"
    goodput, p_hit = limit_goodput(
        payload,
        rate=row.rate,
        max_len=classic.max_packet_length,
        encoding=encoding,  # type: ignore[arg-type]
        byte_error_rate=row.ber,
    )
    assert classic.share == pytest.approx(goodput / (row.rate / 10), rel=1e-12)
    assert classic.packet_error == p_hit


def test_limit_on_a_printable_line_is_radix_91_at_the_best_length() -> None:
    limit = table.line_limit(PRINTABLE_1E4, _payload(PRINTABLE_1E4))
    # The sender measures its packet length (serialsocket/PROTOCOL.md 4.7):
    # the limit is the best length it may choose, 384 at 1e-4 -- or, with
    # sums that repair one damaged character per block (15), 1024.
    assert (limit.encoding, limit.max_packet_length, limit.check) == (
        "radix-91+sums",
        1024,
        "CRC16",
    )
    plain = table.line_limit(PRINTABLE_1E4, _payload(PRINTABLE_1E4), correction=False)
    assert (plain.encoding, plain.max_packet_length) == ("radix-91", 384)
    assert plain.share < limit.share
    assert limit.share == limit.carried / limit.wire * (1 - limit.packet_error)
    # At 128, an extended-length packet: 7 header characters, room for 118
    # data characters of which radix 91 fills 117 (7 blocks of 13 bytes in 16
    # characters, a 4-byte tail in 5: 95 bytes), 3 CRC characters and the
    # EOL: 128 on the line.  The best length does better.
    assert limit.share > 95 / 128 * (1 - 1e-4) ** 128


def test_limit_on_an_8_bit_line_is_the_escape_code() -> None:
    payload = _payload(MOON_1E4)
    dense = table.line_limit(MOON_1E4, payload)
    classic = table.line_limit(MOON_1E4, payload, dense=False)
    assert (dense.encoding, dense.max_packet_length, dense.check) == ("escape+sums", 1024, "CRC16")
    assert dense.share == dense.carried / dense.wire * (1 - dense.packet_error)
    # Escaping costs about 1 % on random binary where Kermit prefixing costs
    # 27 %; the sums 12 characters of 1024, and a loss in 400 packets.
    assert 1.0 < dense.wire / dense.carried < 1.05
    assert 0.95 < dense.share < 0.98
    assert classic.share < dense.share
    clean = table.line_limit(TRANSFER_ROWS[0], _payload(TRANSFER_ROWS[0]))
    assert clean.packet_error == 0.0
    assert clean.share == clean.carried / clean.wire


def test_limit_is_at_the_best_length_whatever_the_hints() -> None:
    """9600 bit/s, 1.3 s, 1e-3: the packets start at 128 without hints and 256
    with them (31 packets of 128 cannot cover a repair), but the length is
    measured, and the best at 1e-3 is 384 with sums (96, the longest normal
    packet, without them); on a clean line, the whole receive limit."""
    row = TRANSFER_ROWS[4]
    payload = _payload(row)
    plain = table.line_limit(row, payload)
    hinted = table.line_limit(row, payload, hints=True)
    assert plain == hinted
    assert (plain.encoding, plain.max_packet_length) == ("escape+sums", 384)
    assert table.line_limit(row, payload, correction=False).max_packet_length == 96
    clean = table.line_limit(TRANSFER_ROWS[0], _payload(TRANSFER_ROWS[0]))
    assert clean.max_packet_length == 1024
    assert plain.share < clean.share < 1


def test_limit_needs_a_payload() -> None:
    with pytest.raises(ValueError, match="cannot be empty"):
        table.line_limit(MOON_1E4, b"")


# -- the rows ----------------------------------------------------------------------------


def test_every_row_reads_back_from_its_number_and_its_spec() -> None:
    assert [r.target for r in TRANSFER_ROWS] == [0.93, 0.85, 0.80, 0.65, 0.60, 0.70]
    for number, row in enumerate(TRANSFER_ROWS, 1):
        assert parse_transfer_row(str(number)) is row
        assert parse_transfer_row(row.spec) is row
    assert MOON_1E4.spec == "2400/1.3/1e-4/auto"


@pytest.mark.parametrize(
    "spec", ["2400/1.3/0.0001/auto", "2400/1.3/1e-4", " 2400/1.30/1E-4/auto ", "3"]
)
def test_a_spec_names_the_issue_row_whatever_the_spelling(spec: str) -> None:
    assert parse_transfer_row(spec) is MOON_1E4


def test_a_line_outside_the_table_has_no_target() -> None:
    assert parse_transfer_row("9600/0/0") == TransferRow(9600, 0.0, 0.0, "auto", None)
    assert parse_transfer_row("2400/1.3/1e-4/8bit") == TransferRow(2400, 1.3, 1e-4, "8bit")
    assert parse_transfer_row("2400/1.3/1e-4/8bit").default_size == 8192
    assert parse_transfer_row("9600/0/0").default_size == 32768


@pytest.mark.parametrize(
    ("spec", "words"),
    [
        ("0", "no row 0"),
        ("7", "no row 7"),
        ("", "give a row number 1..6"),
        ("x", "give a row number 1..6"),
        ("2400/1.3", "RATE/DELAY/BER[/PROFILE]"),
        ("2400/1.3/0/auto/x", "RATE/DELAY/BER[/PROFILE]"),
        ("2400.5/1/0", "RATE/DELAY/BER[/PROFILE]"),
        ("0/1/0", "RATE must be"),
        ("2400/-1/0", "DELAY must be"),
        ("2400/nan/0", "DELAY must be"),
        ("2400/1/2", "BER must be"),
        ("2400/1/nan", "BER must be"),
        ("2400/1/0/bogus", "PROFILE must be one of auto, 8bit, printable"),
    ],
)
def test_a_bad_row_is_refused_saying_what_is_accepted(spec: str, words: str) -> None:
    with pytest.raises(ValueError, match=words.replace("[", r"\[").replace("]", r"\]")):
        parse_transfer_row(spec)


def test_bad_rows_option_is_one_argparse_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["bench", "transfer", "--rows", "1", "2400/x/0"])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.splitlines()[-1] == (
        "linksim bench transfer: error: argument --rows: '2400/x/0': give a row number "
        "1..6 or RATE/DELAY/BER[/PROFILE], e.g. 2400/1.3/1e-4/auto"
    )


def test_the_command_passes_the_chosen_rows_and_fails_when_one_did(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Rows are numbered when they are the issue's, duplicates run once, and the
    exit status is 1 as soon as one transfer did not deliver."""
    calls: list[dict[str, Any]] = []

    def fake(rows: Any, seeds: Any, **kwargs: Any) -> list[dict[str, Any]]:
        calls.append({"rows": rows, "seeds": seeds, **kwargs})
        records = [{"ok": True}, {"ok": len(calls) == 1}]
        for record in records:
            kwargs["on_row"]({"row": 1, "ok": record["ok"]})
        return records

    monkeypatch.setattr(bench_cli, "run_transfer_table", fake)
    argv = ["bench", "transfer", "--json", "--rows", "3", "9600/0/0", "2400/1.3/0.0001"]
    assert main([*argv, "--seeds", "2", "2", "5", "--size", "512", "--jobs", "2"]) == 0
    assert calls[0]["rows"] == [(3, MOON_1E4), (None, TransferRow(9600, 0.0, 0.0))]
    assert calls[0]["seeds"] == [2, 5]
    assert (calls[0]["size"], calls[0]["jobs"], calls[0]["hints"]) == (512, 2, False)
    assert [json.loads(line)["ok"] for line in capsys.readouterr().out.splitlines()] == [
        True,
        True,
    ]
    assert main(["bench", "transfer", "--json", "--hints"]) == 1
    assert calls[1]["rows"] == list(enumerate(TRANSFER_ROWS, 1))
    assert (calls[1]["seeds"], calls[1]["size"], calls[1]["jobs"]) == ([1], None, None)
    assert calls[1]["hints"] is True


# -- running ------------------------------------------------------------------------------


def test_one_small_transfer_delivers(capsys: pytest.CaptureFixture[str]) -> None:
    """512 bytes at 9600 bit/s on a clean line: the real relay and netcat."""
    status = main(["bench", "transfer", "--rows", "9600/0/0", "--size", "512", "--json"])
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 1
    row = json.loads(lines[0])
    assert status == 0, row
    assert row["ok"] is True, row
    assert (row["row"], row["spec"], row["target"], row["meets_target"]) == (
        None,
        "9600/0/0/auto",
        None,
        None,
    )
    assert (row["bytes"], row["seed"], row["connect_exit"], row["listen_exit"]) == (512, 1, 0, 0)
    assert (row["encoding"], row["check"]) == ("escape", "CRC16")
    assert 128 <= row["max_packet_len"] <= 1024
    assert 0 < row["limit_share"] < 1
    assert row["line_share"] > 0
    assert row["ratio_to_limit"] == pytest.approx(row["line_share"] / row["limit_share"], abs=2e-3)
    assert row["wire_bytes_sent"] > 512
    assert row["retransmissions"] == 0
    assert "error" not in row


def test_a_relay_that_fails_makes_a_failed_row(monkeypatch: pytest.MonkeyPatch) -> None:
    """Nothing ran: the row says why, and the command's status would be 1."""
    monkeypatch.setattr(
        table, "_python", lambda *args: [sys.executable, "-c", "import sys; sys.exit(3)"]
    )
    record = table.run_row(parse_transfer_row("9600/0/0"), 1, size=64)
    assert record["ok"] is False
    assert record["error"] == "the relay exited (status 3) before its ptys"
    assert (record["seconds"], record["line_share"], record["connect_exit"]) == (None, None, None)


def test_killing_the_table_kills_its_children_and_refuses_new_ones() -> None:
    children = table._Children()
    sleeper = children.start(
        [sys.executable, "-c", "import time; time.sleep(60)"], stdin=subprocess.DEVNULL
    )
    children.kill_all()
    assert sleeper.wait(timeout=10) != 0
    children.reap(sleeper)
    with pytest.raises(table._RowFailed, match="cancelled"):
        children.start([sys.executable, "-c", "pass"])
