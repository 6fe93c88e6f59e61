"""Setpoint age on noisy-moon, every mode, both tasks, seeds 1-3, and where its tail comes from.

Writes one JSON line per run to stdout (``bench/results/teleop-age-noisy-moon.jsonl``)::

    .venv/bin/python bench/results/teleop-age-matrix.py > bench/results/teleop-age-noisy-moon.jsonl

Each run is ``linksim teleop --virtual --preset noisy-moon --mode M --task T --seed S``
(shared compliance).  Besides the report's ``setpoint_age_s`` it classifies every
sample the arm applied: *released by a repair* when it took more than one way +
0.6 s from the operator's channel handing it to the serial socket to the arm's
channel reading it (a sample that waits behind nothing takes one way + 0.3-0.45 s:
its line time and the receiver's FIFO), i.e. it waited at the receiver for the
retransmission of a lost packet ahead of it, or was that packet; else *direct*.
The probes wrap the channel ends' private methods: a measurement, not an API.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from linksim.link import run_virtual
from linksim.teleop import TeleopOptions, _remote, run_teleop
from tcpstream import _teleop_connection as tc
from tcpstream.teleop import SampleArrived, TeleopMode

sent: dict[int, float] = {}
arrived: dict[int, float] = {}
applied: list[tuple[int, float]] = []

_poll = tc.OperatorChannel.poll
_dispatch = tc.ArmChannel._dispatch
_apply = _remote.RemoteArm._apply


def poll(self: tc.OperatorChannel, now: float, backlog: Any = None) -> bool:
    pending = self.pending
    went = _poll(self, now, backlog)
    if went and pending is not None and self.pending is None:
        sent[pending.sample] = now
    return went


def dispatch(self: tc.ArmChannel, kind: Any, raw: bytes, now: float) -> Any:
    events = _dispatch(self, kind, raw, now)
    for ev in events:
        if isinstance(ev, SampleArrived):
            arrived[ev.sample.sample] = now
    return events


def apply(self: _remote.RemoteArm, s: Any, arrived: float, now: float) -> None:
    applied.append((s.sample, now - s.stamp))
    _apply(self, s, arrived, now)


tc.OperatorChannel.poll = poll  # type: ignore[method-assign]
tc.ArmChannel._dispatch = dispatch  # type: ignore[method-assign]
_remote.RemoteArm._apply = apply  # type: ignore[method-assign]


def main() -> None:
    for mode in ("joint", "cartesian", "rate", "index"):
        for task in ("surface", "peg"):
            for seed in (1, 2, 3):
                sent.clear()
                arrived.clear()
                applied.clear()
                options = TeleopOptions(mode=TeleopMode[mode.upper()], task=task, seed=seed)
                r = run_virtual(run_teleop, options)
                held = {n for n in arrived if arrived[n] - sent[n] > r.one_way_delay_s + 0.6}
                repaired = [age for n, age in applied if n in held]
                direct = [age for n, age in applied if n not in held]
                row = {
                    "mode": mode,
                    "task": task,
                    "seed": seed,
                    "ok": r.ok,
                    "setpoint_age_s": r.setpoint_age_s,
                    "samples_sent": r.samples_sent,
                    "samples_applied": r.samples_applied,
                    "released_by_repair": len(repaired),
                    "repair_ages_s": sorted(repaired),
                    "direct_age_s": {
                        "p50": float(np.percentile(direct, 50)) if direct else None,
                        "p99": float(np.percentile(direct, 99)) if direct else None,
                        "max": max(direct) if direct else None,
                    },
                }
                print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
