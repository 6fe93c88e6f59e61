"""Exactly once, randomized, on virtual time: the acceptance test of issue 17.

Sixty controller identities compete for one arm over links that are cut at
random byte offsets (mid-packet, either direction) more than a thousand times,
the arm's memory holds fewer identities than compete (memory pressure), and
the arm's server is restarted several times while commands are in flight.
Every command carries a unique token in its arguments, so the arm's log says
exactly which ran and how often.  The invariants:

* no command is executed twice;
* no command is reported COMPLETED that did not run, and a COMPLETED reply
  is the reply of that very command (its feedback echoes the token);
* no command reported as not run (SKIPPED, EXPIRED, QUEUE_FULL, TERMINATING)
  ran;
* every submitted command is settled with a typed outcome: completed,
  :class:`CommandFailed`, :class:`OutcomeUnknown` or :class:`SessionClosed`
  -- none is left pending.
"""

from __future__ import annotations

import random
from collections import Counter
from dataclasses import dataclass, field

import trio
import trio.testing

from tcpstream import (
    ArmClient,
    CommandCode,
    CommandFailed,
    FailureReason,
    OutcomeUnknown,
    Refused,
    Server,
    ServerConfig,
    SessionClosed,
    commands,
)

from .fakearm import FakeArm
from .harness import run, trio_scheduler_rng

IDENTITIES = 60
MEMORY_IDENTITIES = 8
"""Fewer than compete: identities are forgotten all the time."""
RESTARTS = 4
COMMANDS_PER_IDENTITY = 30
NOT_RUN = frozenset(
    {
        FailureReason.SKIPPED,
        FailureReason.EXPIRED,
        FailureReason.QUEUE_FULL,
        FailureReason.TERMINATING,
    }
)


def token_of(ident: int, seq: int) -> tuple[float, ...]:
    """Six joint targets unique to (identity, sequence), all within the bounds."""
    return (ident / 64.0, seq / 64.0, 0.125, 0.0, 0.0, 0.0)


@dataclass
class Ledger:
    executed: Counter[tuple[float, ...]] = field(default_factory=Counter)
    outcomes: Counter[str] = field(default_factory=Counter)
    completed: list[tuple[float, ...]] = field(default_factory=list)
    not_run: list[tuple[float, ...]] = field(default_factory=list)
    submitted: int = 0
    cuts: int = 0
    refusals: int = 0
    no_session: int = 0


class TokenArm(FakeArm):
    """Counts every execution of every token (MOVE_JOINTS echoes it as joints)."""

    def __init__(self, ledger: Ledger) -> None:
        super().__init__(move_time=0.05)
        self.ledger = ledger

    async def execute(self, command):  # type: ignore[no-untyped-def]
        if command.code is CommandCode.MOVE_JOINTS:
            self.ledger.executed[tuple(command.args[:6])] += 1
        return await super().execute(command)


class CutAt(trio.abc.Stream):
    """A client-side stream cut after ``budget`` bytes in either direction,
    possibly mid-packet: what gets through is a prefix, then both ends die."""

    def __init__(
        self, inner: trio.abc.Stream, far: trio.abc.Stream, budget: int, ledger: Ledger
    ) -> None:
        self.inner, self.far = inner, far
        self.budget = budget
        self.ledger = ledger
        self.cut = False

    async def _cut(self) -> None:
        if not self.cut:
            self.cut = True
            self.ledger.cuts += 1
            await trio.aclose_forcefully(self.far)
            await trio.aclose_forcefully(self.inner)

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        if self.cut:
            raise trio.BrokenResourceError("cut")
        data = bytes(data)
        if len(data) >= self.budget:
            await self.inner.send_all(data[: self.budget])
            await self._cut()
            raise trio.BrokenResourceError("cut")
        self.budget -= len(data)
        await self.inner.send_all(data)

    async def wait_send_all_might_not_block(self) -> None:
        await self.inner.wait_send_all_might_not_block()

    async def receive_some(self, max_bytes: int | None = None) -> bytes:
        if self.cut:
            return b""
        try:
            data = await self.inner.receive_some(max_bytes)
        except trio.ClosedResourceError:
            return b""
        if len(data) >= self.budget:
            head = data[: self.budget]
            await self._cut()
            return head
        self.budget -= len(data)
        return data

    async def aclose(self) -> None:
        await trio.aclose_forcefully(self.inner)


def test_no_command_runs_twice_under_cuts_identity_churn_and_restarts() -> None:
    rng = random.Random(2026)
    # Trio breaks ties between runnable tasks with its own RNG: seed it too, so
    # that two runs of this test are the same run.
    trio_scheduler_rng().seed(2026)
    ledger = Ledger()
    arm = TokenArm(ledger)
    config = ServerConfig(rtt_hint=0.2, memory_identities=MEMORY_IDENTITIES, idle_timeout=None)

    class Arm:
        server: Server | None = None
        conns: trio.Nursery | None = None
        streams: list[trio.abc.Stream] = []  # noqa: RUF012 (one per test run)
        restarts = 0
        forgotten = 0

    async def factory() -> trio.abc.Stream:
        await trio.sleep(rng.uniform(0.0, 0.05))
        if Arm.server is None or Arm.conns is None:
            raise OSError("the arm is restarting")
        client_end, server_end = trio.testing.memory_stream_pair()
        Arm.conns.start_soon(Arm.server.serve_stream, server_end)
        Arm.streams.append(server_end)
        return CutAt(client_end, server_end, rng.randint(100, 4000), ledger)

    async def arm_site(all_done: trio.Event) -> None:
        while True:
            async with Server(arm, config) as server, trio.open_nursery() as conns:
                Arm.server, Arm.conns = server, conns
                with trio.move_on_after(rng.uniform(20.0, 40.0)):
                    await all_done.wait()
                Arm.forgotten += server.statistics().identities_forgotten
                Arm.server = Arm.conns = None
                # A crash, not a shutdown: every connection dies without a BYE,
                # so the controllers reconnect to an arm that forgot them all.
                for stream in Arm.streams:
                    await trio.aclose_forcefully(stream)
                Arm.streams.clear()
                conns.cancel_scope.cancel()
            if all_done.is_set():
                return
            Arm.restarts += 1
            await trio.sleep(rng.uniform(0.1, 2.0))  # the arm is down

    async def controller(ident: int) -> None:
        seq = 0
        while seq < COMMANDS_PER_IDENTITY:
            client = ArmClient(
                factory,
                identity=f"ctl-{ident}",
                incarnation=rng.getrandbits(64),
                nonce_source=rng.randbytes,
                reconnect_attempts=rng.randint(0, 6),
                reconnect_delay=rng.uniform(0.05, 1.0),
                handshake_timeout=5.0,
            )
            try:
                async with client:
                    while seq < COMMANDS_PER_IDENTITY:
                        batch = []
                        try:
                            for _ in range(rng.randint(1, 4)):
                                token = token_of(ident, seq)
                                seq += 1
                                handle = await client.submit(commands.move_joints(token))
                                ledger.submitted += 1
                                batch.append((token, handle))
                        finally:
                            for token, handle in batch:
                                await settle(token, handle)
                        if rng.random() < 0.1:
                            break  # leave politely (BYE); a new incarnation next time
            except Refused:
                ledger.refusals += 1
            except SessionClosed:
                ledger.no_session += 1  # the first connection failed: nothing sent
            await trio.sleep(rng.uniform(0.0, 3.0))

    async def settle(token: tuple[float, ...], handle) -> None:  # type: ignore[no-untyped-def]
        try:
            result = await handle.completed()
        except OutcomeUnknown:
            ledger.outcomes["outcome unknown"] += 1
        except CommandFailed as exc:
            ledger.outcomes[f"failed {exc.reason.name}"] += 1
            if exc.reason in NOT_RUN:
                ledger.not_run.append(token)
        except SessionClosed:
            ledger.outcomes["session closed"] += 1
        else:
            assert result.feedback.joints == token, "a COMPLETED answered another command"
            ledger.completed.append(token)
            ledger.outcomes["completed"] += 1

    async def main() -> None:
        all_done = trio.Event()
        with trio.fail_after(24 * 3600):
            async with trio.open_nursery() as site:
                site.start_soon(arm_site, all_done)
                async with trio.open_nursery() as controllers:
                    for ident in range(IDENTITIES):
                        controllers.start_soon(controller, ident)
                all_done.set()

    run(main)

    twice = [t for t, n in ledger.executed.items() if n > 1]
    assert twice == [], f"executed twice: {twice}"
    assert all(ledger.executed[t] == 1 for t in ledger.completed)
    assert not any(ledger.executed[t] for t in ledger.not_run)
    assert sum(ledger.outcomes.values()) == ledger.submitted  # nothing left pending
    # The run really was hostile: enough cuts, restarts and forgotten identities.
    assert ledger.cuts >= 1000, ledger
    assert Arm.restarts >= 3, Arm.restarts
    assert Arm.forgotten > 0, "no memory pressure"
    assert ledger.outcomes["outcome unknown"] > 0, ledger.outcomes
    assert ledger.outcomes["completed"] > IDENTITIES * COMMANDS_PER_IDENTITY // 3, ledger.outcomes
    print(
        f"\n{ledger.submitted} commands, {ledger.cuts} cuts, {Arm.restarts} restarts, "
        f"{Arm.forgotten} identities forgotten, {ledger.refusals} BUSY refusals, "
        f"{ledger.no_session} failed connects; outcomes {dict(ledger.outcomes)}"
    )
