"""Exactly-once memory: what the arm remembers about each controller's request ids.

PROTOCOL.md section 9.  The key is the :class:`~tcpstream.connection.ControllerIdentity`
(name and incarnation).  A client numbers its commands 1, 2, 3, ... and never
reuses a number within an incarnation, so for each identity the arm keeps:

* ``highest``: the highest request id it has taken in (kept as long as the
  identity is remembered at all);
* the final reply of the last :data:`DEFAULT_MEMORY_SIZE` finished requests;
* the requests still queued or running (at most the queue size plus one, so
  never evicted).

A request id is then exactly one of: new (above ``highest``: run it), in
flight (attach to it), done (answer from memory) or expired (at or below
``highest`` but forgotten: refuse it with EXPIRED -- never run it, because it
may have run already).  Nothing here is ever executed twice; the price of the
bound is that a command re-sent after more than 1024 newer ones finished gets
EXPIRED instead of its original answer.
"""

from __future__ import annotations

import enum
from collections import OrderedDict
from dataclasses import dataclass

from ._commands import CommandCode, CommandResult, FailureReason
from ._events import ControllerIdentity

__all__ = [
    "DEFAULT_IDENTITIES",
    "DEFAULT_MEMORY_SIZE",
    "Lookup",
    "RequestMemory",
    "StoredFailure",
    "StoredReply",
    "StoredSuccess",
]

DEFAULT_MEMORY_SIZE = 1024
"""Finished request ids remembered per identity.  A reconnect re-sends at most
the client's in-flight window (32), so 1024 covers many reconnects' worth of
lost replies; 1024 replies of ~250 bytes are ~250 kB per identity."""
DEFAULT_IDENTITIES = 16
"""Controller identities remembered (least recently used forgotten first).  An
arm has one controller at a time; 16 covers restarts and a few operators.

Memory pressure evicts; it never refuses.  Refusing a new identity would let
anyone who can take control once per identity lock every later controller out
of the arm, so instead the least recently used identity with nothing in flight
is forgotten -- and the arm *says so*: the next GRANT to that identity carries
"no memory of you" (:meth:`RequestMemory.admit` returns False), and its client
settles every command it has not seen answered as outcome-unknown instead of
re-sending it.  Evictions are counted (``forgotten``)."""


@dataclass(frozen=True, slots=True)
class StoredSuccess:
    code: CommandCode
    result: CommandResult


@dataclass(frozen=True, slots=True)
class StoredFailure:
    code: int
    reason: FailureReason
    message: str
    aux: tuple[float, float, float, float]


StoredReply = StoredSuccess | StoredFailure


class Lookup(enum.Enum):
    NEW = "new"
    IN_FLIGHT = "in-flight"
    DONE = "done"
    EXPIRED = "expired"


class _Record:
    __slots__ = ("barrier", "done", "evicted_max", "highest", "in_flight", "stopped_at")

    def __init__(self) -> None:
        self.barrier = 0
        self.stopped_at = 0
        self.evicted_max = 0
        self.highest = 0
        self.in_flight: set[int] = set()
        self.done: OrderedDict[int, StoredReply] = OrderedDict()


class RequestMemory:
    """Bounded per-identity memory of request ids and their final replies."""

    def __init__(
        self, size: int = DEFAULT_MEMORY_SIZE, identities: int = DEFAULT_IDENTITIES
    ) -> None:
        if size < 1 or identities < 1:
            raise ValueError("memory size and identity count must be >= 1")
        self.size = size
        self._identities = identities
        self._records: OrderedDict[ControllerIdentity, _Record] = OrderedDict()
        self.forgotten = 0
        """Identities evicted to make room for new ones (see DEFAULT_IDENTITIES)."""

    def _record(self, identity: ControllerIdentity) -> _Record:
        rec = self._records.get(identity)
        if rec is None:
            rec = self._records[identity] = _Record()
            # Forget the least recently used identity with nothing in flight.
            # With work in flight in every record (at most queue + 1 of them can
            # be), the memory holds one more than its bound until one finishes.
            if len(self._records) > self._identities:
                for old, old_rec in self._records.items():
                    if not old_rec.in_flight and old != identity:
                        del self._records[old]
                        self.forgotten += 1
                        break
        self._records.move_to_end(identity)
        return rec

    def admit(self, identity: ControllerIdentity) -> bool:
        """A controller is granted: remember it from now on.

        Returns whether the arm already remembered ``identity`` -- False for a
        controller never seen by this memory, or one evicted since.  The GRANT
        carries the answer: when it is False the arm cannot prove whether any
        command the controller sent before ran, and the client must not re-send
        one (PROTOCOL.md 9).
        """
        known = identity in self._records
        self._record(identity)
        return known

    def remembers(self, identity: ControllerIdentity) -> bool:
        """Whether ``identity`` is remembered (without touching its recency)."""
        return identity in self._records

    def highest(self, identity: ControllerIdentity) -> int:
        """The highest request id taken in from ``identity`` (0 if none or forgotten)."""
        rec = self._records.get(identity)
        return rec.highest if rec is not None else 0

    def lookup(
        self, identity: ControllerIdentity, request_id: int
    ) -> tuple[Lookup, StoredReply | None]:
        """Classify ``request_id``; for DONE also return the stored reply."""
        rec = self._record(identity)
        if request_id in rec.in_flight:
            return Lookup.IN_FLIGHT, None
        stored = rec.done.get(request_id)
        if stored is not None:
            return Lookup.DONE, stored
        if request_id > rec.highest:
            return Lookup.NEW, None
        return Lookup.EXPIRED, None

    def start(self, identity: ControllerIdentity, request_id: int) -> None:
        """Take in a NEW request id (it is now in flight)."""
        rec = self._record(identity)
        if request_id <= rec.highest:
            raise ValueError(f"request id {request_id} is not new (highest {rec.highest})")
        rec.highest = request_id
        rec.in_flight.add(request_id)

    def finish(self, identity: ControllerIdentity, request_id: int, reply: StoredReply) -> None:
        """Record the final reply of a request (in flight or taken in and refused at once)."""
        rec = self._record(identity)
        rec.in_flight.discard(request_id)
        rec.highest = max(rec.highest, request_id)
        rec.done[request_id] = reply
        while len(rec.done) > self.size:
            evicted, _ = rec.done.popitem(last=False)
            rec.evicted_max = max(rec.evicted_max, evicted)

    def barrier(self, identity: ControllerIdentity) -> int:
        """The request id of this controller's latest failure at the arm (0: none)."""
        rec = self._records.get(identity)
        return rec.barrier if rec is not None else 0

    def raise_barrier(self, identity: ControllerIdentity, request_id: int) -> None:
        """Commands sent without having seen ``request_id``'s failure will be skipped."""
        rec = self._record(identity)
        rec.barrier = max(rec.barrier, request_id)

    def stopped_at(self, identity: ControllerIdentity) -> int:
        """The request id of this controller's latest EMERGENCY_STOP (0: none)."""
        rec = self._records.get(identity)
        return rec.stopped_at if rec is not None else 0

    def note_stop(self, identity: ControllerIdentity, request_id: int) -> None:
        """An EMERGENCY_STOP was taken in: commands numbered below it that
        arrive later were sent before it (it overtook them) and never run."""
        rec = self._record(identity)
        rec.stopped_at = max(rec.stopped_at, request_id)

    def may_have_run(self, identity: ControllerIdentity, request_id: int) -> bool:
        """Whether ``request_id``, neither in flight nor remembered, may have
        finished and been evicted (False: it never reached the arm, or the
        identity is not remembered at all -- then nothing is known)."""
        rec = self._records.get(identity)
        return rec is None or request_id <= rec.evicted_max

    def in_flight(self, identity: ControllerIdentity) -> int:
        rec = self._records.get(identity)
        return len(rec.in_flight) if rec is not None else 0
