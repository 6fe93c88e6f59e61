"""The predictive model: where the arm will be, from what it last confirmed and what is in flight.

Seed 003 section 2.2: the local world model runs ahead of the remote arm so
the operator is not waiting seconds to learn what a command does.  The
:class:`Predictor` keeps

* a **base**: the model's belief (:class:`~linksim.control._preview.ModelState`)
  after the last command whose outcome the arm reported, corrected to the
  state it reported (joints, finger opening, tactile switches);
* the **in-flight** commands: sent, outcome not yet seen, in sending order
  (the arm runs them in that order);
* the **prediction**: the base played through the in-flight commands by the
  local model (:func:`~linksim.control._preview.preview`), recomputed lazily when
  either changes.

When a completion arrives, the command is replayed on the base alone and
its predicted end state is compared with the reported one; telemetry
samples are compared with the predicted path of the command the arm is
running.  Each comparison is a :class:`Divergence`; one beyond the
tolerances is *flagged*: the world differs from the model (an object was
not where expected, an obstacle is missing from the model...).  Either way
the base is then corrected to the arm's report, so the prediction converges
on the real arm as outcomes come in.

Pure and synchronous (no trio calls of its own): callers pass the time.
"""

from __future__ import annotations

import collections
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from linksim._errors import ConfigError
from linksim.arm import DEFAULT_WORLD, WorldConfig
from tcpstream import Command, Feedback

from ._preview import ModelState, PreviewReport, preview

__all__ = ["Divergence", "Predictor"]

JOINT_TOLERANCE = math.radians(1.0)
"""rad: a reported joint further than this from the model's is flagged.  The
model is exact on the same world, so anything above numerical noise means
the world differs; 1 degree leaves room for telemetry taken between samples."""

POSITION_TOLERANCE = 0.005
"""m: hand position difference flagged (5 mm, the grasp check's slack)."""

OPENING_TOLERANCE = 0.002
"""m: finger opening difference flagged (an object of another size was grasped)."""

MAX_RECORDS = 1000
"""Divergence records kept (the newest); counters cover all of them.  A
telemetry sample every 80 ms of motion makes this the last minute or so."""

NOT_RUN = frozenset({"SKIPPED", "STOPPED", "DEADMAN", "NOT_RUN"})
"""Remote outcomes that say the command did not run as planned for reasons
of the session (a stop, an earlier failure), not of the world."""


@dataclass(frozen=True, slots=True)
class Divergence:
    """One comparison of the arm's report with the model's prediction.

    ``source`` is ``"completion"`` (end state of command ``index``) or
    ``"telemetry"`` (distance from the predicted path of the running
    command).  Errors: ``joint_error`` the largest joint difference (rad),
    ``position_error`` of the hand P (m), ``opening_error`` of the fingers
    (m).  ``outcome`` describes an outcome mismatch (None when they agree).
    ``t`` is the caller's clock (s).
    """

    t: float
    source: str
    index: int | None
    joint_error: float
    position_error: float
    opening_error: float
    outcome: str | None
    flagged: bool
    predicted: Feedback | None = None
    """For a completion: the model's end state for the command (what was compared)."""

    def as_dict(self) -> dict[str, Any]:
        return {
            "t": round(self.t, 3),
            "source": self.source,
            "index": self.index,
            "joint_error_rad": round(self.joint_error, 6),
            "position_error_m": round(self.position_error, 6),
            "opening_error_m": round(self.opening_error, 6),
            "outcome": self.outcome,
            "flagged": self.flagged,
        } | (
            {}
            if self.predicted is None
            else {
                "predicted_joints_deg": [round(math.degrees(q), 4) for q in self.predicted.joints],
                "predicted_opening_m": round(self.predicted.finger_opening, 6),
            }
        )


def _errors(a: Feedback, b: Feedback) -> tuple[float, float, float]:
    joint = max(abs(x - y) for x, y in zip(a.joints, b.joints, strict=True))
    position = math.dist(a.p, b.p)
    return joint, position, abs(a.finger_opening - b.finger_opening)


def _distance_to_path(q: Sequence[float], points: Sequence[Sequence[float]]) -> float:
    """Largest joint error (rad) from ``q`` to the nearest point of the polyline ``points``.

    The remote arm samples its telemetry on its own count of control
    samples, not the model's, so a report falls between two predicted
    samples: the distance is to the segments joining them, not to the
    samples (which would be up to half a telemetry interval of motion off).
    """
    x = np.asarray(q, dtype=np.float64)
    path = np.asarray(points, dtype=np.float64)
    if len(path) == 1:
        return float(np.max(np.abs(x - path[0])))
    a, b = path[:-1], path[1:]
    d = b - a
    length = np.einsum("ij,ij->i", d, d)
    t = np.where(length > 0, np.einsum("ij,ij->i", x - a, d) / np.where(length > 0, length, 1), 0)
    nearest = a + np.clip(t, 0.0, 1.0)[:, None] * d
    return float(np.min(np.max(np.abs(x - nearest), axis=1)))


class Predictor:
    """Confirmed state + in-flight commands -> predicted state.  See the module docstring.

    Commands are identified by a caller-chosen ``key`` (the task's command
    index, or the request id).  Tolerances: ``joint_tolerance`` (rad),
    ``position_tolerance`` and ``opening_tolerance`` (m).
    """

    def __init__(
        self,
        world: WorldConfig = DEFAULT_WORLD,
        *,
        joint_tolerance: float = JOINT_TOLERANCE,
        position_tolerance: float = POSITION_TOLERANCE,
        opening_tolerance: float = OPENING_TOLERANCE,
    ) -> None:
        self._tolerances = (joint_tolerance, position_tolerance, opening_tolerance)
        self._base = ModelState.initial(world)
        self._in_flight: dict[int, Command] = {}
        self._plan: PreviewReport | None = None
        self._dirty = True
        self._finished: list[Sequence[float]] = []
        """The predicted path of the command completed last (see :meth:`observe`)."""
        self.model_error: str | None = None
        """Why the model cannot predict now (a reported pose it cannot stand in), or None."""
        self.confirmed: Feedback | None = None
        """The arm's latest report (telemetry or outcome), None before the first."""
        self.confirmed_at: float | None = None
        self.records: collections.deque[Divergence] = collections.deque(maxlen=MAX_RECORDS)
        self.comparisons = 0
        self.flagged = 0
        self.max_joint_error = 0.0
        self.max_position_error = 0.0

    # --- inputs ------------------------------------------------------------------------

    def sent(self, key: int, command: Command) -> None:
        """``command`` went to the arm; it runs after every earlier in-flight one."""
        self._in_flight[key] = command
        self._dirty = True

    def completed(
        self,
        key: int,
        now: float,
        *,
        feedback: Feedback | None = None,
        failure: str | None = None,
    ) -> Divergence | None:
        """The arm reported command ``key``'s outcome.

        ``feedback``: the state it reported (a completion's, or a failure's
        when known); ``failure``: the reason name when it failed (``None``
        when it completed).  Returns the comparison, or None for an unknown
        key or when the model cannot run.
        """
        command = self._in_flight.pop(key, None)
        self._dirty = True
        if command is None:
            return None
        if failure in NOT_RUN:
            # Not run (or stopped) for reasons of the session: nothing to
            # compare; a stopped arm's pose comes with the next report.
            if feedback is not None:
                self._rebase(feedback)
            return None
        try:
            step = preview([command], self._base)
        except ConfigError as exc:
            self.model_error = str(exc)
            if feedback is not None:
                self._rebase(feedback)
            return None
        outcome = step.outcomes[0]
        self._finished = [q for _t, q in outcome.path]
        predicted = outcome.reason.name if not outcome.ok else None
        mismatch = None
        if predicted != failure:
            mismatch = (
                f"model predicted {predicted or 'completion'}, arm reported "
                f"{failure or 'completion'}"
            )
        if failure is None:
            self._base = step.end_state
        # else: the arm refused the command before it moved (the planner
        # refuses whole motions up front; halts are NOT_RUN above), so the
        # arm is where the base says, whatever the model predicted.
        errors = (0.0, 0.0, 0.0)
        if feedback is not None:
            errors = _errors(outcome.feedback, feedback)
            self._base = self._base.rebased(feedback)
            self.confirmed, self.confirmed_at = feedback, now
        return self._record(now, "completion", key, errors, mismatch, outcome.feedback)

    def observe(self, feedback: Feedback, now: float) -> Divergence:
        """A telemetry sample: compare it with the predicted path of the running command."""
        self.confirmed, self.confirmed_at = feedback, now
        plan = self.plan
        # Samples taken during the command completed last may arrive after its
        # completion: both come in one read when the link bunches them (one
        # 512-character packet carried five samples and the completion) and
        # the client hands them on in its own order.
        points: list[Sequence[float]] = [self._base.world.initial_joints, *self._finished]
        if plan is not None:
            # The arm runs the head of the queue; its completion may still be
            # on the wire while the next one's samples arrive: two commands.
            for outcome in plan.outcomes[:2]:
                points += [q for _t, q in outcome.path]
                points.append(outcome.feedback.joints)
        joint = _distance_to_path(feedback.joints, points)
        return self._record(now, "telemetry", None, (joint, 0.0, 0.0), None)

    def reset(self, feedback: Feedback, now: float) -> None:
        """Start over from a reported state with nothing in flight (an observer joining)."""
        self._in_flight.clear()
        self._finished = []
        self._rebase(feedback)
        self.confirmed, self.confirmed_at = feedback, now

    # --- outputs -----------------------------------------------------------------------

    @property
    def in_flight(self) -> tuple[int, ...]:
        """Keys of the commands sent and not yet reported, in order."""
        return tuple(self._in_flight)

    @property
    def plan(self) -> PreviewReport | None:
        """The in-flight commands played from the base (None when the model cannot run)."""
        if self._dirty:
            self._dirty = False
            try:
                self._plan = preview(list(self._in_flight.values()), self._base)
                self.model_error = None
            except ConfigError as exc:
                self._plan, self.model_error = None, str(exc)
        return self._plan

    @property
    def predicted(self) -> Feedback | None:
        """Where the arm will be when every in-flight command is done."""
        plan = self.plan
        return None if plan is None else plan.final

    @property
    def base(self) -> ModelState:
        """The corrected belief after the last reported command."""
        return self._base

    def recent(self, count: int = 5) -> Iterable[Divergence]:
        """The newest ``count`` records, oldest first."""
        return list(self.records)[-count:]

    # --- internals ---------------------------------------------------------------------

    def _rebase(self, feedback: Feedback) -> None:
        self._base = self._base.rebased(feedback)
        self._dirty = True

    def _record(
        self,
        now: float,
        source: str,
        index: int | None,
        errors: tuple[float, float, float],
        mismatch: str | None,
        predicted: Feedback | None = None,
    ) -> Divergence:
        joint, position, opening = errors
        jt, pt, ot = self._tolerances
        flagged = mismatch is not None or joint > jt or position > pt or opening > ot
        record = Divergence(
            now, source, index, joint, position, opening, mismatch, flagged, predicted
        )
        self.records.append(record)
        self.comparisons += 1
        self.flagged += flagged
        self.max_joint_error = max(self.max_joint_error, joint)
        self.max_position_error = max(self.max_position_error, position)
        return record
