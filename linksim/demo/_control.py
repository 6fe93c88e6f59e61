"""``linksim control``: the rock task run against a running ``linksim arm-server``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import trio

import serialsocket
from linksim.control import TaskRun
from linksim.link import endpoint_config_for, endpoint_overrides
from tcpstream import SessionError, connect_stream, connect_tcp

from ._report import (
    IDENTITY,
    DemoOptions,
    DemoReport,
    add_rates,
    client_link_figures,
    explain_failure,
    make_report,
    serial_link_figures,
)
from ._stack import drive, new_run

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
) -> DemoReport:
    """Run the rock task against a running arm server (``linksim control``).

    Over TCP it connects to ``host:tcp_port``; over a serial line it opens
    ``port`` at ``baud`` (dialing ``dial`` through a Hayes modem first).
    """
    where = _Where(host, tcp_port, port, baud, dial)
    run = new_run(options)
    figures: dict[str, Any] = {}
    error: str | None = None
    start = trio.current_time()
    try:
        with trio.fail_after(options.timeout):
            await _control_session(options, where, key, run, figures)
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
) -> None:
    title = f"telelink control: rock task over {options.transport}"
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
        sock = await serialsocket.connect(port, endpoint)
        try:
            async with connect_stream(sock, identity=IDENTITY, key=key) as arm:
                await drive(arm, run, options, lambda: serial_link_figures(sock), title)
                figures.update(client_link_figures(arm) | serial_link_figures(sock))
        finally:
            await sock.aclose()


def _overrides(options: DemoOptions) -> dict[str, Any]:
    """The serial endpoint options the run was given, for :func:`endpoint_config_for`."""
    return endpoint_overrides(window=options.window, max_len=options.max_len)
