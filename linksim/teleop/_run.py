"""``linksim teleop``: the operator, the line and the remote arm in one run.

The operator's loop samples the FRHC at 104 Hz (seed 004's closed loop) and
submits every sample to the teleoperation channel; the arm's loop runs at
125 Hz, applies the newest sample that arrived and answers.  The channel
runs over the same transports as ``linksim demo``: a serial socket on the
impaired line (its pacing from the socket's own figures), or TCP (the line's
delay; TCP repairs the rest), on a virtual clock; or real TCP over loopback
on the wall clock (the latency benchmark).
"""

from __future__ import annotations

import contextlib
import math
import random
import sys
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import trio

from linksim.arm import DEFAULT_WORLD, PUMA560, hand_frame
from linksim.control import ConsoleSession, render_plain
from linksim.link import (
    LinkConfig,
    rtt_hint_for,
)
from tcpstream import ArmClient, Server, ServerConfig, SessionError, connect_stream
from tcpstream.commands import emergency_stop
from tcpstream.teleop import (
    ChannelStatistics,
    Reply,
    Sample,
    TeleopArm,
    TeleopMode,
    TeleopOperator,
    TeleopRefused,
    open_teleop,
)

from ._contact import ContactModel, Hole
from ._executor import TeleopExecutor
from ._keyboard import KeyboardScript, read_keys
from ._operator import Intent, Operator, Script, peg_script, surface_script
from ._remote import RemoteArm, RemoteConfig, rate_deadman, rotation
from ._transport import SAMPLE_RATE, SerialFigures, line_interval, open_channels
from ._view import ViewState, render

__all__ = [
    "CONTROL_RATE",
    "IDENTITY",
    "TeleopOptions",
    "TeleopReport",
    "percentile",
    "run_teleop",
    "script_for",
    "world_for",
]

IDENTITY = "teleop-operator"
STOP_SETTLE = 0.005
"""m: how far the hand may coast while the servo settles after a stop."""
COMMAND_HEARTBEAT = 10.0
"""s: the command session's heartbeat beside a sample stream (samples show the line
is alive; at 2400 bit/s a 216-byte heartbeat takes 1.6 s of line)."""
CONTROL_RATE = 125.0
"""Hz: the arm's control loop (seed 000's sample rate)."""
TABLE_DROP = 0.10
"""The table is this far below the hand's start (m)."""


@dataclass(frozen=True, slots=True)
class TeleopOptions:
    mode: TeleopMode = TeleopMode.CARTESIAN
    task: str = "surface"
    scheme: str = "shared-compliance"
    """"shared-compliance" or "force-reflection"."""
    transport: str = "serial"
    """"serial" or "tcp" (virtual), "loopback" (real TCP, wall clock)."""
    preset: str = "noisy-moon"
    seed: int = 1
    key: bytes | None = None
    stop_at: float | None = None
    """Script seconds at which the operator presses the emergency stop."""
    force_stop: bool = True
    real: bool = False
    """Serial only: real ptys joined by the impaired relay, on the wall clock."""
    keyboard: bool = False
    """A person drives the hand controller from the keyboard (stdin) instead of the script."""
    live: bool = False
    """Show the teleoperation view on stderr while the run goes (a terminal only)."""
    commands: bool = False
    """Run the command session beside the sample channel, on the same line (the mux)."""
    stop_via: str = "teleop"
    """Where ``stop_at`` sends the emergency stop: the sample channel's STOP ("teleop")
    or the command session's EMERGENCY_STOP ("command", needs ``commands``)."""
    duration: float | None = None
    """Script seconds to run (default: the script, then the line's round trip and 1 s)."""
    timeout: float = 600.0
    link: LinkConfig | None = None
    """The line itself, instead of ``preset`` and ``seed`` (e.g. with scripted faults)."""


@dataclass
class TeleopReport:
    ok: bool
    mode: str
    task: str
    scheme: str
    transport: str
    preset: str
    one_way_delay_s: float
    samples_sampled: int
    samples_sent: int
    samples_coalesced: int
    samples_received: int
    samples_superseded: int
    samples_applied: int
    setpoint_age_s: dict[str, float]
    max_contact_force_n: float
    force_limit_n: float
    compliance_force_n: float
    force_limit_stops: int
    emergency_stops: int
    samples_after_stop: int
    moved_after_stop_m: float
    bounces: int
    pose_changes: int
    deadman_trips: int
    rate_deadman_s: float
    replies_received: int
    line_queue_max_s: float | None
    """Serial: the most line time ever committed ahead of a sample (no queue grows)."""
    stop_to_arm_s: float | None
    seconds: float
    error: str | None = None
    force_trace: list[tuple[float, float]] = field(default_factory=list)
    samples_on_lane: int = 0
    """Samples sent on the transport's latest-value lane (serial socket between
    telelink ends, tcpstream/PROTOCOL.md 14.8) rather than in the stream."""

    def to_json(self) -> dict[str, Any]:
        data = asdict(self)
        data.pop("force_trace")
        return data


def script_for(task: str, mode: TeleopMode) -> Script:
    """The task's script in ``mode``; the JOINT one is derived from the arm's start
    joints (:func:`world_for`'s) under the default :class:`RemoteConfig` mapping, as
    :func:`run_teleop` builds the arm."""
    if task not in ("surface", "peg"):
        raise ValueError(f"task must be surface or peg, got {task!r}")
    start = world_for(task)[1]
    if task == "surface":
        return surface_script(mode, drop=TABLE_DROP, start=start)
    return peg_script(mode, hole=(0.05, 0.0), above=0.08, start=start)


def world_for(task: str) -> tuple[ContactModel, np.ndarray[Any, np.dtype[np.float64]]]:
    """The contact world around the hand's start pose, and that pose's joints."""
    q0 = np.array(DEFAULT_WORLD.initial_joints, dtype=np.float64)
    p0 = hand_frame(PUMA560, q0)[:3, 3]
    table = float(p0[2]) - TABLE_DROP
    if task == "peg":
        top = float(p0[2]) - 0.08
        hole = Hole(centre=(float(p0[0]) + 0.05, float(p0[1])), top=top)
        return ContactModel(table_z=top - 0.06, hole=hole), q0
    return ContactModel(table_z=table), q0


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(np.array(values), q)) if values else math.nan


async def run_teleop(options: TeleopOptions) -> TeleopReport:
    """One run on whatever clock trio has (virtual under ``run_virtual``)."""
    link = options.link or LinkConfig.preset(options.preset, seed=options.seed)
    one_way = link.a_to_b.delay + link.a_to_b.jitter
    keys = KeyboardScript() if options.keyboard else None
    script: Intent = keys if keys is not None else script_for(options.task, options.mode)
    duration = options.duration or script.duration + 2 * one_way + 1.0
    contact, q0 = world_for(options.task)
    deadman = rate_deadman(one_way, line_interval(link))
    remote = RemoteArm(
        RemoteConfig(
            control_rate=CONTROL_RATE, rate_deadman=deadman, force_stop=options.force_stop
        ),
        contact,
        q0,
    )
    operator = Operator(
        script,
        options.mode,
        force_reflection=options.scheme == "force-reflection",
        shared_compliance=options.scheme == "shared-compliance",
    )
    rng = random.Random(options.seed)
    stop_sent: float | None = None
    stop_arrived: list[float] = []

    def on_stop() -> None:
        stop_arrived.append(trio.current_time())
        remote.emergency_stop()

    arm_end = TeleopArm(
        key=options.key,
        rate_deadman=deadman,
        control_rate=CONTROL_RATE,
        on_stop=on_stop,
        nonce_source=rng.randbytes,
    )
    executor = TeleopExecutor(remote, on_stop)
    view = _ViewFeed(operator, remote.config.force_limit, one_way)
    console = (
        ConsoleSession(
            f"linksim teleop: {options.mode.name.lower()}, {options.task}, {options.scheme}",
            DEFAULT_WORLD,
            run=None,
            clock=trio.current_time,
            origin=trio.current_time(),
            out=sys.stderr,
        )
        if options.live
        else None
    )
    error: str | None = None
    op_stats = None
    final_view: ViewState | None = None
    figures: dict[str, SerialFigures] = {}
    start = trio.current_time()
    with trio.move_on_after(options.timeout) as scope:
        async with (
            open_channels(options.transport, options.real, options.commands, link, figures) as (
                ctl,
                arm_stream,
                ctl_backlog,
                arm_backlog,
                ctl_cmd,
                arm_cmd,
            ),
            trio.open_nursery() as nursery,
        ):
            nursery.start_soon(lambda: arm_end.serve_stream(arm_stream, backlog=arm_backlog))
            nursery.start_soon(_arm_loop, arm_end, remote)
            try:
                async with contextlib.AsyncExitStack() as stack:
                    client: ArmClient | None = None
                    if ctl_cmd is not None and arm_cmd is not None:
                        server_cfg = ServerConfig(
                            key=options.key,
                            rtt_hint=rtt_hint_for(link),
                            heartbeat_interval=COMMAND_HEARTBEAT,
                            # The samples' replies carry the state: telemetry every 10 s.
                            telemetry_every=int(CONTROL_RATE * COMMAND_HEARTBEAT),
                            nonce_source=rng.randbytes,
                        )
                        server = await stack.enter_async_context(Server(executor, server_cfg))
                        nursery.start_soon(server.serve_stream, arm_cmd)
                        client = await stack.enter_async_context(
                            connect_stream(
                                ctl_cmd,
                                identity=IDENTITY,
                                key=options.key,
                                incarnation=rng.getrandbits(64),
                                nonce_source=rng.randbytes,
                            )
                        )
                    op = await stack.enter_async_context(
                        open_teleop(
                            ctl,
                            identity=IDENTITY,
                            key=options.key,
                            backlog=ctl_backlog,
                            on_reply=view.on_reply,
                            nonce_source=rng.randbytes,
                        )
                    )
                    if console is not None:
                        # The console's teleoperating mode: the view, and the line's figures.
                        console.teleop = lambda: render(
                            view.state(trio.current_time(), op.statistics())
                        )
                        console.link = _link_probe(figures, op)
                        if console.is_live:
                            stack.enter_context(console)
                    t0 = trio.current_time()
                    dt = 1.0 / SAMPLE_RATE
                    k = 0
                    if keys is not None:
                        nursery.start_soon(read_keys, keys)
                    # After the script the hand controller is still sampled until the
                    # channel has taken its newest sample (the writer runs while this
                    # loop sleeps): a sample left waiting for the line with nothing newer
                    # behind it would be sent late -- an age that an operator who keeps
                    # sampling never sees.  Bounded by one round trip of the line.
                    last = duration + 2 * one_way
                    while not (keys is not None and keys.done):
                        await trio.sleep_until(t0 + k * dt)
                        if k * dt > duration and (
                            k * dt > last or stop_sent is not None or op.channel.pending is None
                        ):
                            break
                        now = trio.current_time()
                        stop = options.stop_at
                        if keys is not None and keys.stop_requested:
                            stop = 0.0  # the person pressed x
                        if stop is not None and stop_sent is None and now - t0 >= stop:
                            stop_sent = now
                            if options.stop_via == "command" and client is not None:
                                nursery.start_soon(client.submit, emergency_stop())
                            else:
                                op.emergency_stop()
                        if stop_sent is None:
                            view.sample = operator.sample(now - t0, dt, stamp=now)
                            op.submit(view.sample)
                        if console is not None and k % LIVE_EVERY == 0:
                            console.refresh()
                        k += 1
                    # Let the last sample and its reply cross the line before counting.
                    await trio.sleep(2 * one_way + 2 * line_interval(link) + 0.1)
                    op_stats = op.statistics()
                    final_view = view.state(trio.current_time(), op_stats)
                    executor.armed = False  # the session's end halts the arm: not a stop
            except (TeleopRefused, SessionError) as exc:
                error = str(exc)
            nursery.cancel_scope.cancel()
    if scope.cancelled_caught:
        error = f"the run did not finish within {options.timeout:g} s"
    if console is not None and final_view is not None and not console.is_live:
        shown = final_view
        console.teleop = lambda: render(shown)
        print(render_plain(console.snapshot()), file=sys.stderr)  # the final frame only
    return _report(
        options,
        remote,
        operator,
        op_stats,
        arm_end,
        one_way,
        deadman,
        start,
        error,
        None if stop_sent is None or not stop_arrived else stop_arrived[0] - stop_sent,
        figures.get("operator"),
    )


LIVE_EVERY = 26
"""Samples between redraws of the live view: four a second."""


def _link_probe(
    figures: dict[str, SerialFigures], op: TeleopOperator
) -> Callable[[], Mapping[str, Any]]:
    """The console's link line: the serial socket's own figures, or (TCP) the sample
    channel's."""

    def probe() -> Mapping[str, Any]:
        line = figures.get("operator")
        if line is not None:
            return line.link_figures()
        st = op.statistics()
        return {
            "rtt_s": st.min_rtt if st.min_rtt is not None else math.nan,
            "packets_sent": st.packets_out,
            "packets_received": st.packets_in,
            "bytes_sent": st.bytes_out,
            "bytes_received": st.bytes_in,
        }

    return probe


class _ViewFeed:
    """What the live view shows, gathered as the run goes."""

    def __init__(self, operator: Operator, force_limit: float, one_way: float) -> None:
        self.operator = operator
        self.force_limit = force_limit
        self.one_way = one_way
        self.sample: Sample | None = None
        self.reply: Reply | None = None
        self.reply_at: float | None = None
        self._origin: tuple[float, float, float] | None = None

    def on_reply(self, reply: Reply, now: float) -> None:
        self.operator.on_reply(reply, now)
        if self._origin is None and reply.sample == 0:
            self._origin = (reply.actual[0], reply.actual[1], reply.actual[2])
        self.reply, self.reply_at = reply, now

    def predicted(self) -> tuple[float, float, float] | None:
        """The hand where the operator's own increments put it (Cartesian modes)."""
        if self._origin is None or self.operator.mode in (TeleopMode.JOINT, TeleopMode.RATE):
            return None
        r = rotation(np.array(self.operator.hand_to_robot))
        d = r @ self.operator.sums[:3]
        o = self._origin
        return (o[0] + float(d[0]), o[1] + float(d[1]), o[2] + float(d[2]))

    def state(self, now: float, channel: ChannelStatistics | None) -> ViewState:
        return ViewState(
            now=now,
            sample=self.sample,
            reply=self.reply,
            reply_at=self.reply_at,
            predicted=self.predicted(),
            channel=channel,
            force_limit=self.force_limit,
            one_way_delay=self.one_way,
        )


async def _arm_loop(arm_end: TeleopArm, remote: RemoteArm) -> None:
    dt = 1.0 / remote.config.control_rate
    t0 = trio.current_time()
    k = 1
    while True:
        await trio.sleep_until(t0 + k * dt)
        k += 1
        latest = arm_end.latest()
        reply = remote.step(trio.current_time(), latest)
        if arm_end.connected:
            arm_end.reply(reply)


def _report(
    options: TeleopOptions,
    remote: RemoteArm,
    operator: Operator,
    op_stats: Any,
    arm_end: TeleopArm,
    one_way: float,
    deadman: float,
    start: float,
    error: str | None,
    stop_to_arm: float | None,
    line: SerialFigures | None = None,
) -> TeleopReport:
    st = remote.stats
    ages = st.ages
    sent = op_stats.samples_sent if op_stats is not None else 0
    coalesced = op_stats.samples_coalesced if op_stats is not None else 0
    replies = op_stats.replies_received if op_stats is not None else 0
    limit = remote.config.force_limit
    arm_st = arm_end.statistics()
    ok = error is None and st.samples_applied > 0
    if options.scheme == "shared-compliance":
        ok = ok and st.max_force <= limit
    if options.stop_at is not None:
        # Stopped, and nothing moved it afterwards (samples still on the way are ignored)
        # beyond the servo settling where the stop caught it (a few mm at 0.1 m/s).
        ok = ok and st.emergency_stops == 1 and st.moved_after_stop < STOP_SETTLE
    return TeleopReport(
        ok=ok,
        mode=options.mode.name.lower(),
        task=options.task,
        scheme=options.scheme,
        transport=options.transport,
        preset=options.preset,
        one_way_delay_s=one_way,
        samples_sampled=operator.sampled,
        samples_sent=sent,
        samples_coalesced=coalesced,
        samples_received=arm_st.samples_received if arm_st is not None else 0,
        samples_superseded=arm_st.samples_superseded if arm_st is not None else 0,
        samples_applied=st.samples_applied,
        setpoint_age_s={
            "p50": percentile(ages, 50),
            "p99": percentile(ages, 99),
            "max": max(ages) if ages else math.nan,
        },
        max_contact_force_n=st.max_force,
        force_limit_n=limit,
        compliance_force_n=remote.config.compliance_force,
        force_limit_stops=st.force_limit_stops,
        emergency_stops=st.emergency_stops,
        samples_after_stop=st.samples_after_stop,
        moved_after_stop_m=st.moved_after_stop,
        bounces=st.bounces,
        pose_changes=st.pose_changes,
        deadman_trips=st.deadman_trips,
        rate_deadman_s=deadman,
        replies_received=replies,
        line_queue_max_s=None if line is None else line.max_line,
        stop_to_arm_s=stop_to_arm,
        seconds=trio.current_time() - start,
        error=error,
        force_trace=st.force_trace,
        samples_on_lane=op_stats.lane_packets_out if op_stats is not None else 0,
    )
