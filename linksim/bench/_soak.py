"""The soak (issue 11): hours of command traffic and bulk data over noisy-moon with outages.

``linksim soak --hours 24`` (``make soak``) runs, on trio's virtual
clock, two independent noisy-moon lines that share one outage schedule (an
outage every ``outage_every`` hours, lengths cycling through
``OUTAGE_LENGTHS``):

* **commands**: a controller (:class:`tcpstream.ArmClient`) drives the
  :class:`SimulatedArm` behind a :class:`tcpstream.Server` through a serial
  socket: joint moves back and forth, gripper, speed changes -- the kinds of command
  the demo's rock task sends, each one unique (its last argument word carries its
  number) so an execution can be attributed.  An outage longer than the
  session's deadman ends the session (the arm halts); the client reconnects
  over a fresh serial socket once the line is back and resumes: commands in
  flight are answered from the arm's exactly-once memory, never run again.
* **bulk data**: a serial socket pair carries seeded pseudo-random bytes both
  ways at once, continuously.  Its ARQ is told to ride out outages
  (``dead_after`` beyond the longest one), so the same connection lasts the
  whole soak.  Each receiver checks every byte against the sender's generator:
  a lost, duplicated, reordered or corrupted byte fails at once.

The report counts bytes, commands, executions, outages, deadman stops and
traced memory (tracemalloc) sampled every simulated hour.  :func:`check`
turns it into a verdict: zero bytes lost, duplicated or reordered; zero
commands executed twice; one deadman stop inside every outage longer than the
deadman and no halt anywhere else but the server's STOPPED at shutdown; live
memory (sampled after a garbage collection) flat after the first hour.
"""

from __future__ import annotations

import dataclasses
import gc
import random
import sys
import time
import tracemalloc
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import trio
import trio.testing

from linksim.arm import SimulatedArm
from linksim.link import (
    LinkConfig,
    Outage,
    endpoint_config_for,
    rtt_hint_for,
    run_virtual,
    serial_socket_pair,
)
from serialsocket import SerialSocket
from tcpstream import (
    ArmClient,
    Command,
    CommandFailed,
    CommandResult,
    FailureReason,
    Feedback,
    Server,
    ServerConfig,
    SessionError,
    commands,
)

__all__ = ["OUTAGE_LENGTHS", "SoakReport", "check", "run_soak"]

OUTAGE_LENGTHS = (30.0, 300.0, 5.0, 900.0)
"""Seconds, in turn: one well past the deadman, one of five minutes, one shorter
than the deadman (the session must ride it out), one of a quarter hour."""
RIDE_OUT = 3600.0
"""``dead_after`` and ``connect_timeout`` of every serial endpoint (s): longer than
any outage, so the ARQ keeps its connection and only the session's deadman acts."""
BULK_CHUNK = 512
"""Bytes per bulk write: a few packets, so commands and data interleave finely."""
MEMORY_SLACK = 1536 * 1024
"""Traced memory may grow this much between the end of hour 1 and the end (bytes):
room for the arm's exactly-once memory filling up to its bound (1024 stored
replies of ~1 KB; at ~320 commands an hour that takes the first three hours),
not for a leak -- 64 KB an hour over 24 hours would exceed it."""


@dataclass(slots=True)
class SoakReport:
    """What a soak did; :meth:`as_dict` is the JSON printed by :func:`main`."""

    hours: float
    seed: int
    cpu_seconds: float = 0.0
    bulk_sent: dict[str, int] = field(default_factory=dict)
    bulk_verified: dict[str, int] = field(default_factory=dict)
    bulk_errors: list[str] = field(default_factory=list)
    commands_submitted: int = 0
    commands_completed: int = 0
    commands_failed: dict[str, int] = field(default_factory=dict)
    executions: int = 0
    executed_twice: int = 0
    reconnects: int = 0
    outages: list[tuple[float, float]] = field(default_factory=list)
    deadman: float = 0.0
    halts: list[tuple[float, str]] = field(default_factory=list)
    memory_samples: list[int] = field(default_factory=list)
    error: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


class _CountingArm:
    """The simulated arm, with every execution and halt recorded (the soak's witness)."""

    def __init__(self, arm: SimulatedArm, report: SoakReport) -> None:
        self._arm = arm
        self._report = report
        self._last = 0

    @property
    def control_rate_hz(self) -> float:
        return self._arm.control_rate_hz

    async def execute(self, command: Command) -> CommandResult:
        # The traffic is sequential and numbered (last argument word): a command
        # run twice shows up as a number not above the last one run.  O(1)
        # memory, so the witness does not itself grow the traced memory.
        self._report.executions += 1
        number = int(command.args[-1])
        if number <= self._last:
            self._report.executed_twice += 1
        self._last = max(self._last, number)
        return await self._arm.execute(command)

    def halt(self, reason: FailureReason) -> None:
        self._report.halts.append((trio.current_time(), reason.name))
        self._arm.halt(reason)

    def state(self) -> Feedback:
        return self._arm.state()


def _schedule(hours: float, every_hours: float) -> list[Outage]:
    out: list[Outage] = []
    t = every_hours * 3600.0
    i = 0
    while t < hours * 3600.0:
        length = OUTAGE_LENGTHS[i % len(OUTAGE_LENGTHS)]
        out.append(Outage(t, t + length))
        t += every_hours * 3600.0
        i += 1
    return out


def _with_outages(link: LinkConfig, outages: Sequence[Outage], origin: float) -> LinkConfig:
    """``link`` with the schedule's outages, in the link time of a line opened at ``origin``."""
    shifted = tuple(
        Outage(max(0.0, o.start - origin), o.end - origin) for o in outages if o.end > origin
    )
    return dataclasses.replace(
        link,
        a_to_b=dataclasses.replace(link.a_to_b, outages=shifted),
        b_to_a=dataclasses.replace(link.b_to_a, outages=shifted),
    )


def _command(i: int) -> Command:
    """The i-th command of the traffic: harmless motions, numbered in the last
    argument word (unused by these commands) so each execution is attributable."""
    kind = i % 5
    if kind in (0, 1):
        base = commands.move_joint(1 + i % 3, 0.02 if kind == 0 else -0.02)
    elif kind == 2:
        base = commands.open_fingers(0.01)
    elif kind == 3:
        base = commands.change_speed(0.5)
    else:
        base = commands.move_joint(4 + i % 3, 0.0)
    return dataclasses.replace(base, args=(*base.args[:-1], float(i)))


async def _bulk_writer(sock: SerialSocket, rng: random.Random, end: float, sent: list[int]) -> None:
    while trio.current_time() < end:
        chunk = rng.randbytes(BULK_CHUNK)
        await sock.send_all(chunk)
        sent[0] += len(chunk)
    await sock.send_eof()


async def _bulk_reader(
    sock: SerialSocket, rng: random.Random, verified: list[int], errors: list[str]
) -> None:
    pending = b""
    while True:
        data = await sock.receive_some(4096)
        if not data:
            return
        pending += data
        while len(pending) >= BULK_CHUNK:
            expected = rng.randbytes(BULK_CHUNK)
            if pending[:BULK_CHUNK] != expected:
                errors.append(f"mismatch after {verified[0]} good bytes")
                return
            pending = pending[BULK_CHUNK:]
            verified[0] += BULK_CHUNK


async def _command_traffic(client: ArmClient, report: SoakReport, end: float) -> None:
    i = 0
    while trio.current_time() < end:
        i += 1
        report.commands_submitted += 1
        try:
            await client.send(_command(i))
        except CommandFailed as exc:
            name = exc.reason.name
            report.commands_failed[name] = report.commands_failed.get(name, 0) + 1
        else:
            report.commands_completed += 1


async def _soak(report: SoakReport, outage_every: float, bulk: bool, progress: bool) -> None:
    seed = report.seed
    end = report.hours * 3600.0
    outages = _schedule(report.hours, outage_every)
    report.outages = [(o.start, o.end) for o in outages]
    base = LinkConfig.preset("noisy-moon", seed=seed)
    ep = endpoint_config_for(base, dead_after=RIDE_OUT, connect_timeout=RIDE_OUT)
    rng = random.Random(seed)
    server_cfg = ServerConfig(rtt_hint=rtt_hint_for(base), nonce_source=rng.randbytes)
    report.deadman = server_cfg.timing()[1]
    arm = _CountingArm(SimulatedArm(), report)
    lines = 0
    sent = {"a_to_b": [0], "b_to_a": [0]}
    verified = {"a_to_b": [0], "b_to_a": [0]}

    async with Server(arm, server_cfg) as server, trio.open_nursery() as nursery:

        async def hold_line(*, task_status: trio.TaskStatus[SerialSocket]) -> None:
            """One command line: open while the server serves the session over it."""
            nonlocal lines
            lines += 1
            link = _with_outages(
                dataclasses.replace(base, seed=seed + lines), outages, trio.current_time()
            )
            async with serial_socket_pair(link, endpoint=ep) as (ctl, arm_end):
                task_status.started(ctl)
                await server.serve_stream(arm_end)

        async def factory() -> trio.abc.Stream:
            stream: SerialSocket = await nursery.start(hold_line)
            return stream

        async def sample_memory() -> None:
            while True:
                await trio.sleep(3600.0)
                # Live memory, not garbage awaiting the cycle collector: trio's
                # cancel scopes and caught exceptions form reference cycles, and
                # when the oldest generation was last collected would otherwise
                # move the sample by hundreds of kB.
                gc.collect()
                report.memory_samples.append(tracemalloc.get_traced_memory()[0])
                if progress:
                    print(
                        f"[soak] hour {len(report.memory_samples)}: "
                        f"{report.commands_completed} commands, "
                        f"bulk {verified['a_to_b'][0]}/{verified['b_to_a'][0]} B verified, "
                        f"{len(report.halts)} halts, memory {report.memory_samples[-1]} B, "
                        f"cpu {time.process_time():.0f} s",
                        file=sys.stderr,
                        flush=True,
                    )

        async def bulk_both_ways() -> None:
            link = _with_outages(dataclasses.replace(base, seed=seed + 100_000), outages, 0.0)
            async with (
                serial_socket_pair(link, endpoint=ep) as (a, b),
                trio.open_nursery() as flows,
            ):
                for name, src, dst, n in (("a_to_b", a, b, 1), ("b_to_a", b, a, 2)):
                    gen = 1000 * seed + n
                    flows.start_soon(_bulk_writer, src, random.Random(gen), end, sent[name])
                    flows.start_soon(
                        _bulk_reader, dst, random.Random(gen), verified[name], report.bulk_errors
                    )

        nursery.start_soon(sample_memory)
        try:
            async with trio.open_nursery() as work:
                if bulk:
                    work.start_soon(bulk_both_ways)
                async with ArmClient(
                    factory,
                    identity="soak",
                    reconnect_attempts=64,
                    reconnect_delay=1.0,
                    incarnation=rng.getrandbits(64),
                    nonce_source=rng.randbytes,
                ) as client:
                    await _command_traffic(client, report, end)
                    report.reconnects = client.reconnects
        except SessionError as exc:
            report.error = f"the command session was lost: {exc}"
        nursery.cancel_scope.cancel()
    report.bulk_sent = {k: v[0] for k, v in sent.items()}
    report.bulk_verified = {k: v[0] for k, v in verified.items()}


def run_soak(
    hours: float = 24.0,
    seed: int = 0,
    *,
    outage_every: float = 3.0,
    bulk: bool = True,
    progress: bool = False,
) -> SoakReport:
    """Run the soak for ``hours`` of simulated time; the report (see :func:`check`).

    ``progress`` prints one line per simulated hour to stderr.
    """
    report = SoakReport(hours=hours, seed=seed)
    started = time.process_time()
    tracing = tracemalloc.is_tracing()
    if not tracing:
        tracemalloc.start()
    try:
        run_virtual(_soak, report, outage_every, bulk, progress)
    finally:
        if not tracing:
            tracemalloc.stop()
    report.cpu_seconds = time.process_time() - started
    return report


def check(report: SoakReport) -> list[str]:
    """Everything the soak must show; an empty list means it passed."""
    problems: list[str] = []
    if report.error:
        problems.append(report.error)
    problems += report.bulk_errors
    for name, n in report.bulk_sent.items():
        if report.bulk_verified.get(name) != n:
            problems.append(f"bulk {name}: sent {n}, verified {report.bulk_verified.get(name)}")
    if report.executed_twice:
        problems.append(f"{report.executed_twice} commands executed twice")
    if report.executions > report.commands_submitted:
        problems.append(f"{report.executions} executions of {report.commands_submitted} commands")
    end = report.hours * 3600.0
    deadman = [t for t, why in report.halts if why == FailureReason.DEADMAN.name]
    for start, stop in report.outages:
        if stop - start <= report.deadman:
            continue
        stops = [t for t in deadman if start <= t <= start + report.deadman + 1.0]
        if len(stops) != 1:
            problems.append(f"outage {start:.0f}-{stop:.0f} s: {len(stops)} deadman stops")
    # Every halt is accounted for: a deadman stop only inside a long outage (a
    # trip on a healthy line would be a false alarm), and otherwise only the
    # server's own STOPPED when the soak shuts it down after its last command.
    long_outages = [(a, b) for a, b in report.outages if b - a > report.deadman]
    for t, why in report.halts:
        if why == FailureReason.DEADMAN.name:
            if not any(a <= t <= a + report.deadman + 1.0 for a, _ in long_outages):
                problems.append(f"deadman stop at {t:.0f} s outside any long outage")
        elif not (why == FailureReason.STOPPED.name and t >= end):
            problems.append(f"unexpected halt {why} at {t:.0f} s")
    samples = report.memory_samples
    if len(samples) >= 2 and max(samples[1:]) - samples[0] > MEMORY_SLACK:
        problems.append(f"traced memory grew from {samples[0]} to {max(samples[1:])} bytes")
    return problems
