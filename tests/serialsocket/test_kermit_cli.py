"""``serialsocket kermit send`` to ``serialsocket kermit receive``: two real processes, real ptys.

Everything runs as a user runs it: the two sides are ``python -m serialsocket
kermit ...`` subprocesses on the two ttys of ``linksim relay`` (itself a
subprocess, so the line can be delayed and damaged), or of a 7-bit line made
here, or of a bare pty nobody answers.  Received files are compared byte for
byte and both sides' ``--stats`` counters are checked.

No sleeps: the sender starts once the receiver is *waiting to read its tty*,
which Linux shows in /proc (the tty among the process's fds, armed for input
in its epoll set).  An S packet sent before the receiver has its tty open and
set up may be lost, costing the sender a timeout (``linksim bench kermit``
waits a fixed 0.3 s instead).  Every subprocess has a timeout that only stops
a hang, and is killed on the way out.
"""

from __future__ import annotations

import contextlib
import json
import os
import pathlib
import random
import select
import signal
import subprocess
import sys
import threading
import time
import tty
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import pytest

GUARD = 60.0
"""Seconds any one subprocess may take: a bound on a hang, never an expectation."""


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "serialsocket", "kermit", *args]


def _stop(proc: subprocess.Popen[Any]) -> None:
    """Kill ``proc`` if it is still running and reap it."""
    if proc.poll() is None:
        proc.kill()
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=GUARD)


def _reading(pid: int, path: str) -> bool:
    """True when process ``pid`` has ``path`` open and waits for input on it.

    trio waits in epoll; /proc/PID/fdinfo of an epoll fd lists each watched fd
    as ``tfd: N events: MASK ...``, and a one-shot registration keeps
    EPOLLIN (bit 0) in MASK only while it is armed.
    """
    proc = pathlib.Path(f"/proc/{pid}")
    tty_fds: set[str] = set()
    try:
        fds = list((proc / "fd").iterdir())
    except OSError:
        return False
    for fd in fds:
        with contextlib.suppress(OSError):
            if os.readlink(fd) == path:
                tty_fds.add(fd.name)
    if not tty_fds:
        return False
    for fd in fds:
        try:
            info = (proc / "fdinfo" / fd.name).read_text()
        except OSError:
            continue
        for line in info.splitlines():
            parts = line.split()
            if parts[:1] == ["tfd:"] and parts[1] in tty_fds and int(parts[3], 16) & 1:
                return True
    return False


def wait_until_reading(proc: subprocess.Popen[bytes], path: str) -> None:
    """Return once ``proc`` waits for input on the tty ``path``.

    Fails the test if ``proc`` exits first (with its stderr) or if it has not
    got there within ``GUARD`` seconds.  Linux only (/proc), as ptys are.
    """
    if not pathlib.Path("/proc/self/fdinfo").is_dir():
        pytest.skip("needs Linux's /proc/PID/fdinfo to see a process wait on its tty")
    deadline = time.monotonic() + GUARD
    while not _reading(proc.pid, path):
        if proc.poll() is not None:
            _, err = proc.communicate(timeout=GUARD)
            pytest.fail(f"{proc.args!r} exited with {proc.returncode} before reading: {err!r}")
        if time.monotonic() > deadline:
            pytest.fail(f"{proc.args!r} did not wait for input on {path} in {GUARD} s")
        time.sleep(0.01)


@dataclass
class Relay:
    """A running ``linksim relay``: its two tty paths, and its counters once stopped."""

    a: str
    b: str
    proc: subprocess.Popen[str]
    stats: dict[str, Any] | None = None


@contextlib.contextmanager
def relay(*line: str) -> Iterator[Relay]:
    """``linksim relay`` with the line options ``line``; its final counters land in ``.stats``."""
    argv = [sys.executable, "-m", "linksim", "relay", "--json", "--stats"]
    proc = subprocess.Popen(
        [*argv, "--stats-interval", "3600", *line],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        paths = json.loads(proc.stdout.readline())
        r = Relay(paths["a"], paths["b"], proc)
        yield r
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=GUARD)
        assert proc.returncode == 0, err
        r.stats = json.loads(err.strip().splitlines()[-1])
    finally:
        _stop(proc)


class SevenBitLine:
    """Two raw ptys joined by a thread that clears the 8th bit of every byte.

    ``linksim relay`` is 8-bit clean, so a 7-bit line (a UART at 7 data bits,
    or a parity-stripping path) is modelled here; ``high_bytes`` counts the
    bytes that arrived with the 8th bit set (and so were damaged).
    """

    _STRIP = bytes(b & 0x7F for b in range(256))

    def __init__(self) -> None:
        self.masters: list[int] = []
        self.paths: list[str] = []
        for _ in range(2):
            master, slave = os.openpty()
            tty.setraw(slave)  # the setting stays with the pty
            self.paths.append(os.ttyname(slave))
            os.close(slave)
            # Non-blocking: a side opened between select and read must not
            # stall the other direction.
            os.set_blocking(master, False)
            self.masters.append(master)
        self.high_bytes = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select(self.masters, [], [], 0.05)
            for side, master in enumerate(self.masters):
                if master not in ready:
                    continue
                try:
                    data = os.read(master, 4096)
                except BlockingIOError:  # the program opened its side since select
                    continue
                except OSError:  # EIO: nobody has this side open (yet, or any more)
                    time.sleep(0.01)
                    continue
                self.high_bytes += len(data.translate(None, bytes(range(128))))
                self._write(self.masters[1 - side], data.translate(self._STRIP))

    def _write(self, fd: int, data: bytes) -> None:
        """Write all of ``data``, waiting while the far tty is full (as a UART would)."""
        view = memoryview(data)
        while view and not self._stop.is_set():
            try:
                view = view[os.write(fd, view) :]
            except BlockingIOError:
                select.select([], [fd], [], 0.05)
            except OSError:  # EIO: nobody has the far side open; the bytes are lost
                return

    def __enter__(self) -> SevenBitLine:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=GUARD)
        for fd in self.masters:
            os.close(fd)


@dataclass
class Outcome:
    """One side's exit status, stderr, and its ``--stats`` counters (None if not printed)."""

    returncode: int
    stderr: str
    stats: dict[str, Any] | None


def _outcome(returncode: int, stderr: bytes) -> Outcome:
    text = stderr.decode("utf-8", "replace")
    stats = None
    lines = text.strip().splitlines()
    if lines and lines[-1].startswith("{"):
        stats = json.loads(lines[-1])
    return Outcome(returncode, text, stats)


def transfer(
    line_a: str,
    line_b: str,
    files: Sequence[pathlib.Path],
    out: pathlib.Path,
    options: Sequence[str] = (),
    *,
    send_options: Sequence[str] = (),
    receive_options: Sequence[str] = (),
) -> tuple[Outcome, Outcome]:
    """Receive into ``out`` on ``line_b`` while sending ``files`` on ``line_a``."""
    receiver = subprocess.Popen(
        # Literal names: these tests check names round-trip exactly between
        # two copies of ours (conversion: test_kermit_features.py).
        cli(
            "receive",
            str(out),
            "--port",
            line_b,
            "--stats",
            "--literal-names",
            *options,
            *receive_options,
        ),
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        wait_until_reading(receiver, line_b)
        sender = subprocess.run(
            cli(
                "send",
                *map(str, files),
                "--port",
                line_a,
                "--stats",
                "--literal-names",
                *options,
                *send_options,
            ),
            stdin=subprocess.DEVNULL,
            capture_output=True,
            timeout=GUARD,
        )
        _, err = receiver.communicate(timeout=GUARD)
        return _outcome(sender.returncode, sender.stderr), _outcome(receiver.returncode, err)
    finally:
        _stop(receiver)


def make_files(directory: pathlib.Path, size: int, seed: int = 1) -> list[pathlib.Path]:
    """Every byte value with runs of prefix characters, random binary, text, an empty file."""
    rng = random.Random(seed)
    binary = (
        bytes(range(256)) * 8
        + b"\x00" * 300
        + b"#" * 100
        + b"~" * 100
        + b"&" * 100
        + b"\xff" * 200
        + b"\x8d\r\n\x0d\x8a" * 40
    )
    words = [b"kermit", b"packet", b"\r\n", b"\n", b"   ", b"#if", b"~~~~", b"&&"]
    contents = {
        "all-bytes.bin": binary,
        "random.bin": rng.randbytes(size),
        "Notes v2.txt": b" ".join(rng.choice(words) for _ in range(size // 6)),
        "empty": b"",
    }
    directory.mkdir()
    for name, data in contents.items():
        (directory / name).write_bytes(data)
    return [directory / name for name in contents]


def assert_received(files: Sequence[pathlib.Path], out: pathlib.Path) -> None:
    """``out`` holds exactly ``files``, byte for byte (no ``.part`` left over)."""
    assert sorted(p.name for p in out.iterdir()) == sorted(f.name for f in files)
    for f in files:
        assert (out / f.name).read_bytes() == f.read_bytes(), f.name


def assert_done(side: Outcome, files: Sequence[pathlib.Path]) -> dict[str, Any]:
    """A clean exit, and counters that account for every file and byte."""
    assert side.returncode == 0, side.stderr[-2000:]
    assert "Traceback" not in side.stderr
    assert side.stats is not None, side.stderr
    assert side.stats["state"] == "done"
    assert side.stats["files"] == len(files)
    assert side.stats["file_bytes"] == sum(f.stat().st_size for f in files)
    return side.stats


@pytest.mark.parametrize(
    ("window", "packet_length", "expected_length"),
    [(8, 1000, 1000), (1, 94, 91)],
    ids=["window-8-long-packets", "window-1-normal-packets"],
)
def test_files_arrive_byte_exact_on_a_clean_line(
    tmp_path: pathlib.Path, window: int, packet_length: int, expected_length: int
) -> None:
    files = make_files(tmp_path / "src", 20_000)
    out = tmp_path / "out"
    out.mkdir()
    options = ["--window", str(window), "--packet-length", str(packet_length)]
    with relay() as line:
        sent, received = transfer(line.a, line.b, files, out, options)
    for side in (sent, received):
        stats = assert_done(side, files)
        # MAXL is never advertised above 89 (KERMIT.md: C-Kermit overshoots),
        # so normal packets are at most 91 characters, MARK through CHECK.
        assert (stats["window"], stats["packet_length"]) == (window, expected_length)
        assert stats["eighth_bit_prefix"] is None  # an 8-bit line
        assert stats["repeat_prefix"] == "~"  # both offer repeat counts
        assert stats["retransmissions"] == stats["timeouts"] == stats["damaged"] == 0
    assert_received(files, out)
    assert line.stats is not None
    assert line.stats["a_to_b"]["bytes_corrupted"] == 0


def test_delayed_noisy_line_window_8_long_packets(tmp_path: pathlib.Path) -> None:
    files = make_files(tmp_path / "src", 15_000, seed=2)
    out = tmp_path / "out"
    out.mkdir()
    # 50 ms each way and a byte error rate of 3e-4: with ~1000-byte packets
    # some arrive damaged in each direction (seeded, so the same ones each
    # run).  The fixed timeout is well above a full window's round trip.
    options = ["--window", "8", "--packet-length", "1000", "--timeout", "2", "--retries", "20"]
    with relay("--delay", "0.05", "--ber", "3e-4", "--seed", "3") as line:
        sent, received = transfer(line.a, line.b, files, out, options)
    send_stats = assert_done(sent, files)
    receive_stats = assert_done(received, files)
    assert_received(files, out)
    for stats in (send_stats, receive_stats):
        assert (stats["window"], stats["packet_length"]) == (8, 1000)
    assert line.stats is not None
    corrupted = line.stats["a_to_b"]["bytes_corrupted"] + line.stats["b_to_a"]["bytes_corrupted"]
    assert corrupted > 0
    # The damage was seen and repaired, not missed.
    assert receive_stats["damaged"] + send_stats["damaged"] > 0
    assert send_stats["retransmissions"] > 0


def test_seven_bit_line_uses_8th_bit_prefixing(tmp_path: pathlib.Path) -> None:
    files = make_files(tmp_path / "src", 10_000, seed=3)
    out = tmp_path / "out"
    out.mkdir()
    with SevenBitLine() as line:
        sent, received = transfer(line.paths[0], line.paths[1], files, out, ["--seven-bit"])
    for side in (sent, received):
        stats = assert_done(side, files)
        assert stats["eighth_bit_prefix"] == "&"
        assert stats["damaged"] == 0
    assert line.high_bytes == 0  # nothing on the wire needed its 8th bit
    assert_received(files, out)


def test_only_the_sender_asks_for_8th_bit_prefixing(tmp_path: pathlib.Path) -> None:
    # The receiver, not told the line is 7-bit, answers Y to the sender's '&'.
    files = make_files(tmp_path / "src", 2_000, seed=4)
    out = tmp_path / "out"
    out.mkdir()
    with SevenBitLine() as line:
        sent, received = transfer(
            line.paths[0], line.paths[1], files, out, send_options=["--seven-bit"]
        )
    for side in (sent, received):
        assert assert_done(side, files)["eighth_bit_prefix"] == "&"
    assert line.high_bytes == 0
    assert_received(files, out)


@contextlib.contextmanager
def unanswered_pty() -> Iterator[str]:
    """The path of a raw pty whose other end is held open here and never read or written."""
    master, slave = os.openpty()
    try:
        tty.setraw(slave)
        path = os.ttyname(slave)
        os.close(slave)
        yield path
    finally:
        os.close(master)


def run_alone(*args: str) -> Outcome:
    """One ``kermit`` command with nobody on the far end of its line."""
    with unanswered_pty() as path:
        result = subprocess.run(
            cli(*args, "--port", path),
            stdin=subprocess.DEVNULL,
            capture_output=True,
            timeout=GUARD,
        )
    return _outcome(result.returncode, result.stderr)


@pytest.fixture(scope="module")
def sender_alone(tmp_path_factory: pytest.TempPathFactory) -> Outcome:
    """A sender (window 1, 0.3 s timeout, 3 retries) on a line nobody answers."""
    data = tmp_path_factory.mktemp("alone") / "data.bin"
    data.write_bytes(bytes(range(256)))
    return run_alone(
        "send", str(data), "--stats", "--window", "1", "--timeout", "0.3", "--retries", "3"
    )


def test_sender_without_receiver_gives_up_after_its_retries(sender_alone: Outcome) -> None:
    assert sender_alone.returncode == 1
    assert "Traceback" not in sender_alone.stderr
    assert (
        "serialsocket kermit: transfer failed (we gave up): no answer at all: nothing came back "
        "from the peer in " in sender_alone.stderr
    )
    assert "(packet 0 (S) was never acknowledged, 4 tries)" in sender_alone.stderr
    assert "the link is down" not in sender_alone.stderr
    stats = sender_alone.stats
    assert stats is not None
    assert stats["state"] == "failed"
    assert stats["files"] == 0
    assert stats["retransmissions"] == 3  # the S packet, resent 3 times
    assert stats["packets_received"] == 0


def test_failure_is_reported_once(sender_alone: Outcome) -> None:
    assert sender_alone.stderr.count("no answer at all") == 1, sender_alone.stderr


def test_receiver_without_sender_gives_up_after_its_retries(tmp_path: pathlib.Path) -> None:
    got = run_alone("receive", str(tmp_path), "--window", "1", "--timeout", "0.3", "--retries", "2")
    assert got.returncode == 1
    assert "Traceback" not in got.stderr
    assert "serialsocket kermit: transfer failed (we gave up): no answer at all" in got.stderr
    assert "(S never arrived, 3 tries)" in got.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["send", "{tmp}/no-such-file"], "No such file or directory: '{tmp}/no-such-file'"),
        (["send", "{tmp}/file", "{tmp}"], "Is a directory: '{tmp}'"),
        (["receive", "{tmp}/no-such-dir"], "{tmp}/no-such-dir is not a directory"),
        (
            ["send", "{tmp}/file", "--window", "40"],
            "argument --window: must be an integer in 1..31",
        ),
        (["receive", "{tmp}", "--timeout", "0"], "argument --timeout: must be a number of seconds"),
    ],
    ids=["missing-file", "directory-as-file", "missing-directory", "bad-window", "bad-timeout"],
)
def test_bad_arguments_exit_2_with_a_message(
    tmp_path: pathlib.Path, args: list[str], message: str
) -> None:
    (tmp_path / "file").write_bytes(b"x")
    got = run_alone(*(a.format(tmp=tmp_path) for a in args))
    assert got.returncode == 2, got.stderr
    last = got.stderr.splitlines()[-1]
    assert last.startswith(("serialsocket kermit: ", "python -m serialsocket kermit")), got.stderr
    assert message.format(tmp=tmp_path) in got.stderr
    assert "Traceback" not in got.stderr
    assert [p.name for p in tmp_path.iterdir()] == ["file"]  # nothing created


def test_unopenable_port_exits_2() -> None:
    got = subprocess.run(
        cli("receive", "--port", "/dev/no-such-tty-telelink"),
        stdin=subprocess.DEVNULL,
        capture_output=True,
        timeout=GUARD,
    )
    assert got.returncode == 2
    assert b"check the path and its permissions" in got.stderr
    assert b"Traceback" not in got.stderr


LONG_NAMES = {
    "x" + "\u00e9" * 100 + "-first.txt": b"hello",
    "x" + "\u00e9" * 100 + "-second.txt": b"world",
}
"""Two UTF-8 names that cannot fit one normal F packet and start the same."""


def _long_name_transfer(tmp_path: pathlib.Path, *options: str) -> tuple[Outcome, Outcome]:
    (tmp_path / "src").mkdir()
    for name, content in LONG_NAMES.items():
        (tmp_path / "src" / name).write_bytes(content)
    out = tmp_path / "out"
    out.mkdir()
    with relay() as line:
        return transfer(
            line.a,
            line.b,
            [tmp_path / "src" / name for name in LONG_NAMES],
            out,
            ["--packet-length", "94", *options],
        )


def _assert_shortened_whole(tmp_path: pathlib.Path, sent: Outcome, received: Outcome) -> None:
    """Cut by whole characters, keeping the extension, tagged so that two names
    with the same start stay two files, with a warning that says so."""
    assert sent.returncode == received.returncode == 0, (sent.stderr, received.stderr)
    stored = sorted((tmp_path / "out").iterdir(), key=lambda p: p.read_bytes())
    assert [p.read_bytes() for p in stored] == [b"hello", b"world"]  # none overwritten
    for path in stored:
        assert "\ufffd" not in path.name, path.name
        assert path.name.startswith("x\u00e9")
        assert path.name.endswith(".txt")
    assert stored[0].name != stored[1].name
    assert sent.stderr.count("does not fit in one F packet") == 2
    assert "--packet-length" in sent.stderr


def test_long_name_on_a_seven_bit_line_is_not_cut_inside_a_prefix(
    tmp_path: pathlib.Path,
) -> None:
    """Found by this file: the encoded name used to be cut at the packet
    capacity, splitting an 8th-bit prefix pair (the receiver rejected the F
    packet: dangling prefix)."""
    sent, received = _long_name_transfer(tmp_path, "--seven-bit")
    assert "dangling prefix" not in sent.stderr
    assert "ends inside a prefix sequence" not in received.stderr
    _assert_shortened_whole(tmp_path, sent, received)


def test_long_name_is_not_cut_inside_a_character(tmp_path: pathlib.Path) -> None:
    """Found by this file: a cut at a byte count split a UTF-8 character and
    the file was stored under a name ending in U+FFFD."""
    sent, received = _long_name_transfer(tmp_path)
    _assert_shortened_whole(tmp_path, sent, received)
