"""linksim bench kermit runs and prints one valid JSON record (needs C-Kermit)."""

from __future__ import annotations

import argparse
import json

import pytest

from linksim.bench import _kermit as _bench_kermit
from linksim.cli import _bench as bench_cli


def _args(*argv: str) -> argparse.Namespace:
    ap = argparse.ArgumentParser()
    bench_cli.add_kermit_arguments(ap)
    return ap.parse_args(list(argv))


@pytest.mark.slow
def test_bench_kermit_emits_json(capsys: pytest.CaptureFixture[str]) -> None:
    if not _bench_kermit.available("ckermit"):
        pytest.skip("ckermit not installed: .ci/run installs it (apt-get install ckermit)")
    args = _args("--size", "20000", "--runs", "1", "--delay", "0.02", "--ber", "0", "--json")
    assert bench_cli.kermit_main(args) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["benchmark"] == "kermit"
    assert record["bytes"] == 20000
    assert [r["pair"] for r in record["results"]] == ["ours->ckermit", "ckermit->ckermit"]
    for r in record["results"]:
        assert r["runs"] == 1
        assert len(r["seconds"]) == 1
        assert r["goodput_Bps"] > 0
        assert r["fixed_seconds"] > 0
    ours = record["results"][0]["ours"]
    assert len(ours) == 1
    assert ours[0]["window"] == 8
    assert ours[0]["packet_length"] == 1000
    assert record["results"][1]["ours"] == []


def test_bench_kermit_rejects_a_bad_pairing(capsys: pytest.CaptureFixture[str]) -> None:
    assert bench_cli.kermit_main(_args("--pairs", "ours->xmodem")) == 2
    assert "bad pairing 'ours->xmodem'" in capsys.readouterr().err
