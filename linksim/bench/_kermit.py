"""``linksim bench kermit``: Kermit file-transfer goodput, ours against C-Kermit's.

Each run sends one file of random binary through ``linksim relay`` (in this
process) between two ptys, with the same line settings for every pairing:

* ``ours->ckermit``: ``serialsocket kermit send`` to C-Kermit's receiver;
* ``ckermit->ckermit``: C-Kermit sending to C-Kermit (the reference);
* optionally ``ckermit->ours`` and the G-Kermit pairings (``--pairs``).

Both sides are told the same window, packet length and block check; streaming
is off (``set streaming off``: it is not an option on an impaired line and
ours does not offer it).  The time runs from starting the sender to the
receiver's exit, so it includes the programs' start-up; the file must be big
enough to make that small.  The received file is compared byte for byte.

The same machinery runs the interop tests (tests/serialsocket/test_kermit_interop.py):
:func:`run_transfer` is the one entry point.
"""

from __future__ import annotations

import contextlib
import os
import pathlib
import random
import shutil
import statistics
import tempfile
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import trio

from linksim.link import DirectionConfig, LinkConfig, run_relay
from serialsocket import open_port
from serialsocket.kermit import (
    KermitConfig,
    KermitStatistics,
    TransactionEnded,
    kermit_receive,
    kermit_send,
    kermit_server,
)

__all__ = [
    "DEFAULT_PAIRS",
    "PEERS",
    "TransferResult",
    "TransferSetup",
    "available",
    "bad_pairing",
    "run_against_server",
    "run_bench_kermit",
    "run_interrupted",
    "run_kermit_table",
    "run_transfer",
]

PEERS = ("ours", "ckermit", "gkermit")
_PROGRAMS = {"ckermit": "kermit", "gkermit": "gkermit"}
DEFAULT_PAIRS = ("ours->ckermit", "ckermit->ckermit")
_START_GAP = 0.3
"""Seconds between starting the receiver and the sender: the receiver must
have opened its tty first, or the sender's S packet meets a closed pty."""


def available(peer: str) -> bool:
    """True when ``peer`` can run here (ours always; the others need their program)."""
    return peer == "ours" or shutil.which(_PROGRAMS[peer]) is not None


@dataclass(frozen=True, slots=True, kw_only=True)
class TransferSetup:
    """One transfer: who sends, who receives, the line and the protocol settings.

    Attributes:
        sender, receiver: ``ours``, ``ckermit`` or ``gkermit``.
        window: window slots both sides are told to use (G-Kermit has none).
        packet_length: the Kermit receive packet length both sides are told
            (Kermit's own measure, as C-Kermit's SET RECEIVE PACKET-LENGTH;
            ours is given the same number as its MARK-through-CHECK length).
        delay: one-way line delay, s.
        byte_error_rate: probability a byte is corrupted, each direction.
        rate: line rate in bit/s, or None for as fast as the ptys go.
        timeout: fixed timeout for both sides, s (Kermit TIME units: whole seconds).
        limit: hard limit for the whole transfer, s; stragglers are killed.
        seed: the relay's random seed.
        seven_bit: treat the line as 7-bit: ours asks for 8th-bit prefixing,
            C-Kermit and G-Kermit use parity space (which makes them ask too).
        literal_names: every side keeps file names as they are (C-Kermit
            ``set file names literal``, G-Kermit ``-P``, ours
            ``literal_names``); False: the Kermit default, common form on
            the wire and lower case on arrival.
        text: the sender sends in text mode (C-Kermit ``set file type
            text``, G-Kermit without ``-i``, ours ``text``); receivers follow
            the A packet.
        resend: the sender uses RESEND (ours ``resend``, C-Kermit ``resend``).
        dynamic_length: ours chooses its D packet length (False: always the
            longest, as the bench compared before).
        streaming: every side offers streaming (C-Kermit ``set reliable on``,
            ``set streaming on``; G-Kermit without ``-S``; ours ``streaming``)
            -- for reliable lines only.
        force3: ours uses FORCE-3 (block check 5; C-Kermit's own side is
            set through ``extra_ckermit``).
        defaults: every side runs with its own defaults, as a user who
            tunes nothing: ours with the line only (``KermitConfig(delay=,
            rate=)``, what ``serialsocket kermit send --baud R --delay D``
            runs), C-Kermit with its line, file and streaming settings only
            (its window 30, receive packet-length 4000, dynamic timers, 10
            retries); ``window``, ``packet_length`` and ``timeout`` are then
            ignored.  G-Kermit always runs with its defaults but ``-b``.
        extra_ckermit: more C-Kermit commands, before SEND/RECEIVE.
    """

    sender: str
    receiver: str
    window: int = 8
    packet_length: int = 1000
    delay: float = 0.0
    byte_error_rate: float = 0.0
    rate: float | None = None
    timeout: int = 5
    limit: float = 120.0
    seed: int = 1
    seven_bit: bool = False
    literal_names: bool = True
    text: bool = False
    resend: bool = False
    dynamic_length: bool = True
    force3: bool = False
    streaming: bool = False
    defaults: bool = False
    extra_ckermit: tuple[str, ...] = ()


def _ckermit_argv(setup: TransferSetup, line: str, files: Sequence[pathlib.Path]) -> list[str]:
    """C-Kermit, non-interactive: settings, then SEND or RECEIVE, then EXIT with its status."""
    cmds = [
        f"set line {line}",
        "set carrier-watch off",
        "set flow none",
        "set parity space" if setup.seven_bit else "set parity none",
        "set reliable on" if setup.streaming else "set reliable off",
        "set streaming on" if setup.streaming else "set streaming off",
        "set file type text" if setup.text else "set file type binary",
        "set transfer mode manual",
        "set file names literal" if setup.literal_names else "set file names converted",
        "set file collision overwrite",
        "set file incomplete keep",
        "set attributes on",
    ]
    if not setup.defaults:
        cmds += [
            f"set window {setup.window}",
            f"set receive packet-length {setup.packet_length}",
            "set block-check 3",
            f"set send timeout {setup.timeout} fixed",
            f"set receive timeout {setup.timeout}",
            "set retry-limit 20",
        ]
    cmds += setup.extra_ckermit
    if files:
        verb = "send" if len(files) == 1 else "msend"
        if setup.resend:
            verb = "resend"
        cmds.append(f"{verb} " + " ".join(str(f) for f in files))
    else:
        cmds.append("receive")
    cmds.append("exit \\v(status)")
    return ["kermit", "-Y", "-q", "-B", "-C", ", ".join(cmds)]


def _gkermit_argv(setup: TransferSetup, files: Sequence[pathlib.Path]) -> list[str]:
    """G-Kermit on stdin/stdout: binary, literal names, overwrite, no streaming."""
    argv = ["gkermit", "-q", "-w", "-b", str(setup.timeout)]
    if not setup.streaming:
        argv.append("-S")
    argv.append("-T" if setup.text else "-i")
    if setup.literal_names:
        argv.append("-P")
    argv += ["-e", str(min(max(setup.packet_length, 40), 9000))]
    if setup.seven_bit:
        argv += ["-p", "s"]
    return [*argv, "-s", *map(str, files)] if files else [*argv, "-r"]


def _our_config(setup: TransferSetup) -> KermitConfig:
    if setup.defaults:
        return KermitConfig(
            delay=setup.delay,
            rate=None if setup.rate is None else round(setup.rate),
            seven_bit=setup.seven_bit,
            literal_names=setup.literal_names,
            text=setup.text,
            resend=setup.resend,
            streaming=setup.streaming,
        )
    return KermitConfig(
        max_packet_length=setup.packet_length,
        window=setup.window,
        timeout=float(setup.timeout),
        retry_limit=20,
        seven_bit=setup.seven_bit,
        literal_names=setup.literal_names,
        text=setup.text,
        resend=setup.resend,
        dynamic_length=setup.dynamic_length,
        force3=setup.force3,
        streaming=setup.streaming,
    )


@dataclass(frozen=True, slots=True)
class TransferResult:
    """What one transfer measured: seconds, and our side's counters if it took part."""

    seconds: float
    ours: KermitStatistics | None


async def _run_peer(
    peer: str,
    setup: TransferSetup,
    line: str,
    files: Sequence[pathlib.Path],
    directory: pathlib.Path,
    log: list[str],
    ours: list[KermitStatistics],
) -> None:
    """Run one side to completion; raises on failure (with the program's output).

    Our side's final counters are appended to ``ours``.
    """
    if peer == "ours":
        port = await open_port(line)
        async with port:
            if files:
                ours.append(await kermit_send(port, files, _our_config(setup)))
            else:
                ours.append(await kermit_receive(port, directory, _our_config(setup)))
        return
    if peer == "ckermit":
        argv = _ckermit_argv(setup, line, files)
        result = await trio.run_process(
            argv, cwd=directory, capture_stdout=True, capture_stderr=True, check=False
        )
    else:
        fd = os.open(line, os.O_RDWR | os.O_NOCTTY)
        try:
            result = await trio.run_process(
                _gkermit_argv(setup, files),
                cwd=directory,
                stdin=fd,
                stdout=fd,
                capture_stderr=True,
                check=False,
            )
        finally:
            os.close(fd)
    out = (result.stdout or b"") + (result.stderr or b"")
    log.append(out.decode("utf-8", "replace"))
    if result.returncode != 0:
        raise RuntimeError(
            f"{peer} exited with status {result.returncode}: "
            f"{out.decode('utf-8', 'replace')[-500:]}"
        )


async def _transfer(
    setup: TransferSetup, files: Sequence[pathlib.Path], out_dir: pathlib.Path
) -> TransferResult:
    direction = DirectionConfig(
        rate=setup.rate, delay=setup.delay, byte_error_rate=setup.byte_error_rate
    )
    config = LinkConfig.symmetric(direction, seed=setup.seed)
    log: list[str] = []
    ours: list[KermitStatistics] = []
    with trio.fail_after(setup.limit):
        async with trio.open_nursery() as nursery:
            stop = trio.Event()
            ready: list[tuple[str, str]] = []
            got_paths = trio.Event()

            def on_ready(a: str, b: str) -> None:
                ready.append((a, b))
                got_paths.set()

            nursery.start_soon(lambda: run_relay(config, stop=stop, on_ready=on_ready))
            await got_paths.wait()
            line_a, line_b = ready[0]
            done = trio.Event()
            errors: list[BaseException] = []

            async def receiver() -> None:
                try:
                    await _run_peer(setup.receiver, setup, line_b, [], out_dir, log, ours)
                except Exception as exc:
                    errors.append(exc)
                done.set()

            nursery.start_soon(receiver)
            await trio.sleep(_START_GAP)
            t0 = time.perf_counter()
            try:
                await _run_peer(setup.sender, setup, line_a, files, out_dir.parent, log, ours)
            except Exception as exc:
                errors.append(exc)
            with trio.move_on_after(max(4 * setup.timeout, 10)):
                await done.wait()
            elapsed = time.perf_counter() - t0
            stop.set()
            nursery.cancel_scope.cancel()
    if not done.is_set():
        errors.append(RuntimeError(f"the {setup.receiver} receiver did not finish"))
    if errors:
        raise RuntimeError(f"{setup.sender}->{setup.receiver} failed: {errors[0]}") from errors[0]
    return TransferResult(seconds=elapsed, ours=ours[0] if ours else None)


def run_transfer(
    setup: TransferSetup, files: Sequence[pathlib.Path], out_dir: pathlib.Path
) -> TransferResult:
    """Send ``files`` (which must not be in ``out_dir``) and check what arrives.

    Returns:
        The time from starting the sender to the receiver's exit, and our
        side's counters (None when neither side is ours).

    Raises:
        RuntimeError: a side failed or timed out (message includes its output).
        AssertionError: a received file differs from the original (checked
            only with literal names in binary mode; otherwise by the caller).
    """
    result = trio.run(_transfer, setup, files, out_dir)
    if setup.text or not setup.literal_names:
        return result  # names or contents change on the way: the caller checks them
    for f in files:
        got = (out_dir / f.name).read_bytes()
        if got != f.read_bytes():
            raise AssertionError(
                f"{f.name}: received {len(got)} bytes that differ from the "
                f"{f.stat().st_size} sent ({setup.sender}->{setup.receiver})"
            )
    return result


async def _cut(setup: TransferSetup, path: pathlib.Path, out_dir: pathlib.Path, cut: int) -> int:
    """Start sending ``path`` and kill both sides once the receiver holds ``cut`` bytes.

    Our side is cancelled (a receiver keeps ``NAME.part``); C-Kermit and
    G-Kermit are killed as an interrupted line would leave them.  Returns
    the size of the partial file left at the receiver.
    """
    direction = DirectionConfig(
        rate=setup.rate, delay=setup.delay, byte_error_rate=setup.byte_error_rate
    )
    config = LinkConfig.symmetric(direction, seed=setup.seed)
    partial = out_dir / (path.name + ".part" if setup.receiver == "ours" else path.name)
    log: list[str] = []
    ours: list[KermitStatistics] = []

    async def quietly(
        peer: str, line: str, files: Sequence[pathlib.Path], where: pathlib.Path
    ) -> None:
        with contextlib.suppress(Exception):
            await _run_peer(peer, setup, line, files, where, log, ours)

    with trio.fail_after(setup.limit):
        async with trio.open_nursery() as nursery:
            ready: list[tuple[str, str]] = []
            got_paths = trio.Event()

            def on_ready(a: str, b: str) -> None:
                ready.append((a, b))
                got_paths.set()

            nursery.start_soon(lambda: run_relay(config, stop=trio.Event(), on_ready=on_ready))
            await got_paths.wait()
            line_a, line_b = ready[0]
            nursery.start_soon(quietly, setup.receiver, line_b, [], out_dir)
            await trio.sleep(_START_GAP)
            nursery.start_soon(quietly, setup.sender, line_a, [path], out_dir.parent)
            while not (partial.exists() and partial.stat().st_size >= cut):
                await trio.sleep(0.02)
            nursery.cancel_scope.cancel()
    return partial.stat().st_size


def run_interrupted(
    setup: TransferSetup, path: pathlib.Path, out_dir: pathlib.Path, cut: int
) -> tuple[int, TransferResult]:
    """A transfer killed once the receiver holds ``cut`` bytes, then resumed with RESEND.

    Returns:
        The bytes the receiver held after the cut, and the resumed
        transfer's result (``setup`` with ``resend`` set; the file is checked
        byte for byte as by :func:`run_transfer`).
    """
    held = trio.run(_cut, setup, path, out_dir, cut)
    return held, run_transfer(replace(setup, resend=True), [path], out_dir)


def _ckermit_client_argv(setup: TransferSetup, line: str, commands: Sequence[str]) -> list[str]:
    """C-Kermit as a server's client: the line settings, ``commands``, then EXIT.

    A command starting with ``-`` is C-Kermit command-line flags instead
    (``-g FILE``: its GET action, run after the settings).
    """
    argv = _ckermit_argv(setup, line, [])
    if commands and commands[0].startswith("-"):
        settings = [c for c in argv[-1].split(", ")[:-2] if not c.startswith("set line")]
        flags = commands[0].split()
        return ["kermit", "-Y", "-q", "-B", "-l", line, "-C", ", ".join(settings), *flags]
    settings = argv[-1].split(", ")[:-2]  # drop RECEIVE and EXIT
    script = ", ".join([*settings, *commands, "exit \\v(status)"])
    return [*argv[:-1], script]


async def _against_server(
    setup: TransferSetup,
    served: pathlib.Path,
    client_dir: pathlib.Path,
    commands: Sequence[str],
    ended: list[TransactionEnded] | None,
) -> tuple[int, int, str]:
    direction = DirectionConfig(
        rate=setup.rate, delay=setup.delay, byte_error_rate=setup.byte_error_rate
    )
    config = LinkConfig.symmetric(direction, seed=setup.seed)
    count: list[int] = []
    with trio.fail_after(setup.limit):
        async with trio.open_nursery() as nursery:
            ready: list[tuple[str, str]] = []
            got_paths = trio.Event()

            def on_ready(a: str, b: str) -> None:
                ready.append((a, b))
                got_paths.set()

            nursery.start_soon(lambda: run_relay(config, stop=trio.Event(), on_ready=on_ready))
            await got_paths.wait()
            line_a, line_b = ready[0]

            async def serve() -> None:
                port = await open_port(line_b)
                async with port:
                    count.append(
                        await kermit_server(port, served, _our_config(setup), on_event=collect)
                    )

            def collect(event: object) -> None:
                if isinstance(event, TransactionEnded) and ended is not None:
                    ended.append(event)

            nursery.start_soon(serve)
            await trio.sleep(_START_GAP)
            if setup.sender == "gkermit":  # G-Kermit on stdin/stdout: its flags only
                fd = os.open(line_a, os.O_RDWR | os.O_NOCTTY)
                try:
                    argv = ["gkermit", "-q", "-i", "-w", "-b", str(setup.timeout)]
                    result = await trio.run_process(
                        [*argv, *commands[0].split()],
                        cwd=client_dir,
                        stdin=fd,
                        stdout=fd,
                        capture_stderr=True,
                        check=False,
                    )
                finally:
                    os.close(fd)
            else:
                result = await trio.run_process(
                    _ckermit_client_argv(setup, line_a, commands),
                    cwd=client_dir,
                    capture_stdout=True,
                    capture_stderr=True,
                    check=False,
                )
            # The server ends on FINISH or BYE; command-line flags (-g) leave it up.
            flags_only = bool(commands) and commands[0].startswith("-")
            with trio.move_on_after(0 if flags_only else max(4 * setup.timeout, 10)):
                while not count:
                    await trio.sleep(0.05)
            nursery.cancel_scope.cancel()
    output = ((result.stdout or b"") + (result.stderr or b"")).decode("utf-8", "replace")
    return (count[0] if count else -1), result.returncode, output


def run_against_server(
    setup: TransferSetup,
    served: pathlib.Path,
    client_dir: pathlib.Path,
    commands: Sequence[str],
    ended: list[TransactionEnded] | None = None,
) -> tuple[int, int, str]:
    """A client runs ``commands`` against our server serving ``served``.

    The client is ``setup.sender``: C-Kermit runs ``commands`` (GET, REMOTE
    ..., FINISH; or one string of command-line flags such as ``-g FILE``);
    G-Kermit runs the flags in ``commands[0]`` (``-g FILE``).

    Returns:
        Our server's transaction count (-1 if it had not ended when C-Kermit
        did), C-Kermit's exit status, and its output.  ``ended`` (if given)
        collects the server's :class:`TransactionEnded` events.
    """
    return trio.run(_against_server, setup, served, client_dir, commands, ended)


def _setup(pair: str, base: TransferSetup, seed: int) -> TransferSetup:
    sender, receiver = pair.split("->")
    return replace(base, sender=sender, receiver=receiver, seed=seed)


def _one(setup: TransferSetup, data: bytes, workdir: pathlib.Path, tag: str) -> TransferResult:
    src = workdir / f"src-{tag}"
    out = workdir / f"out-{tag}"
    src.mkdir()
    out.mkdir()
    path = src / "bench.bin"
    path.write_bytes(data)
    try:
        return run_transfer(setup, [path], out)
    finally:
        shutil.rmtree(src)
        shutil.rmtree(out)


def _measure(
    pair: str, base: TransferSetup, runs: int, data: bytes, workdir: pathlib.Path
) -> dict[str, object]:
    """Median of ``runs`` transfers, plus the fixed cost of a 1-byte transfer.

    The fixed cost (program start-up, the S/F/A/Z/B exchanges: several round
    trips) differs between pairings (C-Kermit's sender starts a process, ours
    runs in this one), so ``net_goodput_Bps`` divides by the time above it.
    """
    name = pair.replace("->", "-")
    fixed = _one(_setup(pair, base, base.seed), b"x", workdir, f"{name}-fixed").seconds
    times: list[float] = []
    counters: list[dict[str, int]] = []
    for run in range(runs):
        result = _one(_setup(pair, base, base.seed + run), data, workdir, f"{name}-{run}")
        times.append(result.seconds)
        if result.ours is not None:
            st = result.ours
            counters.append(
                {
                    "timeouts": st.timeouts,
                    "retransmissions": st.retransmissions,
                    "naks_sent": st.naks_sent,
                    "naks_received": st.naks_received,
                    "damaged": st.damaged,
                    "packets_sent": st.packets_sent,
                    "window": st.window,
                    "packet_length": st.packet_length,
                }
            )
    median = statistics.median(times)
    return {
        "pair": pair,
        "runs": runs,
        "seconds": [round(t, 3) for t in times],
        "median_seconds": round(median, 3),
        "goodput_Bps": round(len(data) / median, 1),
        "fixed_seconds": round(fixed, 3),
        "net_goodput_Bps": round(len(data) / max(median - fixed, 1e-3), 1),
        "ours": counters,
    }


def bad_pairing(pairs: Sequence[str]) -> str | None:
    """Why ``pairs`` cannot run (a malformed pairing, a program not installed), or None."""
    for pair in pairs:
        parts = pair.split("->")
        if len(parts) != 2 or not set(parts) <= set(PEERS):
            return f"bad pairing {pair!r}: use e.g. ours->ckermit"
        missing = [p for p in parts if not available(p)]
        if missing:
            return f"{missing[0]} is not installed (apt-get install ckermit gkermit)"
    return None


def run_bench_kermit(
    pairs: Sequence[str], base: TransferSetup, *, size: int, runs: int
) -> dict[str, object]:
    """``linksim bench kermit``: each pairing's median of ``runs`` transfers of ``size`` bytes.

    ``base`` holds the line and protocol settings (its sender and receiver are
    replaced by each pairing's, its seed is the first run's).
    """
    data = os.urandom(size)
    with tempfile.TemporaryDirectory(prefix="bench-kermit-") as tmp:
        results = [_measure(p, base, runs, data, pathlib.Path(tmp)) for p in pairs]
    return {
        "benchmark": "kermit",
        "bytes": size,
        "window": base.window,
        "packet_length": base.packet_length,
        "delay": base.delay,
        "byte_error_rate": base.byte_error_rate,
        "rate": base.rate,
        "timeout": base.timeout,
        "results": results,
    }


TABLE_LINES = ((2400, 8192), (9600, 32768))
"""(bit/s, file bytes) of :func:`run_kermit_table`: issue 23's Moon lines."""
TABLE_DELAY = 1.3
TABLE_BER = 1e-3
TABLE_HAND_TUNED = (8, 16)
"""Windows of the hand-tuned C-Kermit reference (250-character packets)."""
_HAND_LENGTH = 250
_TABLE_TIMEOUT = 10
_TABLE_PARALLEL = 12
"""Transfers run at once: each waits on its line almost all the time."""


def _table_setups(seeds: Sequence[int]) -> list[tuple[str, TransferSetup]]:
    """Each row's setting name and setup: our defaults both ways, and the reference."""
    rows: list[tuple[str, TransferSetup]] = []
    for rate, _ in TABLE_LINES:
        line = TransferSetup(
            sender="ours",
            receiver="ckermit",
            delay=TABLE_DELAY,
            byte_error_rate=TABLE_BER,
            rate=rate,
            limit=900.0,
        )
        for seed in seeds:
            defaults = replace(line, defaults=True, seed=seed, timeout=_TABLE_TIMEOUT)
            rows.append(("defaults", defaults))
            rows.append(("defaults", replace(defaults, sender="ckermit", receiver="ours")))
            for window in TABLE_HAND_TUNED:
                rows.append(
                    (
                        f"hand-tuned, window {window}",
                        replace(
                            line,
                            sender="ckermit",
                            seed=seed,
                            window=window,
                            packet_length=_HAND_LENGTH,
                            timeout=_TABLE_TIMEOUT,
                        ),
                    )
                )
    return rows


def _table_row(setting: str, setup: TransferSetup, workdir: pathlib.Path) -> dict[str, object]:
    size = dict(TABLE_LINES)[round(setup.rate or 0)]
    data = random.Random(setup.seed).randbytes(size)
    tag = f"{setup.sender}-{setup.receiver}-{setup.rate}-{setup.seed}-{setup.window}-{setting[:4]}"
    row: dict[str, object] = {
        "rate": setup.rate,
        "pair": f"{setup.sender}->{setup.receiver}",
        "setting": setting,
        "seed": setup.seed,
        "bytes": size,
    }
    try:
        result = _one(setup, data, workdir, tag)
    except (RuntimeError, AssertionError) as exc:
        return {**row, "ok": False, "error": str(exc)[:300]}
    assert setup.rate is not None
    line_Bps = setup.rate / 10
    row.update(ok=True, seconds=round(result.seconds, 1))
    row["line_share"] = round(size / result.seconds / line_Bps, 3)
    if result.ours is not None:
        st = result.ours
        row["ours"] = {
            "window": st.window,
            "packet_length": st.packet_length,
            "data_packet_length": st.data_packet_length,
            "retransmissions": st.retransmissions,
            "timeouts": st.timeouts,
            "naks_sent": st.naks_sent,
            "naks_received": st.naks_received,
        }
    return row


def run_kermit_table(seeds: Sequence[int] = (1, 2, 3)) -> dict[str, object]:
    """``linksim bench kermit --table``: issue 23's line x defaults vs hand-tuned C-Kermit.

    Through the relay at 1.3 s one way and a byte error rate of 1e-3 (each
    direction), 8192 bytes at 2400 bit/s and 32768 at 9600, random binary,
    for each seed: our defaults sending to C-Kermit's defaults, C-Kermit's
    defaults sending to our defaults (only what our receiver offers is ours
    there), and C-Kermit to C-Kermit hand-tuned (250-character packets,
    windows 8 and 16, block check 3, a fixed 10 s timeout, 20 retries).
    ``line_share`` is the file size over the time from starting the sender
    to the receiver's exit, over the line's bytes a second (bit/s / 10).
    The transfers run in parallel; each is real time (a few minutes).
    """
    setups = _table_setups(seeds)
    with tempfile.TemporaryDirectory(prefix="bench-kermit-table-") as tmp:
        workdir = pathlib.Path(tmp)
        with ThreadPoolExecutor(max_workers=_TABLE_PARALLEL) as pool:
            rows = list(pool.map(lambda r: _table_row(r[0], r[1], workdir), setups))
    return {
        "benchmark": "kermit-table",
        "delay": TABLE_DELAY,
        "byte_error_rate": TABLE_BER,
        "lines": [{"rate": r, "bytes": b} for r, b in TABLE_LINES],
        "rows": rows,
    }
