"""``linksim control``: a task (the rock task, or a task file) run against an arm server.

:func:`run_control` drives a running ``linksim arm-server``;
:func:`run_control_virtual` runs the arm server in the same process over an
in-memory line on trio's virtual clock (``linksim control --virtual``:
instant and deterministic, two runs give the same report).
"""

from __future__ import annotations

import random
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import trio

import serialsocket
from linksim.arm import SimulatedArm
from linksim.control import TaskRun
from linksim.link import (
    endpoint_config_for,
    endpoint_overrides,
    handshake_timeout_for,
    rtt_hint_for,
)
from tcpstream import (
    Command,
    Server,
    ServerConfig,
    SessionError,
    connect_stream,
    connect_tcp,
)

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
from ._stack import drive, new_run, virtual_streams

__all__ = ["run_control"]


@dataclass(frozen=True, slots=True)
class _Where:
    """Where the arm server is."""

    host: str
    tcp_port: int
    port: str | None
    baud: int
    dial: str | None


async def run_control(
    options: DemoOptions,
    *,
    key: bytes | None,
    host: str = "127.0.0.1",
    tcp_port: int = 7010,
    port: str | None = None,
    baud: int = 9600,
    dial: str | None = None,
    commands: Sequence[Command] | None = None,
    task: str = "rock task",
) -> DemoReport:
    """Run ``commands`` (default: the rock task) against a running arm server.

    Over TCP it connects to ``host:tcp_port``; over a serial line it opens
    ``port`` at ``baud`` (dialing ``dial`` through a Hayes modem first).
    ``task`` names the commands in the progress display's title.  With
    ``options.virtual`` the arm server runs in this process instead, over an
    in-memory line of ``options.link`` (call it on a virtual clock).
    """
    if options.virtual:
        return await _run_virtual(options, commands, task)
    where = _Where(host, tcp_port, port, baud, dial)
    run = new_run(options) if commands is None else TaskRun(commands)
    figures: dict[str, Any] = {}
    error: str | None = None
    start = trio.current_time()
    try:
        with trio.fail_after(options.timeout):
            await _control_session(options, where, key, run, figures, task)
    except trio.TooSlowError:
        error = f"the run did not finish within {options.timeout:g} s"
    except (SessionError, serialsocket.DialError, trio.BrokenResourceError, OSError) as exc:
        error = explain_failure(exc)
    seconds = trio.current_time() - start
    # An 8N1 serial line carries baud / 10 characters a second each way.
    cps = baud / 10 if options.transport == "serial" else None
    add_rates(figures, seconds, (cps, cps))
    return make_report(options, run, figures, seconds, error)


async def _control_session(
    options: DemoOptions,
    where: _Where,
    key: bytes | None,
    run: TaskRun,
    figures: dict[str, Any],
    task: str,
) -> None:
    title = f"telelink control: {task} over {options.transport}"
    if options.transport == "tcp":
        async with connect_tcp(where.host, where.tcp_port, identity=IDENTITY, key=key) as arm:
            await drive(arm, run, options, lambda: client_link_figures(arm), title)
            figures.update(client_link_figures(arm))
    else:
        if where.port is None:
            raise ValueError("the serial transport needs the port's path")
        endpoint = endpoint_config_for(options.link, **_overrides(options))
        port = await serialsocket.open_port(where.port, where.baud)
        if where.dial:
            await serialsocket.dial(port, where.dial)
        # Deferred: the connection request goes out with the session's HELLO
        # inside (early data), a round trip sooner than connecting first.
        sock = await serialsocket.connect(port, endpoint, defer=True)
        try:
            async with connect_stream(sock, identity=IDENTITY, key=key) as arm:
                await drive(arm, run, options, lambda: serial_link_figures(sock), title)
                figures.update(client_link_figures(arm) | serial_link_figures(sock))
        finally:
            await sock.aclose()


async def _run_virtual(
    options: DemoOptions, commands: Sequence[Command] | None = None, task: str = "rock task"
) -> DemoReport:
    """Run ``commands`` (default: the rock task) against an arm server in this process.

    The line is ``options.link`` (``linksim control`` gives it the --baud and
    --delay hints: a clean line of that rate and delay), run on the caller's
    clock, which ``linksim control --virtual`` makes trio's virtual clock.
    Session nonces and the incarnation come from the link's seed, so two
    runs are identical.
    """
    arm = SimulatedArm(options.world)
    rng = random.Random(options.link.seed)
    server_cfg = ServerConfig(
        key=options.key, rtt_hint=rtt_hint_for(options.link), nonce_source=rng.randbytes
    )
    start = trio.current_time()
    run = new_run(options) if commands is None else TaskRun(commands)
    figures: dict[str, Any] = {}
    error: str | None = None
    title = f"telelink control: {task} over {options.transport} (virtual time)"
    with trio.move_on_after(options.timeout) as scope:
        async with (
            virtual_streams(options) as (ctl, arm_side, probe),
            Server(arm, server_cfg) as server,
            trio.open_nursery() as nursery,
        ):
            nursery.start_soon(server.serve_stream, arm_side)
            try:
                async with connect_stream(
                    ctl,
                    identity=IDENTITY,
                    key=options.key,
                    incarnation=rng.getrandbits(64),
                    nonce_source=rng.randbytes,
                    handshake_timeout=handshake_timeout_for(options.link),
                ) as client:
                    await drive(client, run, options, probe, title)
                    figures = client_link_figures(client) | probe()
            except (SessionError, trio.BrokenResourceError, OSError) as exc:
                error = explain_failure(exc)
            nursery.cancel_scope.cancel()
    if scope.cancelled_caught:
        error = f"the run did not finish within {options.timeout:g} s of link time"
    seconds = trio.current_time() - start
    capacity = line_capacity(options.link) if options.transport == "serial" else (None, None)
    add_rates(figures, seconds, capacity)
    return make_report(options, run, figures, seconds, error)


def _overrides(options: DemoOptions) -> dict[str, Any]:
    """The serial endpoint options the run was given, for :func:`endpoint_config_for`."""
    return endpoint_overrides(window=options.window, max_len=options.max_len)
