"""The real-time demo: a relay between real ptys, the arm server in its own process.

Process layout of ``linksim demo`` (serial)::

    this process                                   child process
    controller --pty A== linksim relay ==pty B-- linksim arm-server
    (tcpstream client over a serial socket)        (serial socket listener,
                                                    tcpstream server, simulated arm)

With ``--transport tcp`` the child listens on a loopback port instead, and the
controller reaches it through the line's delay (not its errors: TCP repairs
those), as the virtual TCP run does.  The
session uses a fresh random pre-shared key (handed to the child in a private
file), so every demo run also exercises the authenticated handshake.
"""

from __future__ import annotations

import contextlib
import contextvars
import json
import os
import secrets
import subprocess
import sys
import tempfile
from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager
from typing import Any

import trio

import serialsocket
from linksim.control import TaskRun
from linksim.link import (
    LinkConfig,
    ModemConfig,
    ModemPair,
    RelayStatistics,
    endpoint_config_for,
    endpoint_overrides,
    open_impaired_link,
    run_relay,
)
from tcpstream import SessionError, connect_stream

from ._report import (
    IDENTITY,
    DemoOptions,
    DemoReport,
    add_rates,
    client_link_figures,
    explain_failure,
    line_capacity,
    make_report,
    serial_link_figures,
)
from ._stack import delay_line, drive, new_run, run_title

__all__ = ["run_real"]

READY_TIMEOUT = 30.0
"""Seconds for the arm server process to start listening (Python start-up and
imports take about a second; a loaded CI machine may take several)."""

EXIT_TIMEOUT = 10.0
"""Seconds the arm server gets to finish its session and exit before it is killed."""


@asynccontextmanager
async def arm_server_process(
    arguments: Sequence[str], key: bytes | None
) -> AsyncIterator[dict[str, Any]]:
    """Start ``linksim arm-server`` and yield its ready line (a dict).

    On the way out the process gets :data:`EXIT_TIMEOUT` seconds to exit by
    itself (it serves one session), then it is terminated.
    """
    with tempfile.TemporaryDirectory(prefix="linksim-demo-") as tmp:
        argv = [sys.executable, "-m", "linksim", "arm-server", "--sessions", "1", *arguments]
        if key is not None:
            key_path = os.path.join(tmp, "key")
            with open(os.open(key_path, os.O_WRONLY | os.O_CREAT, 0o600), "wb") as f:
                f.write(key.hex().encode())
            argv += ["--key-file", key_path]
        proc = await trio.lowlevel.open_process(argv, stdout=subprocess.PIPE)
        try:
            assert proc.stdout is not None
            info = await _read_ready(proc.stdout)
            yield info
            with trio.move_on_after(EXIT_TIMEOUT):
                await proc.wait()
        finally:
            if proc.returncode is None:
                proc.terminate()
                with trio.move_on_after(2.0) as s:
                    s.shield = True
                    await proc.wait()
                if proc.returncode is None:
                    proc.kill()
            if proc.stdout is not None:
                await proc.stdout.aclose()


async def _read_ready(stdout: trio.abc.ReceiveStream) -> dict[str, Any]:
    buf = b""
    with trio.fail_after(READY_TIMEOUT):
        while b"\n" not in buf:
            chunk = await stdout.receive_some(4096)
            if not chunk:
                raise OSError("the arm server exited before it was ready (see its message above)")
            buf += chunk
    line = buf.split(b"\n", 1)[0]
    info: dict[str, Any] = json.loads(line)
    return info


async def run_real(options: DemoOptions) -> DemoReport:
    """The real-time demo over ptys (serial) or loopback (tcp)."""
    key = options.key if options.key is not None else secrets.token_bytes(32)
    start = trio.current_time()
    _START.set(start)
    holder: dict[str, Any] = {}
    error: str | None = None
    try:
        with trio.fail_after(options.timeout):
            if options.transport == "tcp":
                await _tcp(options, key, holder)
            else:
                await _serial(options, key, holder)
    except trio.TooSlowError:
        error = f"the demo did not finish within {options.timeout:g} s"
    except (
        SessionError,
        serialsocket.DialError,
        trio.BrokenResourceError,
        OSError,
        ConnectionError,
    ) as exc:
        error = explain_failure(exc)
    if error is None and holder.get("close_error"):
        error = str(holder["close_error"])  # every command ran, but the link did not close cleanly
    seconds = trio.current_time() - start
    figures: dict[str, Any] = holder.get("figures", {})
    relay: RelayStatistics | None = holder.get("relay")
    if relay is not None:
        figures["line"] = _line_figures(relay)
    if options.transport == "serial":
        add_rates(figures, seconds, line_capacity(options.link))
    else:
        add_rates(figures, seconds)
    run: TaskRun | None = holder.get("run")
    return make_report(options, run, figures, seconds, error)


def _line_figures(stats: RelayStatistics) -> dict[str, Any]:
    """What the impaired line itself did (the relay's counters), per direction."""
    out: dict[str, Any] = {}
    for name, d in (("controller_to_arm", stats.a_to_b), ("arm_to_controller", stats.b_to_a)):
        out[name] = {
            "bytes_sent": d.bytes_sent,
            "bytes_delivered": d.bytes_delivered,
            "bytes_dropped": d.bytes_dropped,
            "bytes_corrupted": d.bytes_corrupted,
            "bytes_inserted": d.bytes_inserted,
        }
    return out


def _say(options: DemoOptions, message: str) -> None:
    """A status line on stderr while nothing else shows (connecting, closing).

    Without these the real-time demo sat silent for its first ~11 s (relay,
    arm server, serial connect and handshake over a slow line) and its last
    ~9 s (closing waits for the final acknowledgements).
    """
    if options.progress:
        print(f"[{trio.current_time() - _START.get():7.2f} s] {message}", file=sys.stderr)


_START: contextvars.ContextVar[float] = contextvars.ContextVar("demo_start", default=0.0)


async def _tcp(options: DemoOptions, key: bytes, holder: dict[str, Any]) -> None:
    line = delay_line(options.link)
    delay = line.a_to_b.delay + line.a_to_b.jitter
    server_args = ["--transport", "tcp", "--tcp-port", "0"]
    if delay > 0:
        server_args += ["--delay", f"{delay:g}"]
    _say(options, "starting the arm server (loopback TCP)")
    async with arm_server_process(server_args, key) as info:
        port = int(info["tcp_port"])
        how = f" through a {delay:g} s one-way delay" if delay > 0 else ""
        _say(options, f"arm server listening on port {port}; connecting{how} and authenticating")
        async with (
            _tcp_through(line, port) as stream,
            connect_stream(stream, identity=IDENTITY, key=key) as client,
        ):
            holder["run"] = run = new_run(options)
            probe = lambda: client_link_figures(client)  # noqa: E731
            await drive(client, run, options, probe, run_title(options, "loopback"))
            holder["figures"] = client_link_figures(client)
            _say(options, "closing the session")
        _say(options, "session closed; waiting for the arm server to exit")


@asynccontextmanager
async def _tcp_through(line: LinkConfig, port: int) -> AsyncIterator[trio.abc.Stream]:
    """A TCP connection to the arm server on ``port`` seen through ``line`` (its
    delay): the controller's end of an in-memory line whose far end is copied
    to and from the socket both ways."""
    async with (
        await trio.open_tcp_stream("127.0.0.1", port) as tcp,
        open_impaired_link(line) as (near, far),
        trio.open_nursery() as nursery,
    ):
        nursery.start_soon(_copy, far, tcp)
        nursery.start_soon(_copy, tcp, far)
        try:
            yield near
        finally:
            nursery.cancel_scope.cancel()


async def _copy(source: trio.abc.Stream, sink: trio.abc.Stream) -> None:
    """Copy until ``source`` ends or either side breaks, then close ``sink`` (the
    other end sees the connection end, as it would have directly)."""
    with contextlib.suppress(trio.BrokenResourceError, trio.ClosedResourceError):
        while data := await source.receive_some():
            await sink.send_all(data)
    await sink.aclose()


async def _serial(options: DemoOptions, key: bytes, holder: dict[str, Any]) -> None:
    link = options.link
    rate = link.a_to_b.rate
    baud = int(rate) if rate is not None else 115200
    endpoint = endpoint_config_for(link, **_overrides(options))
    modems = ModemPair(ModemConfig(connect_rate=baud)) if options.dial else None
    stop = trio.Event()
    async with trio.open_nursery() as nursery:
        _say(options, "starting the impaired relay between two ptys")
        a, b = await nursery.start(_relay, link, modems, stop, holder)
        _say(options, f"relay up ({a} <-> {b}); starting the arm server on {b}")
        server_args = ["--transport", "serial", "--port", b, "--baud", str(baud)]
        server_args += ["--delay", f"{link.a_to_b.delay + link.a_to_b.jitter:g}"]
        if options.window is not None:
            server_args += ["--window", str(options.window)]
        if options.max_len is not None:
            server_args += ["--max-len", str(options.max_len)]
        if options.dial:
            server_args.append("--answer")
        try:
            async with arm_server_process(server_args, key):
                port = await serialsocket.open_port(a, baud)
                if options.dial:
                    _say(options, f"arm server ready; dialing {options.dial}")
                    connection = await serialsocket.dial(port, options.dial)
                    _say(options, f"dialed {options.dial}: {connection}")
                _say(
                    options,
                    f"connecting the serial socket on {a} at {baud} bit/s and authenticating "
                    "(the session's HELLO rides in the connection request)",
                )
                # Deferred: the request goes out with the HELLO inside (early
                # data), a round trip sooner than connecting first.
                sock = await serialsocket.connect(port, endpoint, defer=True)
                try:
                    async with connect_stream(sock, identity=IDENTITY, key=key) as client:
                        rtt = sock.statistics().link.smoothed_rtt
                        measured = f" (round trip {rtt:.2f} s)" if rtt is not None else ""
                        _say(options, f"serial link up{measured}; session granted")
                        holder["run"] = run = new_run(options)
                        await drive(
                            client,
                            run,
                            options,
                            lambda: serial_link_figures(sock),
                            run_title(options, "real time, ptys"),
                        )
                        holder["figures"] = client_link_figures(client) | serial_link_figures(sock)
                        _say(options, "closing the session")
                finally:
                    _say(options, "closing the serial link (waiting for the last acknowledgements)")
                    # Shielded: the close must run even if the run was cancelled;
                    # it is bounded by itself (no progress for close_timeout, or
                    # the dead link), never by a fixed time while data drains.
                    with trio.CancelScope(shield=True):
                        await sock.aclose()
                    holder["close_error"] = sock.close_error
                    _say(options, sock.close_error or "serial link closed")
        finally:
            stop.set()


async def _relay(
    link: LinkConfig,
    modems: ModemPair | None,
    stop: trio.Event,
    holder: dict[str, Any],
    *,
    task_status: trio.TaskStatus[tuple[str, str]] = trio.TASK_STATUS_IGNORED,
) -> None:
    def ready(a: str, b: str) -> None:
        task_status.started((a, b))

    holder["relay"] = await run_relay(link, modems=modems, stop=stop, on_ready=ready)


def _overrides(options: DemoOptions) -> dict[str, Any]:
    """The serial endpoint options the run was given, for :func:`endpoint_config_for`."""
    return endpoint_overrides(window=options.window, max_len=options.max_len)
