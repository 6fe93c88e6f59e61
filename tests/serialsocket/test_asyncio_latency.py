"""``linksim bench latency --client asyncio`` prints the trio client's figures (issue 24).

The asyncio client (tcpstream.asyncio over TCP, or over serialsocket.asyncio on
a pty) against the trio servers in a process of their own; and the trio client
against that same process (``--server process``), the like-for-like
comparison.  Speed is not asserted: this is a benchmark's plumbing.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

TIMEOUT = 120.0
"""A hang guard only: each run takes a few seconds."""


LATENCY = [sys.executable, "-m", "linksim", "bench", "latency"]
SHORT = ["--count", "20", "--warmup", "2"]


def latency(*options: str) -> list[dict[str, object]]:
    done = subprocess.run(
        [*LATENCY, "--json", "--count", "40", "--warmup", "5", *options],
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    reports = json.loads(done.stdout)
    assert isinstance(reports, list)
    return reports


@pytest.mark.parametrize(
    ("options", "client", "server"),
    [
        (["--client", "asyncio"], "asyncio", "process"),
        (["--client", "trio", "--server", "process"], "trio", "process"),
    ],
    ids=["asyncio", "trio-apart"],
)
def test_both_clients_report_the_same_figures(options: list[str], client: str, server: str) -> None:
    reports = latency(*options)
    assert [r["transport"] for r in reports] == ["tcp", "serial"]
    for report in reports:
        assert (report["client"], report["server"]) == (client, server)
        assert report["benchmark"] == "latency"
        assert report["count"] == 40
        assert report["packet_bytes"] == 216
        assert report["authenticated"] is False
        for side in ("command", "raw_echo"):
            figures = report[side]
            assert isinstance(figures, dict)
            assert sorted(figures) == ["mean_us", "min_us", "p50_us", "p99_us"]
            assert 0 < figures["min_us"] <= figures["p50_us"] <= figures["p99_us"]
        assert isinstance(report["p50_ratio"], float)
        assert isinstance(report["target_p50_within_10x"], bool)
        assert isinstance(report["target_p99_under_2ms"], bool)


def test_the_asyncio_client_with_a_key_and_its_text_report() -> None:
    done = subprocess.run(
        [*LATENCY, "--client", "asyncio", "--transport", "serial", "--key", *SHORT],
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "a serial socket on a raw pty (20 round trips, 216-byte packets, with HMAC tags)" in (
        done.stdout
    )
    assert "client: asyncio; arm and echo servers (trio) in a process of their own" in done.stdout
    assert "tcpstream STATUS : p50" in done.stdout
    assert "raw pty echo     : p50" in done.stdout


def test_the_asyncio_client_cannot_share_the_trio_loop() -> None:
    done = subprocess.run(
        [*LATENCY, "--client", "asyncio", "--server", "loop"],
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
        check=False,
    )
    assert done.returncode == 2
    assert done.stderr.strip() == (
        "linksim bench latency: --server loop needs the trio client (the servers are trio); "
        "the asyncio client uses --server process"
    )
