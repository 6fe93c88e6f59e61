"""The demo's options and its report: what ran, what the link did, where the arm ended.

:class:`DemoOptions` says what to run; :class:`DemoReport` is the outcome
(:meth:`DemoReport.as_dict` is the ``--json`` object, :func:`print_report`
the readable summary).  The figures helpers read a serial socket's or a
command session's counters; the failure helpers put a failed run in words.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from typing import Any

import serialsocket
from linksim.arm import DEFAULT_WORLD, WorldConfig
from linksim.control import CommandRecord, CommandState, TaskRun, feedback_record
from linksim.link import LinkConfig
from tcpstream import ArmClient

__all__ = [
    "IDENTITY",
    "DemoOptions",
    "DemoReport",
    "add_rates",
    "client_link_figures",
    "describe_failure",
    "explain_failure",
    "line_capacity",
    "make_report",
    "print_report",
    "serial_link_figures",
]

IDENTITY = "linksim-demo"


@dataclass(frozen=True, slots=True)
class DemoOptions:
    """What to run.  ``link`` impairs the serial line (TCP runs on clean loopback)."""

    link: LinkConfig
    preset: str | None = "noisy-moon"
    transport: str = "serial"
    virtual: bool = False
    dial: str | None = None
    window: int | None = None
    max_len: int | None = None
    world: WorldConfig = DEFAULT_WORLD
    key: bytes | None = None
    progress: bool = True
    live: bool | None = None
    """Redrawn table (True), plain lines (False), or whatever stderr is (None)."""
    timeout: float = 600.0
    """Bound on the whole run, seconds of the run's clock (the command line
    derives it from the line: :func:`run_time_limit`)."""


RUN_ROUND_TRIPS = 40
"""Round trips of the line a whole run is given (connect, authenticate, the
commands and their replies, close: a dozen; the rest is margin)."""


def run_time_limit(link: LinkConfig) -> float:
    """The default bound on a run over ``link``: 600 s, or :data:`RUN_ROUND_TRIPS`
    round trips where that is longer (Mars: 40 minutes a round trip)."""
    delay = max(link.a_to_b.delay + link.a_to_b.jitter, link.b_to_a.delay + link.b_to_a.jitter)
    return max(600.0, RUN_ROUND_TRIPS * 2 * delay)


@dataclass(slots=True)
class DemoReport:
    """The outcome; :meth:`as_dict` is the ``--json`` object."""

    ok: bool
    transport: str
    virtual: bool
    preset: str | None
    seconds: float
    run: TaskRun | None
    link: dict[str, Any]
    error: str | None = None

    def as_dict(self) -> dict[str, Any]:
        run = self.run
        commands = {"sent": 0, "completed": 0, "failed": 0, "total": 0}
        arm: dict[str, Any] | None = None
        log: list[dict[str, Any]] = []
        if run is not None:
            commands = {
                "sent": run.sent,
                "completed": run.count(CommandState.COMPLETED),
                "failed": run.count(CommandState.FAILED),
                "total": len(run.records),
            }
            final = run.final_feedback
            if final is not None:
                arm = feedback_record(final)
                mass = run.weighed_mass
                arm["weighed_mass_kg"] = None if mass is None else round(mass, 4)
            log = [r.as_dict(run.started_at) for r in run.records]
        return {
            "ok": self.ok,
            "transport": self.transport,
            "virtual": self.virtual,
            "preset": self.preset,
            "seconds": round(self.seconds, 3),
            "commands": commands,
            "link": self.link,
            "arm": arm,
            "command_log": log,
            "error": self.error,
        }


def serial_link_figures(sock: serialsocket.SerialSocket) -> dict[str, Any]:
    """The figures an operator reads off a serial socket."""
    s = sock.statistics().link
    return {
        "rtt_s": s.smoothed_rtt,
        "timeout_s": round(s.timeout, 3),
        "retransmissions": s.retransmissions,
        "timeouts": s.timeouts,
        "naks_sent": s.naks_sent,
        "naks_received": s.naks_received,
        "check_failures": s.check_failures,
        "garbage_bytes": s.garbage_bytes,
        "packets_sent": s.packets_sent,
        "packets_received": s.packets_received,
        "bytes_sent": s.bytes_acknowledged,
        "bytes_received": s.bytes_delivered,
        "wire_bytes_sent": s.wire_bytes_sent,
        "wire_bytes_received": s.wire_bytes_received,
    }


def client_link_figures(client: ArmClient) -> dict[str, Any]:
    """What the command session itself counted (all a TCP run has)."""
    stats = client.statistics()
    out: dict[str, Any] = {
        "reconnects": stats.reconnects,
        "telemetry_dropped": stats.telemetry_dropped,
        "bytes_sent": stats.bytes_sent,
        "bytes_received": stats.bytes_received,
    }
    if stats.connection is not None:
        out["packets_sent"] = stats.connection.packets_out
        out["packets_received"] = stats.connection.packets_in
    return out


def line_capacity(link: LinkConfig) -> tuple[float | None, float | None]:
    """Characters per second the line carries controller -> arm and back (None: unlimited)."""
    return tuple(  # type: ignore[return-value]
        d.rate / d.bits_per_char if d.rate is not None else None for d in (link.a_to_b, link.b_to_a)
    )


def add_rates(
    figures: dict[str, Any],
    seconds: float,
    capacity: tuple[float | None, float | None] = (None, None),
) -> None:
    """Each direction's payload rate, and how busy the line was, with units in the names.

    ``payload_*_Bps`` is one direction's application bytes (delivered and
    acknowledged) over the whole run: the same meaning as ``goodput_Bps`` in
    ``linksim bench goodput``, but over a run that also waits on the arm, so
    it is no measure of the line's speed.  ``line_use_*`` is the fraction of
    that direction's capacity (``capacity``, characters per second) the wire
    bytes took -- data, retransmissions, ACKs, heartbeats, telemetry -- where
    both are known.
    """
    if seconds <= 0:
        return
    for way, payload_key, wire_key, cps in (
        ("sent", "bytes_sent", "wire_bytes_sent", capacity[0]),
        ("received", "bytes_received", "wire_bytes_received", capacity[1]),
    ):
        figures[f"payload_{way}_Bps"] = round(int(figures.get(payload_key, 0)) / seconds, 1)
        if cps is not None and wire_key in figures:
            figures[f"line_use_{way}"] = round(int(figures[wire_key]) / (cps * seconds), 3)


def make_report(
    options: DemoOptions,
    run: TaskRun | None,
    figures: dict[str, Any],
    seconds: float,
    error: str | None,
) -> DemoReport:
    if error is None and run is not None and not run.ok:
        failure = run.first_failure
        if failure is not None:
            error = describe_failure(failure)
    ok = error is None and run is not None and run.ok
    return DemoReport(
        ok, options.transport, options.virtual, options.preset, seconds, run, figures, error
    )


_SESSION_ENDINGS = frozenset({"OutcomeUnknown", "SessionClosed", "WatchdogExpired"})
"""Record reasons that are the session's end, not the arm's answer."""


def describe_failure(failure: CommandRecord) -> str:
    """What went wrong, in words: the arm refusing a command is not the link dying."""
    if failure.reason in _SESSION_ENDINGS:
        command = f"#{failure.index} ({failure.label})"
        return f"the link failed with command {command} unanswered: {failure.error}"
    if failure.reason == "NOT_RUN":
        return f"command #{failure.index} ({failure.label}) was not run: {failure.error}"
    return f"the arm refused command #{failure.index} ({failure.label}): {failure.error}"


def explain_failure(exc: BaseException) -> str:
    cause = exc.__cause__
    text = str(exc) or type(exc).__name__
    if cause is not None and str(cause) and str(cause) not in text:
        text += f" ({cause})"
    return text


def print_report(report: DemoReport, *, as_json: bool) -> None:
    """The final report on stdout: one JSON object, or a readable summary.

    Results go to stdout and progress to stderr, so ``linksim demo > run.txt``
    keeps the report and ``--json | jq`` sees only JSON.
    """
    data = report.as_dict()
    if as_json:
        json.dump(data, sys.stdout)
        sys.stdout.write("\n")
        sys.stdout.flush()
        return
    out = sys.stdout
    c = data["commands"]
    clock = "virtual" if report.virtual else "wall-clock"
    print(
        f"\n{'OK' if report.ok else 'FAILED'}: {c['completed']}/{c['total']} commands completed, "
        f"{c['failed']} failed, {c['sent']} sent, {report.seconds:.1f} s ({clock}) "
        f"over {report.transport}",
        file=out,
    )
    link = data["link"]
    if link:
        keys = (
            "rtt_s",
            "bytes_sent",
            "bytes_received",
            "payload_sent_Bps",
            "payload_received_Bps",
            "line_use_sent",
            "line_use_received",
            "retransmissions",
            "check_failures",
            "naks_received",
            "reconnects",
        )
        shown = ", ".join(
            f"{k} {round(link[k], 3):g}" if isinstance(link[k], float) else f"{k} {link[k]}"
            for k in keys
            if k in link and link[k] is not None
        )
        print(f"link: {shown}", file=out)
    arm = data["arm"]
    if arm is not None:
        joints = ", ".join(f"{q:.1f}" for q in arm["joints_deg"])
        p = ", ".join(f"{x:.3f}" for x in arm["p"])
        print(f"arm: joints ({joints}) deg, hand at ({p}) m", file=out)
        if arm.get("weighed_mass_kg") is not None:
            print(f"     weighed {arm['weighed_mass_kg']:.3f} kg", file=out)
    if report.error:
        print(f"error: {report.error}", file=out)
