"""The arm's server: one executor, one ordered queue, many connections (PROTOCOL.md 9-11).

A :class:`Server` owns what outlives a connection: the executor task and its
bounded queue, the exactly-once memory, the controller's lease (who holds the
arm, and until when without hearing from them: the deadman) and telemetry.
Each connection is a sans-I/O :class:`ServerConnection` driven by a
:class:`Pump`; the server reacts to its events.

Seed 003 section 9.1: "When the session is over, both agents will close their
end of the socket stream, and the manipulator will reset and listen for
further connection requests."  Here a session ends with TERMINATE (clean), a
BYE, the deadman, or a broken stream; the arm is halted (never moved) when a
controller is lost, and the listener keeps accepting throughout.
"""

from __future__ import annotations

import itertools
import logging
import math
from collections import deque
from dataclasses import dataclass
from types import TracebackType

import trio

from ._commands import (
    Command,
    CommandCode,
    CommandFailed,
    CommandResult,
    Executor,
    FailureReason,
)
from ._config import ServerConfig
from ._events import (
    CloseReason,
    CommandReceived,
    ControllerIdentity,
    ControlRequested,
    EmergencyStopRequested,
    Event,
    PacketRejected,
    RefuseReason,
    Role,
    SessionEnded,
    SessionParameters,
)
from ._memory import Lookup, RequestMemory, StoredFailure, StoredReply, StoredSuccess
from ._packet import PACKET_SIZE
from ._pump import Pump
from ._ratelimit import TokenBucket
from ._server_connection import ServerConnection
from ._state import SessionState

__all__ = ["Server", "ServerStatistics"]

log = logging.getLogger(__name__)
_ZERO4 = (0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True, kw_only=True)
class ServerStatistics:
    """What an operator console shows about the arm's server."""

    connections: int
    """Open connections now (controller, observers, handshakes)."""
    connections_total: int
    refused: int
    controller: str | None
    """Name of the controller holding the arm, or None."""
    controller_connected: bool
    queue_depth: int
    running: CommandCode | None
    commands_accepted: int
    commands_completed: int
    commands_failed: int
    duplicates_answered: int
    """Re-sent request ids answered from memory or attached to the running one."""
    expired: int
    identities_forgotten: int
    """Controller identities the exactly-once memory evicted to make room
    (``ServerConfig.memory_identities``); each is told "no memory of you" in its
    next GRANT, and its unconfirmed commands end outcome-unknown, never re-run."""
    skipped: int
    """Commands not run because an earlier one failed first (the failure barrier)."""
    emergency_stops: int
    deadman_trips: int
    bad_packets: int
    telemetry_sent: int
    telemetry_skipped: int
    """Samples not sent because the connection was still writing (slow line)."""
    throttled: int
    """Times a connection's reads were paused because it sent faster than
    ``ServerConfig.max_packet_rate`` (a flood, or a controller bursting past
    ``packet_burst``); its bytes waited, none were dropped."""
    throttled_seconds: float
    """Seconds those pauses added up to, over all connections: under a sustained
    flood it grows about as fast as the clock, once per flooding connection."""
    handshakes_evicted: int
    """Connections never granted (still in their handshake, or refused and only
    flushing the REFUSE) that were closed to admit a newer one when the server
    was full (a flood of idle sockets cannot keep a controller out; see
    PROTOCOL.md section 10)."""
    commands_after_close: int = 0
    """Commands that arrived in the same read as the packet closing their session:
    not run (no ACCEPTED could be sent; the controller counts them outcome
    unknown); an emergency stop among them still stops the arm."""
    stopped_overtaken: int = 0
    """Commands answered FAILED STOPPED because they arrived after an emergency
    stop sent later (it overtook them on the transport's expedited lane)."""


@dataclass(slots=True)
class _Job:
    identity: ControllerIdentity
    request_id: int
    command: Command
    failures_seen: int = 0


_ARRIVALS = itertools.count()


def _progress(link: _Link) -> int:
    """How far a connection not granted has come (the least advanced is evicted first)."""
    if link.conn.closed:
        return 0  # refused: only flushing its REFUSE
    if link.conn.state is SessionState.AWAITING_HELLO:
        return 1
    return 2


class _Link:
    """One connection as the server sees it."""

    def __init__(self, server: Server, stream: trio.abc.Stream) -> None:
        cfg = server.config
        self.conn = ServerConnection(
            server.parameters,
            key=cfg.key,
            handshake_timeout=cfg.handshake_time(),
            idle_timeout=cfg.idle_timeout,
            instance=server.instance,
            now=trio.current_time(),
            nonce_source=cfg.nonce_source,
        )
        limit = None
        if cfg.max_packet_rate is not None:
            # Counted in bytes so that garbage costs the same as packets.
            limit = TokenBucket(
                cfg.max_packet_rate * PACKET_SIZE, cfg.burst() * PACKET_SIZE, trio.current_time()
            )
        self.pump = Pump(stream, self.conn, lambda ev: server._on_event(self, ev), read_limit=limit)
        self.identity: ControllerIdentity | None = None
        self.role: Role | None = None
        self.granted = trio.Event()
        """Set once the arm has decided (granted or refused)."""
        self.arrived = next(_ARRIVALS)
        """Arrival order: among equals, the oldest handshake is evicted first."""
        self.scope: trio.CancelScope | None = None
        """The connection's serving scope, to evict it."""


class Server:
    """The arm's command server.  Use as ``async with Server(executor, config) as server:``.

    Inside the block, :meth:`serve_stream` runs one session over any trio
    stream (TCP, TLS, a serial socket), :meth:`serve_tcp` listens on a port.
    The same server across connections is what makes a re-sent command
    answer from memory instead of running twice.
    """

    def __init__(self, executor: Executor, config: ServerConfig | None = None) -> None:
        if not isinstance(executor, Executor):
            raise TypeError(
                "the executor must implement tcpstream.Executor "
                "(control_rate_hz, async execute, halt, state)"
            )
        self.executor = executor
        self.config = config or ServerConfig()
        hb, dead = self.config.timing()
        rate = executor.control_rate_hz
        if not rate > 0:
            raise ValueError(f"the executor's control_rate_hz must be > 0, got {rate!r}")
        period = self.config.telemetry_every / rate if self.config.telemetry_every else 0.0
        self.parameters = SessionParameters(hb, dead, period, self.config.memory_size)
        self.memory = RequestMemory(self.config.memory_size, self.config.memory_identities)
        self.instance = int.from_bytes(self.config.nonce_source(8), "big")
        """Random per server object, sent in every GRANT: a controller that sees it
        change knows the arm restarted and its exactly-once memory is gone."""
        # Bounded by config.queue_size (QUEUE_FULL beyond it).
        self._queue: deque[_Job] = deque()
        self._queue_wake = trio.Event()
        self._running: _Job | None = None
        self._running_scope: trio.CancelScope | None = None
        self._cancel_reason = FailureReason.STOPPED
        self._links: set[_Link] = set()
        self._holder: ControllerIdentity | None = None
        self._holder_link: _Link | None = None
        self._holder_heard = 0.0
        self._terminating = False
        self._lease_wake = trio.Event()
        self._nursery: trio.Nursery | None = None
        self._throttled_for = 0.0  # closed connections' pauses (s)
        self._stats = dict.fromkeys(
            (
                "connections_total",
                "refused",
                "commands_accepted",
                "commands_completed",
                "commands_failed",
                "duplicates_answered",
                "expired",
                "skipped",
                "emergency_stops",
                "deadman_trips",
                "bad_packets",
                "telemetry_sent",
                "telemetry_skipped",
                "throttled",
                "handshakes_evicted",
                "commands_after_close",
                "stopped_overtaken",
            ),
            0,
        )

    # --- lifetime -------------------------------------------------------------

    async def __aenter__(self) -> Server:
        self._nursery_cm = trio.open_nursery()
        self._nursery = await self._nursery_cm.__aenter__()
        self._nursery.start_soon(self._executor_loop)
        self._nursery.start_soon(self._deadman_loop)
        if self.parameters.telemetry_period > 0:
            self._nursery.start_soon(self._telemetry_loop)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        assert self._nursery is not None
        self._nursery.cancel_scope.cancel()
        try:
            # The caller's exception propagates as itself (not in a group).
            await self._nursery_cm.__aexit__(None, None, None)
            return None
        finally:
            self._nursery = None
            # Whatever happens to the server, the arm does not keep moving.
            self._halt(FailureReason.STOPPED)

    def statistics(self) -> ServerStatistics:
        holder_link = self._holder_link
        return ServerStatistics(
            connections=len(self._links),
            controller=self._holder.name if self._holder else None,
            controller_connected=holder_link is not None,
            queue_depth=len(self._queue),
            running=self._running.command.code if self._running else None,
            **(
                self._stats
                | {
                    # Closed connections' pauses, plus those of the open ones so far.
                    "throttled": self._stats["throttled"]
                    + sum(link.pump.throttles for link in self._links)
                }
            ),
            identities_forgotten=self.memory.forgotten,
            throttled_seconds=self._throttled_for
            + sum(link.pump.throttled_for for link in self._links),
        )

    # --- serving --------------------------------------------------------------

    async def serve_stream(self, stream: trio.abc.Stream) -> None:
        """Run one session over ``stream`` until it ends; the stream is closed after."""
        if self._nursery is None:
            raise RuntimeError("use the server inside 'async with Server(...) as server:'")
        self._stats["connections_total"] += 1
        if len(self._links) >= self.config.max_connections:
            self._make_room()
        link = _Link(self, stream)
        self._links.add(link)
        try:
            async with trio.open_nursery() as nursery:
                link.scope = nursery.cancel_scope
                nursery.start_soon(self._handshake_guard, link, nursery.cancel_scope)
                await link.pump.run()
                nursery.cancel_scope.cancel()
        finally:
            self._links.discard(link)
            self._stats["throttled"] += link.pump.throttles
            self._throttled_for += link.pump.throttled_for
            if not link.conn.closed:  # cancelled from outside: the session is over
                link.conn.close(CloseReason.SHUTDOWN, trio.current_time())
                link.pump.drain_events()
            self._detach(link)

    def _make_room(self) -> None:
        """The server is full: close the least advanced connection not granted.

        Connections that have not authenticated (or, without a key, not sent a
        well-formed HELLO) must not starve the sessions the arm exists for: a
        flood of idle or half-open sockets would otherwise keep a keyed
        controller -- above all one resuming after a blip -- out with
        SERVER_FULL.  First one already refused (it is only flushing its
        REFUSE), then one that has not sent a complete HELLO, then one stuck
        after its HELLO; the oldest of each kind first.  A genuine controller
        completes its handshake within a round trip, so a flood must open more
        than ``max_connections`` sockets per round trip to keep it out.
        Granted sessions are never evicted; when every slot holds one, the new
        connection is admitted beyond the limit (one handshake at a time: the
        next arrival evicts it if it is still undecided), and the grant decides
        -- a controller always has a slot (observers take at most
        ``max_connections - 1``; the controller's own older connection is
        retired when it resumes).
        """
        undecided = [ln for ln in self._links if ln.role is None and ln.scope is not None]
        if not undecided:
            return
        victim = min(undecided, key=lambda ln: (_progress(ln), ln.arrived))
        self._stats["handshakes_evicted"] += 1
        log.info("server full: closing an unauthenticated connection to admit a new one")
        self._links.discard(victim)  # its slot is free now, whatever its close takes
        assert victim.scope is not None
        victim.scope.cancel()

    async def _handshake_guard(self, link: _Link, scope: trio.CancelScope) -> None:
        # The connection's own handshake timer needs a writable stream to send its
        # REFUSE; a TLS handshake or a stuck peer can block that, so bound the
        # whole thing here as well.
        with trio.move_on_after(self.config.handshake_time() + 5.0):
            await link.granted.wait()
            return
        if not link.granted.is_set():
            scope.cancel()

    async def serve_listeners(
        self,
        listeners: list[trio.abc.Listener[trio.abc.Stream]],
        *,
        task_status: trio.TaskStatus[list[trio.abc.Listener[trio.abc.Stream]]] = (
            trio.TASK_STATUS_IGNORED
        ),
    ) -> None:
        """Accept and serve connections from ``listeners`` until cancelled."""
        await trio.serve_listeners(self.serve_stream, listeners, task_status=task_status)

    # --- events from connections ----------------------------------------------

    def _on_event(self, link: _Link, event: Event) -> None:
        if link.conn.closed and isinstance(event, CommandReceived | EmergencyStopRequested):
            # A command parsed in the same read as the packet that closed the
            # session (the controller's BYE, or a fault): nobody can be told
            # it was accepted, so it is not run -- the controller counts it
            # as outcome unknown and resumes under its identity.  A stop is
            # still obeyed: stopping is always safe.
            self._stats["commands_after_close"] += 1
            if isinstance(event, EmergencyStopRequested):
                self._halt_all(FailureReason.STOPPED, "emergency stop")
            return
        if isinstance(event, CommandReceived):
            self._submit(link, event.request_id, event.command, event.failures_seen)
        elif isinstance(event, EmergencyStopRequested):
            self._emergency_stop(link, event.request_id)
        elif isinstance(event, ControlRequested):
            self._decide(link, event.identity, event.role)
        elif isinstance(event, PacketRejected):
            self._stats["bad_packets"] += 1
            log.info("rejected packet: %s", event.message)
        elif isinstance(event, SessionEnded):
            log.info("session ended: %s %s", event.reason.name, event.message)
            self._detach(link, event)

    def _decide(self, link: _Link, identity: ControllerIdentity, role: Role) -> None:
        now = trio.current_time()
        if role is Role.OBSERVER:
            if not self.config.allow_observers:
                self._refuse(link, RefuseReason.BUSY, "this arm takes no observers")
                return
            # One slot is always the controller's: observers cannot keep it out.
            watching = sum(
                1 for ln in self._links if ln.role is Role.OBSERVER and not ln.conn.closed
            )
            if watching >= self.config.max_connections - 1:
                self._refuse(
                    link,
                    RefuseReason.SERVER_FULL,
                    f"the arm serves {watching} observers (one slot is kept for the controller); "
                    "try again later",
                )
                return
        elif self._holder is not None and self._holder != identity:
            self._refuse(
                link,
                RefuseReason.BUSY,
                "another controller holds the arm; retry when it is done, or connect as observer",
            )
            return
        else:
            old = self._holder_link
            self._holder, self._holder_link = identity, link
            if old is not None and old is not link:
                old.pump.close(CloseReason.TAKEN_OVER, "the same controller connected again")
            self._lease_wake.set()
        link.identity, link.role = identity, role
        # A controller is remembered from its grant on; an observer never
        # commands, so it takes no place in the memory.
        if role is Role.CONTROLLER:
            remembered = self.memory.admit(identity)
        else:
            remembered = self.memory.remembers(identity)
        link.conn.grant(role, self.memory.highest(identity), now, remembered=remembered)
        link.granted.set()

    def _refuse(self, link: _Link, reason: RefuseReason, message: str) -> None:
        self._stats["refused"] += 1
        link.conn.refuse(reason, message, trio.current_time())
        link.granted.set()  # decided: the guard may stand down

    def _detach(self, link: _Link, ended: SessionEnded | None = None) -> None:
        if self._holder_link is not link:
            return
        self._holder_link = None
        self._holder_heard = link.conn.last_heard
        if ended is not None and ended.reason is CloseReason.SILENCE:
            self._trip_deadman()
        elif ended is not None and ended.reason is CloseReason.IDLE:
            self._release()  # idle: nothing outstanding by definition
        elif ended is not None and ended.by_peer and ended.reason is not CloseReason.PEER_EOF:
            # The controller said goodbye (any BYE).  If work is outstanding,
            # nobody is left to watch it: stop rather than carry on.
            if self._running is not None or self._queue:
                self._halt_all(FailureReason.STOPPED, "the controller closed the session")
            self._release()
        # Otherwise (EOF, broken stream, garbage, cancelled) the lease runs on: the
        # same controller may resume within the dead time, else the deadman trips.
        self._lease_wake.set()

    def _release(self) -> None:
        self._holder = None
        self._terminating = False
        if self._holder_link is not None:
            self._holder_link = None

    # --- commands ---------------------------------------------------------------

    def _reply(self, identity: ControllerIdentity, request_id: int, reply: StoredReply) -> None:
        link = self._holder_link
        if link is None or link.identity != identity or link.conn.closed:
            return  # kept in memory; a resume asks again
        now = trio.current_time()
        if isinstance(reply, StoredSuccess):
            link.conn.completed(request_id, reply.code, reply.result, now)
        else:
            link.conn.failed(request_id, reply.code, reply.reason, reply.message, reply.aux, now)
        link.pump.kick()

    def _finish(self, identity: ControllerIdentity, request_id: int, reply: StoredReply) -> None:
        # Every final reply passes here before it is remembered or sent: the one
        # place to make sure the arm never emits a packet its protocol forbids.
        if not _all_finite(reply):
            reply = self._non_finite(reply)
        self.memory.finish(identity, request_id, reply)
        if isinstance(reply, StoredFailure) and reply.reason in _BARRIER_REASONS:
            self.memory.raise_barrier(identity, request_id)
        key = "commands_completed" if isinstance(reply, StoredSuccess) else "commands_failed"
        self._stats[key] += 1
        self._reply(identity, request_id, reply)

    def _submit(
        self, link: _Link, request_id: int, command: Command, failures_seen: int = 0
    ) -> None:
        identity = link.identity
        assert identity is not None
        now = trio.current_time()
        status, stored = self.memory.lookup(identity, request_id)
        if status is Lookup.DONE:
            assert stored is not None
            self._stats["duplicates_answered"] += 1
            self._reply(identity, request_id, stored)
            return
        if status is Lookup.IN_FLIGHT:
            self._stats["duplicates_answered"] += 1
            link.conn.accepted(request_id, command.code, self._position(request_id), now)
            return
        if (
            status is Lookup.EXPIRED
            and request_id < (stop := self.memory.stopped_at(identity))
            and not self.memory.may_have_run(identity, request_id)
        ):
            # Sent before an emergency stop that overtook it on the transport's
            # expedited lane (PROTOCOL.md 15): the stop meant this one too.
            # (One that may have run and been forgotten stays EXPIRED below.)
            self._stats["stopped_overtaken"] += 1
            self._finish(
                identity,
                request_id,
                _failure(
                    command,
                    FailureReason.STOPPED,
                    f"sent before emergency stop #{stop}, which arrived first; not run",
                ),
            )
            return
        if status is Lookup.EXPIRED:
            self._stats["expired"] += 1
            link.conn.failed(
                request_id,
                command.code,
                FailureReason.EXPIRED,
                "request id is older than the arm's memory; not run now (it may have run "
                "before). Send it again under a new request id if it should run.",
                _ZERO4,
                now,
            )
            return
        self.memory.start(identity, request_id)
        if (skipped := self._skipped(identity, command, failures_seen)) is not None:
            self._finish(identity, request_id, skipped)
            return
        if self._terminating:
            self._finish(
                identity,
                request_id,
                _failure(command, FailureReason.TERMINATING, "the session is terminating"),
            )
            return
        # Capacity is queue_size waiting plus the one running, counted the same
        # whether or not the executor task has taken the head of the queue yet
        # (which depends on scheduling, not on the protocol).
        outstanding = len(self._queue) + (1 if self._running else 0)
        if outstanding > self.config.queue_size:
            self._finish(
                identity,
                request_id,
                _failure(
                    command,
                    FailureReason.QUEUE_FULL,
                    f"{outstanding} commands queued or running; wait for one to complete",
                ),
            )
            return
        position = len(self._queue) + (1 if self._running else 0)
        self._queue.append(_Job(identity, request_id, command, failures_seen))
        if command.code is CommandCode.TERMINATE:
            self._terminating = True
        self._stats["commands_accepted"] += 1
        link.conn.accepted(request_id, command.code, position, now)
        self._queue_wake.set()

    def _skipped(
        self, identity: ControllerIdentity, command: Command, failures_seen: int
    ) -> StoredFailure | None:
        """The failure barrier (PROTOCOL.md section 9): SKIPPED, or None to go ahead.

        A pipelined command was planned assuming the ones before it succeed.  If
        one of them failed at the arm and the controller had not seen that
        failure when it sent this one, running it would act from a state nobody
        planned for -- and on a long link the controller cannot stop it in time.
        TERMINATE still ends the session (it moves nothing).
        """
        barrier = self.memory.barrier(identity)
        if failures_seen >= barrier or command.code is CommandCode.TERMINATE:
            return None
        self._stats["skipped"] += 1
        return StoredFailure(
            command.code,
            FailureReason.SKIPPED,
            f"not run: command #{barrier} failed first and this one was sent before that "
            "was known; re-plan from the arm's state and send again",
            (float(barrier), 0.0, 0.0, 0.0),
        )

    def _position(self, request_id: int) -> int:
        for i, job in enumerate(self._queue):
            if job.request_id == request_id:
                return i + (1 if self._running else 0)
        return 0

    def _emergency_stop(self, link: _Link, request_id: int) -> None:
        identity = link.identity
        assert identity is not None
        status, stored = self.memory.lookup(identity, request_id)
        if status is Lookup.DONE:
            assert stored is not None
            self._stats["duplicates_answered"] += 1
            self._reply(identity, request_id, stored)
            return
        # Halt first, bookkeeping after: the arm stops at once.
        self._halt(FailureReason.STOPPED)
        self._stats["emergency_stops"] += 1
        self._halt_all(FailureReason.STOPPED, "emergency stop")
        if status is Lookup.NEW:
            self.memory.start(identity, request_id)
            self.memory.note_stop(identity, request_id)
            self._finish(
                identity, request_id, self._state_reply(Command(CommandCode.EMERGENCY_STOP))
            )

    def _halt_all(self, reason: FailureReason, why: str) -> None:
        """Cancel the running command and fail every queued one with ``reason``."""
        self._halt(reason)
        if self._running_scope is not None:
            self._cancel_reason = reason
            self._running_scope.cancel()
        while self._queue:
            job = self._queue.popleft()
            self._finish(
                job.identity,
                job.request_id,
                _failure(job.command, reason, f"dropped from the queue: {why}"),
            )
        self._terminating = False

    def _trip_deadman(self) -> None:
        self._stats["deadman_trips"] += 1
        log.warning("deadman: controller %s silent; halting", self._holder)
        self._halt_all(FailureReason.DEADMAN, "the controller fell silent (deadman)")
        if self._holder_link is not None:
            self._holder_link.pump.close(CloseReason.SILENCE, "deadman: controller silent")
        self._release()

    async def _executor_loop(self) -> None:
        while True:
            while not self._queue:
                await self._queue_wake.wait()
                self._queue_wake = trio.Event()
            job = self._queue.popleft()
            # A command that failed while this one waited blocks it, too.
            skipped = self._skipped(job.identity, job.command, job.failures_seen)
            if skipped is not None:
                self._finish(job.identity, job.request_id, skipped)
                continue
            self._running = job
            try:
                reply = await self._execute(job)
            finally:
                self._running = None
                self._running_scope = None
            self._finish(job.identity, job.request_id, reply)
            if job.command.code is CommandCode.TERMINATE:
                link = self._holder_link
                if link is not None and link.identity == job.identity:
                    link.pump.close(CloseReason.TERMINATED, "terminated; the arm listens again")
                    self._holder_link = None
                self._release()
                self._lease_wake.set()

    async def _execute(self, job: _Job) -> StoredReply:
        command = job.command
        if command.code is CommandCode.TERMINATE:
            return self._state_reply(command)
        with trio.CancelScope() as scope:
            self._running_scope = scope
            try:
                result = await self.executor.execute(command)
            except CommandFailed as exc:
                return StoredFailure(command.code, exc.reason, exc.message, exc.aux)
            except Exception as exc:
                # The arm's own bug: stop it, report it, keep serving.
                log.exception("executor failed on %s", command.code.name)
                self._halt(FailureReason.ARM_FAULT)
                return _failure(command, FailureReason.ARM_FAULT, f"executor error: {exc!r}")
            return StoredSuccess(command.code, result)
        # Cancelled by an emergency stop or the deadman (the contract: halted
        # within one control sample); make sure, then report why.
        reason = self._cancel_reason
        self._halt(reason)
        return _failure(command, reason, f"halted by {reason.name.lower().replace('_', ' ')}")

    def _non_finite(self, reply: StoredReply) -> StoredFailure:
        """A reply carrying inf or NaN: the controller's decoder would reject it
        and the command would hang unanswered at the client.  Detail words of a
        failure are clamped (the reason stands); a success reporting a
        non-finite state is an arm fault: halt and say so."""
        if isinstance(reply, StoredFailure):
            log.warning("%s detail words %r are not finite; clamped", reply.reason.name, reply.aux)
            a0, a1, a2, a3 = (_clamp(w) for w in reply.aux)
            return StoredFailure(reply.code, reply.reason, reply.message, (a0, a1, a2, a3))
        log.error("the executor reported a non-finite state after %s; halting", reply.code.name)
        self._halt(FailureReason.ARM_FAULT)
        return StoredFailure(
            reply.code,
            FailureReason.ARM_FAULT,
            "the arm reported a non-finite value in its state; halted (arm fault)",
            _ZERO4,
        )

    # --- calling the executor: its bugs must not take the server down ---------------

    def _halt(self, reason: FailureReason) -> None:
        try:
            self.executor.halt(reason)
        except Exception:
            # Nothing better to do than say so loudly: the command (if any) is
            # cancelled regardless, and that is what stops a well-behaved arm.
            log.exception("executor.halt(%s) failed", reason.name)

    def _state_reply(self, command: Command) -> StoredReply:
        try:
            return StoredSuccess(command.code, CommandResult(self.executor.state()))
        except Exception as exc:
            log.exception("executor.state() failed")
            return _failure(command, FailureReason.ARM_FAULT, f"state unavailable: {exc!r}")

    # --- the lease (deadman) and telemetry -------------------------------------------

    def _lease_deadline(self) -> float:
        if self._holder is None:
            return math.inf
        link = self._holder_link
        heard = link.conn.last_heard if link is not None else self._holder_heard
        return heard + self.parameters.dead_time

    async def _deadman_loop(self) -> None:
        # A connected controller's silence is caught by its connection (same
        # dead time); this loop catches the controller that vanished without a
        # word and did not come back.
        while True:
            self._lease_wake = trio.Event()
            deadline = self._lease_deadline()
            with trio.move_on_at(deadline):
                await self._lease_wake.wait()
                continue
            if self._holder is not None and self._holder_link is None:
                self._trip_deadman()
            elif self._holder_link is not None:
                # Connected but silent: its connection ends itself at the same
                # deadline (SILENCE) -- give its timer a moment to run.
                await trio.sleep(self.parameters.heartbeat_interval)

    async def _telemetry_loop(self) -> None:
        every = self.config.telemetry_every
        period = self.parameters.telemetry_period
        sample = 0
        next_at = trio.current_time() + period
        while True:
            await trio.sleep_until(next_at)
            next_at += period
            sample += every
            listeners = [ln for ln in self._links if ln.role is not None and not ln.conn.closed]
            if not listeners:
                continue
            try:
                state = self.executor.state()
            except Exception:
                log.exception("executor.state() failed; telemetry sample skipped")
                continue
            if not all(math.isfinite(w) for w in state.to_words()):
                log.error("executor.state() is not finite; telemetry sample skipped")
                self._stats["telemetry_skipped"] += 1
                continue
            now = trio.current_time()
            for ln in listeners:
                if ln.pump.idle:
                    ln.conn.telemetry(sample, state, now)
                    ln.pump.kick()
                    self._stats["telemetry_sent"] += 1
                else:
                    self._stats["telemetry_skipped"] += 1


_BARRIER_REASONS = frozenset(
    {
        FailureReason.JOINT_LIMIT,
        FailureReason.UNREACHABLE,
        FailureReason.SINGULAR,
        FailureReason.COLLISION,
        FailureReason.NO_OBJECT,
        FailureReason.NOT_GRASPING,
        FailureReason.BAD_ARGUMENT,
        FailureReason.ARM_FAULT,
        FailureReason.DEADMAN,
    }
)
"""Failures the arm decided on while executing (or the deadman imposed): they
raise the barrier.  Not STOPPED (the controller asked for it), nor refusals of
commands that never ran (QUEUE_FULL, TERMINATING, EXPIRED, SKIPPED itself)."""


def _all_finite(reply: StoredReply) -> bool:
    if isinstance(reply, StoredFailure):
        return all(math.isfinite(w) for w in reply.aux)
    words = (*reply.result.aux, *reply.result.feedback.to_words())
    return all(math.isfinite(w) for w in words)


def _clamp(word: float) -> float:
    """A finite stand-in for a non-finite detail word: NaN is 0, +-inf the largest double."""
    if math.isnan(word):
        return 0.0
    return max(-_LARGEST, min(_LARGEST, word))


_LARGEST = 1.7976931348623157e308


def _failure(command: Command, reason: FailureReason, message: str) -> StoredFailure:
    return StoredFailure(command.code, reason, message, _ZERO4)
