"""``serialsocket listen|connect``: a netcat over real ptys through ``linksim relay``.

Everything runs as subprocesses, as a user runs it; each wait has a generous
timeout that only stops a hang.  The side that waits for a call is known to
be ready when it waits for input on its tty (seen in /proc: see
:func:`~tests.serialsocket.test_kermit_cli.wait_until_reading`), not after a
fixed sleep.
"""

from __future__ import annotations

import json
import os
import pathlib
import random
import select
import signal
import subprocess
import sys
from collections.abc import Iterator

import pytest

from .test_kermit_cli import wait_until_reading

GUARD = 60.0


@pytest.fixture
def relay() -> Iterator[tuple[str, str]]:
    """A clean ``linksim relay`` (2 ms each way); yields the two tty paths."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "linksim", "relay", "--json", "--delay", "0.002"],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        paths = json.loads(proc.stdout.readline())
        yield paths["a"], paths["b"]
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=GUARD) == 0


def _reap(proc: subprocess.Popen[bytes]) -> None:
    """Kill ``proc`` if it is still running (a failed or hung test) and wait for it."""
    if proc.poll() is None:
        proc.kill()
    proc.wait(timeout=GUARD)


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "serialsocket", *args]


def test_files_both_ways_byte_exact_and_clean_exit(
    relay: tuple[str, str], tmp_path: pathlib.Path
) -> None:
    a, b = relay
    upload = random.Random(5).randbytes(60_000) + bytes(range(256)) * 20
    download = b"arm telemetry\r\n\x00\x01\x03\x11\x13\xff" * 2000
    (tmp_path / "up").write_bytes(upload)
    (tmp_path / "down").write_bytes(download)
    with (tmp_path / "down").open("rb") as down_in:
        server = subprocess.Popen(
            cli("listen", b, "--delay", "0.002", "--dead-after", "60", "--stats"),
            stdin=down_in,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
    try:
        wait_until_reading(server, b)  # its port is open (a connect retries anyway)
        with (tmp_path / "up").open("rb") as up_in:
            client = subprocess.run(
                # The connect's derived timeout is ~0.5 s: on a busy machine
                # give it time anyway.
                cli(
                    "connect",
                    a,
                    "--delay",
                    "0.002",
                    "--window",
                    "8",
                    "--trace",
                    "--connect-timeout",
                    "30",
                    "--dead-after",
                    "60",
                    "--json",
                ),
                stdin=up_in,
                capture_output=True,
                timeout=GUARD,
            )
        got_up, server_err = server.communicate(timeout=GUARD)
    finally:
        _reap(server)
    assert client.returncode == 0, client.stderr[-2000:]
    assert server.returncode == 0, server_err
    assert got_up == upload
    assert client.stdout == download
    trace = client.stderr.decode()
    # The connect request (--window 8: no long-sequence offer; XCAPAS offers the
    # dense encodings, PROTOCOL.md section 10) and the escape code on this 8N1 pty.
    # Five characters more: XFLIGHT, the first flight's announcement (PROTOCOL.md 14).
    assert "tx I seq=0 len=40" in trace
    assert "#Y5" in trace  # QBIN Y: --profile auto took the 8-bit profile from the port
    assert "rx Y seq=0" in trace  # its answer
    # The first flight: twice the starting length, on the line before the answer.
    assert trace.index("tx D seq=1 len=256") < trace.index("rx Y seq=0")
    assert "undecodable" not in trace
    # --json: the counters at the end, on stderr (stdout is the data).
    record = json.loads(trace.splitlines()[-1])
    assert record["outcome"] == "delivered"
    assert record["stdin_bytes_read"] == record["bytes_acknowledged"] == len(upload)
    assert record["stdout_bytes_written"] == len(download)
    assert record["peer_eof"] is True
    assert record["bytes_in_flight"] == 0
    assert record["payload_sent_Bps"] > 0
    # A clean line: nothing is resent.  (Idle copies may go: once the pair
    # measures this pty's rate, its 2 ms round trip is many packet times.)
    assert record["doubled_resends"] == 0
    # The first flight went, and the listener (the same profile) took it.
    assert record["flight_packets"] > 0
    assert record["flight_refused"] == 0
    assert record["idle_copies"] >= 0
    # --stats: the same in words.
    stats = server_err.decode().splitlines()[-1]
    assert stats.startswith("serialsocket listen: outcome delivered, connected True")
    assert f"stdout_bytes_written {len(upload)}" in stats


def test_an_unanswered_request_is_reported_as_connect_reports_it(
    relay: tuple[str, str],
) -> None:
    # The netcat connects on its first write (a deferred request, so its
    # first bytes fly behind it): the request's failure reaches a read or a
    # write, and is still said as a plain connect says it, with no transfer
    # report (nothing was connected).
    a, _ = relay
    done = subprocess.run(
        cli("connect", a, "--connect-timeout", "1", "--json"),
        input=b"hello",
        capture_output=True,
        timeout=GUARD,
    )
    assert done.returncode == 1
    lines = done.stderr.decode().splitlines()
    assert lines[-2].startswith("serialsocket connect: no answer to connect within 1.0 s: ")
    assert json.loads(lines[-1]) == {"outcome": "failed", "connected": False}


def test_errors_are_reported_with_exit_status() -> None:
    missing = subprocess.run(
        cli("connect", "/dev/no-such-tty-telelink"), capture_output=True, timeout=GUARD
    )
    assert missing.returncode == 1
    assert b"check the path and its permissions" in missing.stderr
    reported = subprocess.run(
        cli("connect", "/dev/no-such-tty-telelink", "--json"), capture_output=True, timeout=GUARD
    )
    assert reported.returncode == 1
    last = reported.stderr.decode().splitlines()[-1]
    assert json.loads(last) == {"outcome": "failed", "connected": False}
    bad = subprocess.run(
        cli("connect", "loop://", "--window", "40"), capture_output=True, timeout=GUARD
    )
    assert bad.returncode == 2
    assert b"argument --window: must be an integer in 1..31, got '40'" in bad.stderr


def test_dial_and_answer_through_emulated_modems() -> None:
    # The modems report CONNECT 38400 (the relay's rate): both sides pace to it.
    relay = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "linksim",
            "relay",
            "--json",
            "--modem",
            "--rate",
            "38400",
            "--delay",
            "0.002",
            # The first RING comes 0.5 s after ATD.  The answering program
            # must have reset its modem by then, or its ATZ would hang up the
            # ringing call: the test starts the caller only once it has.
            "--dial-time",
            "0.5",
            "--ring-interval",
            "0.3",
            "--handshake-time",
            "0.1",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert relay.stdout is not None
        paths = json.loads(relay.stdout.readline())
        upload = bytes(range(256)) * 12
        server = subprocess.Popen(
            cli("listen", paths["b"], "--answer", "--dead-after", "60"),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        try:
            # The answering side has sent ATZ once it waits for the modem's
            # answer: the reset is on the line before the caller even starts,
            # so it cannot hang up the call.
            wait_until_reading(server, paths["b"])
            client = subprocess.run(
                [
                    *cli("connect", paths["a"], "--dial", "5551234", "--connect-timeout", "30"),
                    "--dead-after",
                    "60",
                ],
                input=upload,
                capture_output=True,
                timeout=GUARD,
            )
            got, server_err = server.communicate(timeout=GUARD)
            assert client.returncode == 0, client.stderr
            assert server.returncode == 0, server_err
            assert got == upload
            assert b"CONNECT 38400" in client.stderr
            assert b"CONNECT 38400" in server_err
        finally:
            _reap(server)
    finally:
        relay.send_signal(signal.SIGTERM)
        relay.wait(timeout=GUARD)


def test_busy_number_is_reported() -> None:
    relay = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "linksim",
            "relay",
            "--json",
            "--modem",
            "--busy",
            "5550000",
            "--dial-time",
            "0.1",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert relay.stdout is not None
        paths = json.loads(relay.stdout.readline())
        client = subprocess.run(
            cli("connect", paths["a"], "--dial", "5550000"),
            stdin=subprocess.DEVNULL,
            capture_output=True,
            timeout=GUARD,
        )
        assert client.returncode == 1
        assert b"5550000 is busy: try again later" in client.stderr
    finally:
        relay.send_signal(signal.SIGTERM)
        relay.wait(timeout=GUARD)


@pytest.mark.slow
@pytest.mark.parametrize("hints", [False, True], ids=["no-hints", "hints"])
def test_both_directions_over_an_impaired_line_exit_0_only_with_every_byte(
    tmp_path: pathlib.Path, hints: bool
) -> None:
    """Issue 17, finding 5: at close, connect aborted with 61-62 KB of 64 KiB
    received, or exited 0 while its peer was missing data.  Over a lossy
    relay, both directions at once: each side exits 0 if and only if what it
    received is exactly what the other sent (and then both are)."""
    relay = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "linksim",
            "relay",
            "--json",
            "--seed",
            "3",
            "--rate",
            "115200",
            "--delay",
            "0.05",
            "--ber",
            "1e-4",
            "--loss",
            "1e-4",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert relay.stdout is not None
        paths = json.loads(relay.stdout.readline())
        a, b = paths["a"], paths["b"]
        up = random.Random(11).randbytes(32_000)
        down = random.Random(12).randbytes(32_000)
        (tmp_path / "up").write_bytes(up)
        (tmp_path / "down").write_bytes(down)
        extra = ["--baud", "115200", "--delay", "0.05"] if hints else []
        with (tmp_path / "down").open("rb") as down_in:
            server = subprocess.Popen(
                cli("listen", b, *extra),
                stdin=down_in,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
            )
        try:
            wait_until_reading(server, b)
            with (tmp_path / "up").open("rb") as up_in:
                client = subprocess.run(
                    cli("connect", a, *extra, "--connect-timeout", "30"),
                    stdin=up_in,
                    capture_output=True,
                    timeout=GUARD * 3,
                )
            got_up, server_err = server.communicate(timeout=GUARD * 3)
        finally:
            _reap(server)
    finally:
        relay.send_signal(signal.SIGTERM)
        relay.wait(timeout=GUARD)
    # Exit 0 if and only if delivered, on each side.
    assert (client.returncode == 0) == (client.stdout == down), client.stderr[-1500:]
    assert (server.returncode == 0) == (got_up == up), server_err[-1500:]
    # And on this line it is delivered.
    assert client.returncode == 0, client.stderr[-1500:]
    assert server.returncode == 0, server_err[-1500:]


def test_progress_is_one_rewritten_line_when_stderr_is_a_terminal(
    relay: tuple[str, str], tmp_path: pathlib.Path
) -> None:
    """At a terminal the netcat keeps one progress line on stderr (rewritten in
    place, erased at the end); piped, it prints none (the other tests)."""
    a, b = relay
    (tmp_path / "up").write_bytes(random.Random(7).randbytes(20_000))
    server = subprocess.Popen(
        cli("listen", b, "--delay", "0.002", "--dead-after", "60"),
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    master, slave = os.openpty()
    try:
        wait_until_reading(server, b)
        with (tmp_path / "up").open("rb") as up_in:
            client = subprocess.run(
                cli("connect", a, "--delay", "0.002", "--connect-timeout", "30"),
                stdin=up_in,
                stdout=subprocess.DEVNULL,
                stderr=slave,
                timeout=GUARD,
            )
        os.close(slave)
        shown = b""
        while True:
            try:
                chunk = os.read(master, 4096)
            except OSError:  # EIO: the terminal's last writer has gone
                break
            if not chunk:
                break
            shown += chunk
        got, _ = server.communicate(timeout=GUARD)
    finally:
        _reap(server)
        os.close(master)
    assert client.returncode == 0
    assert got == (tmp_path / "up").read_bytes()
    assert b"\r\x1b[K" in shown  # the line is rewritten in place ...
    assert shown.endswith(b"\r\x1b[K")  # ... and erased at the end
    assert b"connecting..." in shown or b"acknowledged" in shown, shown


def test_ctrl_c_mid_transfer_exits_130_with_its_report(tmp_path: pathlib.Path) -> None:
    """Ctrl-C while the data flows: exit 130, no traceback, the ``--json``
    report says interrupted, and the listener has a correct prefix.  (The
    report read the end time from trio after trio had returned when the
    interrupt cut the close short: a traceback and exit 1.)"""
    relay = subprocess.Popen(
        [sys.executable, "-m", "linksim", "relay", "--json", "--rate", "9600", "--delay", "0.002"],
        stdout=subprocess.PIPE,
        text=True,
    )
    payload = random.Random(7).randbytes(40_000)  # 40 s of this line
    (tmp_path / "up").write_bytes(payload)
    try:
        assert relay.stdout is not None
        paths = json.loads(relay.stdout.readline())
        server = subprocess.Popen(
            cli("listen", paths["b"], "--dead-after", "60"),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        try:
            wait_until_reading(server, paths["b"])
            with (tmp_path / "up").open("rb") as up_in:
                client = subprocess.Popen(
                    cli("connect", paths["a"], "--connect-timeout", "30", "--json"),
                    stdin=up_in,
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.PIPE,
                    # A test run started in the background inherits SIGINT ignored.
                    preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
                )
            try:
                assert server.stdout is not None
                first = b""
                while len(first) < 2000:  # the transfer is under way
                    # (Unbuffered: communicate() reads the pipe's descriptor.)
                    ready, _, _ = select.select([server.stdout], [], [], GUARD)
                    assert ready, "nothing arrived"
                    chunk = os.read(server.stdout.fileno(), 4096)
                    assert chunk, "the listener closed its stdout"
                    first += chunk
                client.send_signal(signal.SIGINT)
                _, err = client.communicate(timeout=GUARD)
                rest, _ = server.communicate(timeout=GUARD)
            finally:
                _reap(client)
        finally:
            _reap(server)
    finally:
        relay.send_signal(signal.SIGTERM)
        relay.wait(timeout=GUARD)
    text = err.decode()
    assert client.returncode == 130, text[-2000:]
    assert "Traceback" not in text
    record = json.loads(text.splitlines()[-1])
    assert record["outcome"] == "interrupted"
    assert record["connected"] is True
    got = first + rest
    assert 2000 <= len(got) < len(payload)
    assert got == payload[: len(got)]
    assert server.returncode == 1  # the peer aborted: not delivered
