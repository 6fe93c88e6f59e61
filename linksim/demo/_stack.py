"""The demo's stack wiring: the controller side and the one-process virtual run.

The controller side (:func:`new_run`, :func:`drive`, :func:`run_title`) is
shared by the demo, ``linksim control`` and the console; :func:`virtual_streams`
is the in-memory line (a serial socket pair, or a clean delayed link for TCP)
the virtual demo and the virtual console run over.
"""

from __future__ import annotations

import contextlib
import random
from collections.abc import AsyncIterator, Callable, Mapping
from typing import Any

import trio

from linksim.arm import SimulatedArm, rock_task
from linksim.control import Progress, TaskRun
from linksim.link import (
    DirectionConfig,
    LinkConfig,
    endpoint_config_for,
    endpoint_overrides,
    handshake_timeout_for,
    open_impaired_link,
    rtt_hint_for,
    serial_socket_pair,
)
from tcpstream import ArmClient, Server, ServerConfig, SessionError, connect_stream

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

__all__ = ["drive", "new_run", "run_title", "run_virtual_demo", "virtual_streams"]


# --- the controller side (shared by the demo and `linksim control`) ------------------


def new_run(options: DemoOptions) -> TaskRun:
    """The rock task (seed 000) in the demo's world, ready to run."""
    return TaskRun(rock_task(options.world).commands)


async def drive(
    client: ArmClient,
    run: TaskRun,
    options: DemoOptions,
    link: Callable[[], Mapping[str, Any]] | None,
    title: str,
) -> None:
    """Run ``run`` through ``client`` with the progress display."""
    with Progress(
        run,
        title=title,
        link=link,
        clock=trio.current_time,
        live=options.live,
        enabled=options.progress,
    ) as view:
        run.on_change = view.changed
        await run.run(client)


def run_title(options: DemoOptions, where: str) -> str:
    preset = options.preset or "custom link"
    if options.transport == "tcp":
        delay = options.link.a_to_b.delay + options.link.a_to_b.jitter
        preset = f"{preset}: its {delay:g} s delay, TCP repairs the rest"
    return f"telelink demo: rock task over {options.transport} ({preset}, {where})"


def delay_line(link: LinkConfig) -> LinkConfig:
    """The line as TCP sees it: its delay and jitter, no errors (TCP repairs them)."""
    d = link.a_to_b
    return LinkConfig.symmetric(DirectionConfig(delay=d.delay, jitter=d.jitter))


# --- virtual: one process, virtual clock -----------------------------------------------


@contextlib.asynccontextmanager
async def virtual_streams(
    options: DemoOptions,
) -> AsyncIterator[tuple[trio.abc.Stream, trio.abc.Stream, Callable[[], dict[str, Any]]]]:
    if options.transport == "serial":
        ep = endpoint_config_for(options.link, **_overrides(options))
        async with serial_socket_pair(options.link, endpoint=ep) as (ctl, arm):
            yield ctl, arm, lambda: serial_link_figures(ctl)
        return
    # TCP is reliable: the virtual TCP run keeps the line's delay, not its errors.
    async with open_impaired_link(delay_line(options.link)) as (ctl, arm):
        yield ctl, arm, dict


async def run_virtual_demo(options: DemoOptions) -> DemoReport:
    arm = SimulatedArm(options.world)
    # Virtual runs are deterministic: session nonces and the controller's
    # incarnation come from the link seed, not the OS (they change packet
    # contents, hence prefix-encoded sizes, hence timing).
    rng = random.Random(options.link.seed)
    server_cfg = ServerConfig(
        key=options.key, rtt_hint=rtt_hint_for(options.link), nonce_source=rng.randbytes
    )
    start = trio.current_time()
    run = new_run(options)
    figures: dict[str, Any] = {}
    error: str | None = None
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
                    await drive(client, run, options, probe, run_title(options, "virtual time"))
                    figures = client_link_figures(client) | probe()  # the line's own figures win
            except (SessionError, trio.BrokenResourceError, OSError) as exc:
                error = explain_failure(exc)
            nursery.cancel_scope.cancel()
    if scope.cancelled_caught:
        error = f"the run did not finish within {options.timeout:g} s of link time"
    seconds = trio.current_time() - start
    if options.transport == "serial":
        add_rates(figures, seconds, line_capacity(options.link))
    else:
        add_rates(figures, seconds)
    return make_report(options, run, figures, seconds, error)


def _overrides(options: DemoOptions) -> dict[str, Any]:
    """The serial endpoint options the run was given, for :func:`endpoint_config_for`."""
    return endpoint_overrides(window=options.window, max_len=options.max_len)
