"""``linksim console``: drive (or watch) an arm with the operator console.

Three ways, like the demo: ``--virtual`` runs arm server, impaired link and
console in one process on trio's virtual clock (instant, deterministic);
``--transport tcp|serial`` drives a running ``linksim arm-server``;
``--observer`` watches one (TCP) without commanding.  Before anything is
sent the task is previewed on the local model; ``--require-preview``
refuses to send a plan the model says the arm would refuse.  With
``ConsoleOptions.lines`` (``--interactive``) the operator types the commands
instead: :func:`~linksim.control.run_command_line` previews, sends and
reports each one.
"""

from __future__ import annotations

import random
import sys
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, TextIO

import trio
import trio.testing

import serialsocket
from linksim.arm import SimulatedArm, WorldConfig
from linksim.control import (
    CommandStack,
    CommandState,
    ConsoleSession,
    LineSource,
    TaskFile,
    TaskRun,
    TelemetryLog,
    preview,
    run_command_line,
)
from linksim.link import endpoint_config_for, rtt_hint_for, run_virtual
from serialsocket.interrupt import run_interruptibly
from tcpstream import ArmClient, Server, ServerConfig, SessionError, connect_stream, connect_tcp

from ._report import (
    IDENTITY,
    DemoOptions,
    client_link_figures,
    describe_failure,
    explain_failure,
    serial_link_figures,
)
from ._stack import new_run, virtual_streams

__all__ = ["ConsoleOptions", "ConsoleResult", "run_console"]


@dataclass(frozen=True, slots=True)
class ConsoleOptions:
    """What the console runs.  ``demo`` carries link, world, key, transport and timeout."""

    demo: DemoOptions
    observer: bool = False
    require_preview: bool = False
    log: str | None = None
    host: str = "127.0.0.1"
    tcp_port: int = 7010
    port: str | None = None
    baud: int = 9600
    dial: str | None = None
    out: TextIO | None = None
    """Where the console draws (default stderr)."""
    rate: float = 0.0
    """Virtual runs only: the virtual clock runs this many times faster than
    the wall clock, so the run can be watched; 0 = as fast as possible."""
    arm_world: WorldConfig | None = None
    """Virtual runs only: the *remote* arm's world when it differs from the
    model's (``demo.world``), to show divergence; None = the same world."""
    task: TaskFile | None = None
    """The commands to drive (a task file); None = the rock task."""
    lines: LineSource | None = None
    """The operator's command lines (``--interactive``): typed commands instead of a task."""
    say: Callable[[str], None] | None = None
    """Where the command line's messages go (default: a line on ``out``)."""

    @property
    def task_name(self) -> str:
        return "rock task" if self.task is None or self.task.source == "rock" else self.task.name


@dataclass(slots=True)
class ConsoleResult:
    """The outcome; :meth:`as_dict` is the ``--json`` summary."""

    ok: bool
    seconds: float
    session: ConsoleSession | None
    error: str | None = None
    link: dict[str, Any] = field(default_factory=dict)
    command_line: dict[str, Any] | None = None
    """``--interactive``: the command stack's summary (every line's command and outcome)."""

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"ok": self.ok, "seconds": round(self.seconds, 3)}
        if self.command_line is not None:
            out |= {k: v for k, v in self.command_line.items() if k not in ("ok", "seconds")}
        s = self.session
        if s is not None:
            p = s.predictor
            out["preview"] = None if s.preview is None else s.preview.as_dict()
            if s.run is not None:
                out["commands"] = [r.as_dict(s.run.started_at) for r in s.run.records]
            out["model"] = {
                "comparisons": p.comparisons,
                "flagged": p.flagged,
                "max_joint_error_rad": round(p.max_joint_error, 6),
                "max_position_error_m": round(p.max_position_error, 6),
            }
            out["telemetry_samples"] = s.telemetry_samples
        out["link"] = self.link
        out["error"] = self.error
        return out


Probe = Callable[[], Mapping[str, Any]]
Driver = Callable[[ArmClient], Awaitable[None]]
"""What runs once the session is up: the task, the observer's watch, or the command line."""


def _window_figures(sock: serialsocket.SerialSocket) -> dict[str, Any]:
    s = sock.statistics().link
    return serial_link_figures(sock) | {"window_occupancy": f"{s.in_flight}/{s.effective_window}"}


def _session_figures(client: ArmClient) -> dict[str, Any]:
    """A command session's own figures (all a TCP link has): in flight, packets, bytes."""
    return {"pending": client.statistics().pending} | client_link_figures(client)


async def _telemetry_loop(client: ArmClient, session: ConsoleSession) -> None:
    async for feedback in client.telemetry():
        session.telemetry(feedback)


async def _drive(client: ArmClient, session: ConsoleSession, options: ConsoleOptions) -> None:
    """Run the task (or watch until the session ends), feeding the console."""
    run = session.run
    if run is None:
        await _telemetry_loop(client, session)  # ends with the session
        return
    async with trio.open_nursery() as nursery:
        nursery.start_soon(_telemetry_loop, client, session)
        run.on_change = session.changed
        await run.run(client)
        nursery.cancel_scope.cancel()


def _session(options: ConsoleOptions, title: str) -> tuple[ConsoleSession, TelemetryLog | None]:
    """The console for a run (the link probe is attached once the link is up)."""
    now = trio.current_time()
    world = options.demo.world
    log = None
    if options.log is not None:
        log = TelemetryLog(options.log, origin=now, title=title, world=world.to_toml())
    run: TaskRun | None = None
    if not options.observer:
        run = new_run(options.demo) if options.task is None else TaskRun(options.task.commands)
    session = ConsoleSession(
        title,
        world,
        run=run,
        clock=trio.current_time,
        origin=now,
        log=log,
        out=options.out,
        live=options.demo.live,
    )
    if run is not None:
        session.set_preview(preview(run.commands, world))
    return session, log


def _refused_by_preview(session: ConsoleSession, options: ConsoleOptions) -> str | None:
    report = session.preview
    if options.require_preview and report is not None and not report.ok:
        refusal = report.first_refusal
        assert refusal is not None
        where, hint = f"#{refusal.index}", ""
        if options.task is not None and options.task.source != "rock":
            where = f"#{refusal.index} ({options.task.where(refusal.index)})"
            hint = " (--force sends it anyway)"
        return (
            f"preview refused command {where} ({refusal.label}): "
            f"{refusal.reason.name}: {refusal.message}; nothing was sent{hint}"
        )
    return None


async def _virtual(options: ConsoleOptions) -> ConsoleResult:
    demo = options.demo
    arm = SimulatedArm(options.arm_world or demo.world)
    rng = random.Random(demo.link.seed)
    server_cfg = ServerConfig(
        key=demo.key, rtt_hint=rtt_hint_for(demo.link), nonce_source=rng.randbytes
    )
    start = trio.current_time()
    figures: dict[str, Any] = {}
    where = f"{demo.preset or 'custom link'}, virtual time"
    title = f"telelink console: {options.task_name} over {demo.transport} ({where})"
    session, log = _session(options, title)
    error = _refused_by_preview(session, options)

    def set_link(probe: Probe) -> None:
        session.link = probe

    try:
        with session:
            if error is None:
                error = await _virtual_session(
                    options,
                    arm,
                    rng,
                    server_cfg,
                    figures,
                    lambda client: _drive(client, session, options),
                    set_link,
                )
    finally:
        if log is not None:
            log.close()
    return _result(session, figures, trio.current_time() - start, error)


async def _virtual_session(
    options: ConsoleOptions,
    arm: SimulatedArm,
    rng: random.Random,
    server_cfg: ServerConfig,
    figures: dict[str, Any],
    drive: Driver,
    set_link: Callable[[Probe], None],
    *,
    bounded: bool = True,
) -> str | None:
    demo = options.demo
    error: str | None = None
    with trio.move_on_after(demo.timeout if bounded else float("inf")) as scope:
        async with (
            virtual_streams(demo) as (ctl, arm_side, probe),
            Server(arm, server_cfg) as server,
            trio.open_nursery() as nursery,
        ):
            nursery.start_soon(server.serve_stream, arm_side)
            if isinstance(ctl, serialsocket.SerialSocket):
                sock = ctl
                set_link(lambda: _window_figures(sock))
            else:
                set_link(probe)
            try:
                async with connect_stream(
                    ctl,
                    identity=IDENTITY,
                    key=demo.key,
                    incarnation=rng.getrandbits(64),
                    nonce_source=rng.randbytes,
                ) as client:
                    await drive(client)
                    # The line's own figures (serial: what crossed the wire) win.
                    figures.update(client_link_figures(client) | probe())
            except (SessionError, trio.BrokenResourceError, OSError) as exc:
                error = explain_failure(exc)
            nursery.cancel_scope.cancel()
    if scope.cancelled_caught:
        error = f"the run did not finish within {demo.timeout:g} s of link time"
    return error


async def _real(options: ConsoleOptions) -> ConsoleResult:
    demo = options.demo
    start = trio.current_time()
    figures: dict[str, Any] = {}
    role = "watching" if options.observer else options.task_name
    title = f"telelink console: {role} over {demo.transport}"
    session, log = _session(options, title)
    error = _refused_by_preview(session, options)

    def set_link(probe: Probe) -> None:
        session.link = probe

    try:
        with session:
            if error is None:
                try:
                    with trio.fail_after(demo.timeout):
                        await _real_session(
                            options,
                            figures,
                            lambda client: _drive(client, session, options),
                            set_link,
                        )
                except trio.TooSlowError:
                    if not options.observer:
                        error = f"the run did not finish within {demo.timeout:g} s"
                except (
                    SessionError,
                    serialsocket.DialError,
                    trio.BrokenResourceError,
                    OSError,
                ) as exc:
                    error = explain_failure(exc)
    finally:
        if log is not None:
            log.close()
    return _result(session, figures, trio.current_time() - start, error)


async def _real_session(
    options: ConsoleOptions,
    figures: dict[str, Any],
    drive: Driver,
    set_link: Callable[[Probe], None],
) -> None:
    demo = options.demo
    if demo.transport == "tcp":
        async with connect_tcp(
            options.host,
            options.tcp_port,
            identity=IDENTITY,
            key=demo.key,
            observer=options.observer,
        ) as client:
            set_link(lambda: _session_figures(client))
            await drive(client)
            figures.update(_session_figures(client))
        return
    if options.port is None:
        raise OSError("--port PATH is needed for the serial transport")
    endpoint = endpoint_config_for(demo.link)
    port = await serialsocket.open_port(options.port, options.baud)
    if options.dial:
        await serialsocket.dial(port, options.dial)
    # Deferred: the HELLO rides in the connection request (a round trip saved).
    sock = await serialsocket.connect(port, endpoint, defer=True)
    try:
        async with connect_stream(
            sock, identity=IDENTITY, key=demo.key, observer=options.observer
        ) as client:
            set_link(lambda: _window_figures(sock))
            await drive(client)
            figures.update(client_link_figures(client) | _window_figures(sock))
    finally:
        await sock.aclose()


def _result(
    session: ConsoleSession, figures: dict[str, Any], seconds: float, error: str | None
) -> ConsoleResult:
    run = session.run
    if error is None and run is not None and not run.ok:
        failure = run.first_failure
        if failure is not None:
            error = describe_failure(failure)
    ok = error is None and (run is None or run.count(CommandState.COMPLETED) == len(run.records))
    return ConsoleResult(ok, seconds, session, error, figures)


async def _command_line(options: ConsoleOptions) -> ConsoleResult:
    """``--interactive``: the operator's lines through the command stack, until they end.

    The session as a whole is not bounded (the operator ends it); each wait
    for the arm is (``timeout``)."""
    demo = options.demo
    start = trio.current_time()
    stack = CommandStack(demo.world, origin=start)
    out = options.out if options.out is not None else sys.stderr

    def say(text: str) -> None:
        print(text, file=out, flush=True)

    assert options.lines is not None
    lines = options.lines
    show = options.say or say
    figures: dict[str, Any] = {}
    where = f"{demo.preset or 'custom link'}, virtual time" if demo.virtual else "real time"
    show(
        f"telelink console: command line over {demo.transport} ({where}); "
        "help lists the commands, Tab completes, quit ends"
    )

    async def drive(client: ArmClient) -> None:
        await run_command_line(client, stack, lines, show, timeout=demo.timeout)

    def set_link(probe: Probe) -> None:
        stack.link = probe

    error: str | None = None
    if demo.virtual:
        arm = SimulatedArm(options.arm_world or demo.world)
        rng = random.Random(demo.link.seed)
        server_cfg = ServerConfig(
            key=demo.key, rtt_hint=rtt_hint_for(demo.link), nonce_source=rng.randbytes
        )
        error = await _virtual_session(
            options, arm, rng, server_cfg, figures, drive, set_link, bounded=False
        )
    else:
        try:
            await _real_session(options, figures, drive, set_link)
        except (SessionError, serialsocket.DialError, trio.BrokenResourceError, OSError) as exc:
            error = explain_failure(exc)
    now = trio.current_time()
    summary = stack.summary(now)
    ok = error is None and stack.ok
    return ConsoleResult(ok, now - start, None, error, figures, summary)


def run_console(options: ConsoleOptions) -> ConsoleResult:
    """Run the console to the end (never raises for a failed run)."""
    if options.lines is not None:
        if not options.demo.virtual:
            return run_interruptibly(_command_line, options)
        if options.rate > 0:
            clock = trio.testing.MockClock(rate=options.rate)
        else:
            clock = trio.testing.MockClock(autojump_threshold=0)
        return run_virtual(_command_line, options, clock=clock)
    if options.demo.virtual:
        if options.rate > 0:
            clock = trio.testing.MockClock(rate=options.rate)
        else:
            clock = trio.testing.MockClock(autojump_threshold=0)
        return run_virtual(_virtual, options, clock=clock)
    return run_interruptibly(_real, options)
