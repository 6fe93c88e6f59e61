"""A blocking facade for controller code that is not async.

::

    with tcpstream.BlockingClient.tcp("arm.example", 7010, key=KEY) as arm:
        arm.move_joints([0, 0.5, -0.3, 0, 0.2, 0])
        print(arm.weigh().aux[0])

A background thread runs trio and an :class:`ArmClient`; every method hands
its call to that thread and waits at most ``timeout`` seconds.  A timeout
stops the *wait* (raising :class:`TimeoutError`), not the command: it may
still run at the arm -- call :meth:`emergency_stop` if it must not.

The controller watchdog (``watchdog=``, off by default) closes the gap the
arm's deadman leaves here: heartbeats come from the background thread, so a
hung *application* thread (a deadlock, a stuck sensor read) would keep the
arm held and working.  With a watchdog, an application that goes ``watchdog``
seconds without calling into the client loses the session at once and the
arm halts what it was still doing; see :class:`BlockingClient`.
"""

from __future__ import annotations

import contextlib
import logging
import math
import ssl
import threading
from collections.abc import Awaitable, Callable, Sequence
from types import TracebackType
from typing import TypeVar, Unpack

import trio

from . import _builders as build
from ._api import DEFAULT_PORT, connect_tcp
from ._client import ArmClient
from ._commands import Command, CommandResult, Feedback
from ._errors import SessionClosed
from ._options import ClientConfig, ClientOptions, client_config

__all__ = ["BlockingClient", "WatchdogExpired"]

log = logging.getLogger(__name__)

T = TypeVar("T")


class WatchdogExpired(SessionClosed):
    """The controller watchdog expired: the application stopped calling the client.

    The session was closed (BYE) and the arm halted the work still outstanding
    (those commands fail there with STOPPED; this client never learns more of
    them).  It is a :class:`SessionClosed`, but unlike a broken link it is not
    resumable: the client is finished.  Find out why the application stalled,
    then reconnect with a new :class:`BlockingClient`.  ``watchdog`` is the
    limit that expired, in seconds.
    """

    def __init__(self, watchdog: float) -> None:
        super().__init__(
            f"controller watchdog expired after {watchdog:g} s without a call into the "
            "BlockingClient; the session is closed and the arm halted outstanding work: "
            "the controller must reconnect (a new BlockingClient)"
        )
        self.watchdog = watchdog


class BlockingClient:
    """The async client, driven from ordinary threads.  Use ``with``.

    ``watchdog`` (seconds, or None for none -- the default) is the controller
    watchdog: the most time the application may spend *between* calls into
    this client while it is open.  The clock starts when :meth:`open` returns;
    every command method, :meth:`send` and :meth:`kick` restart it, and time
    spent *inside* a call (waiting for a command to complete, however long)
    counts as alive.  A controller loop with nothing to command calls
    :meth:`kick` to say it is alive; reading :attr:`latest_telemetry` does
    not count.  When the watchdog expires, the background thread at once
    closes the session with a BYE (SHUTDOWN), which makes the arm halt the
    command running and fail the queued ones (STOPPED) and release control;
    it logs a warning.  From then on every call raises
    :class:`WatchdogExpired` (except :meth:`close`, which only finishes the
    thread): reconnect with a new client.  If the BYE cannot reach the arm
    (link down at that moment), it halts anyway when its deadman trips.
    Several application threads may share the client: any call from any of
    them counts.
    """

    def __init__(
        self,
        make_client: Callable[[], ArmClient],
        *,
        timeout: float = 60.0,
        watchdog: float | None = None,
    ) -> None:
        if watchdog is not None and (
            isinstance(watchdog, bool) or not math.isfinite(watchdog) or watchdog <= 0
        ):
            raise ValueError(
                f"watchdog must be a finite number of seconds > 0, or None; got {watchdog!r}"
            )
        self._make = make_client
        self.timeout = timeout
        """Default seconds any call waits (connect, each command, close)."""
        self.watchdog = watchdog
        """Most seconds the application may go without a call (None: no watchdog)."""
        # Watchdog state, touched only in the background (trio) thread, except
        # _expired, which the calling threads read to fail fast.
        self._busy = 0  # calls in progress: time inside a call counts as alive
        self._last_call = 0.0  # trio time the last call started or ended
        self._expired = False
        self._thread: threading.Thread | None = None
        self._started = threading.Event()
        self._error: BaseException | None = None
        self._arm: ArmClient | None = None
        self._token: trio.lowlevel.TrioToken | None = None
        self._stop: trio.Event | None = None

    @classmethod
    def tcp(
        cls,
        host: str,
        port: int = DEFAULT_PORT,
        *,
        timeout: float = 60.0,
        watchdog: float | None = None,
        ssl_context: ssl.SSLContext | None = None,
        server_hostname: str | None = None,
        config: ClientConfig | None = None,
        **options: Unpack[ClientOptions],
    ) -> BlockingClient:
        """A blocking client for :func:`~tcpstream.connect_tcp` (same options, typed).

        ``timeout`` and ``watchdog`` are the :class:`BlockingClient`'s own.
        """
        settings = client_config(config, options)  # checked here, not in the thread
        return cls(
            lambda: connect_tcp(
                host,
                port,
                ssl_context=ssl_context,
                server_hostname=server_hostname,
                config=settings,
            ),
            timeout=timeout,
            watchdog=watchdog,
        )

    # --- lifetime -------------------------------------------------------------

    def __enter__(self) -> BlockingClient:
        self.open()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def open(self) -> None:
        """Connect (in the background thread); raises what connecting raised."""
        self._check_expired()
        self._thread = threading.Thread(target=trio.run, args=(self._main,), daemon=True)
        self._thread.start()
        if not self._started.wait(self.timeout):
            raise TimeoutError(f"no session within {self.timeout} s")
        if self._error is not None:
            self._thread.join(self.timeout)
            raise self._error

    def close(self) -> None:
        """Finish outstanding commands, say goodbye, stop the thread.

        After the watchdog expired there is nothing left to finish: this only
        waits for the thread and never raises :class:`WatchdogExpired` (so a
        ``with`` block ends cleanly, with the application's own exception).
        """
        thread, token, stop = self._thread, self._token, self._stop
        if thread is None or token is None or stop is None:
            return
        with contextlib.suppress(trio.RunFinishedError):
            trio.from_thread.run_sync(stop.set, trio_token=token)
        thread.join(self.timeout)
        self._thread = None

    async def _main(self) -> None:
        try:
            async with self._make() as arm:
                self._arm = arm
                self._token = trio.lowlevel.current_trio_token()
                self._stop = trio.Event()
                self._last_call = trio.current_time()
                self._started.set()
                if self.watchdog is None:
                    await self._stop.wait()
                elif await self._watch(self.watchdog, self._stop):
                    # Raised *inside* the ArmClient's block on purpose: its
                    # error exit sends BYE (SHUTDOWN) at once without waiting
                    # for outstanding commands -- the arm halts them (STOPPED)
                    # and releases control.  A normal aclose() would first
                    # wait for them to finish: the hung controller's commands
                    # would run to the end with nobody watching.
                    #
                    # No EMERGENCY_STOP first: with work outstanding the
                    # arm's BYE handling is the same halt (executor.halt,
                    # cancel the running command, fail the queue, STOPPED),
                    # and with none there is nothing of ours to stop.  A
                    # stop would add a packet and, to be of any use, a round
                    # trip (seconds on a slow link) before the BYE; it would
                    # wait for a session during a reconnect; and it would be
                    # counted as an operator's emergency stop.  If the BYE
                    # cannot get out (link down, or slower than the client's
                    # bounded close), the stream just ends and the arm's
                    # deadman halts everything within its dead time.
                    raise WatchdogExpired(self.watchdog)
        except BaseException as exc:  # handed to the calling thread
            self._error = exc
        finally:
            self._started.set()

    async def _watch(self, limit: float, stop: trio.Event) -> bool:
        """Wait for ``stop`` (False) or for the watchdog to expire (True).

        Runs in the background thread on trio's clock, so it is bounded and
        cancelled with everything else there.  It wakes at the earliest
        moment the limit could have passed and re-checks, rather than being
        woken by every call: a call costs the watchdog nothing.
        """
        while not stop.is_set():
            now = trio.current_time()
            if self._busy == 0 and now - self._last_call >= limit:
                # Set before anything can yield: a call arriving from now on
                # fails in _enter instead of starting a command.
                self._expired = True
                log.warning(
                    "controller watchdog expired: the application made no call into the "
                    "BlockingClient for %g s (is its thread hung?); closing the session so "
                    "the arm halts outstanding work.  Find the stall (or call kick() from "
                    "an idle loop), then reconnect with a new BlockingClient.",
                    limit,
                )
                return True
            # While a call is in progress its end restarts the clock, so
            # looking again one limit from now is early enough.
            with trio.move_on_at((now if self._busy else self._last_call) + limit):
                await stop.wait()
        return False

    def _check_expired(self) -> None:
        if self._expired:
            assert self.watchdog is not None
            raise WatchdogExpired(self.watchdog)

    def _enter(self) -> None:
        """In the background thread: a call starts (refused once expired)."""
        self._check_expired()
        self._busy += 1
        self._last_call = trio.current_time()

    def _leave(self) -> None:
        self._busy -= 1
        self._last_call = trio.current_time()

    # --- calls ----------------------------------------------------------------

    def _connected(self) -> tuple[ArmClient, trio.lowlevel.TrioToken]:
        # Expiry first: after it the thread is gone and "not connected" would
        # hide why.
        self._check_expired()
        arm, token = self._arm, self._token
        if arm is None or token is None or self._thread is None:
            raise RuntimeError("not connected: use 'with BlockingClient...(...) as arm:'")
        return arm, token

    def _call(self, fn: Callable[[ArmClient], Awaitable[T]], timeout: float | None) -> T:
        arm, token = self._connected()
        limit = self.timeout if timeout is None else timeout

        async def bounded() -> T:
            self._enter()
            try:
                with trio.fail_after(limit):
                    return await fn(arm)
            finally:
                self._leave()

        try:
            return trio.from_thread.run(bounded, trio_token=token)
        except trio.TooSlowError:
            raise TimeoutError(f"no answer within {limit} s (the command may still run)") from None
        except trio.RunFinishedError:
            # The background thread ended under us: say so if the watchdog
            # ended it (else, as ever, close() from another thread did).
            self._check_expired()
            raise

    def kick(self) -> None:
        """Tell the watchdog the application is alive, without commanding the arm.

        Cheap: one hand-off to the background thread, nothing on the link.
        Call it from a controller loop that may go longer than ``watchdog``
        without a command.  Raises :class:`WatchdogExpired` if it already
        expired (it does not revive the session); a no-op without a watchdog.
        """
        _, token = self._connected()
        if self.watchdog is None:
            return
        try:
            trio.from_thread.run_sync(self._touch, trio_token=token)
        except trio.RunFinishedError:
            self._check_expired()
            raise

    def _touch(self) -> None:
        self._enter()
        self._leave()

    def send(self, command: Command, *, timeout: float | None = None) -> CommandResult:
        """Run ``command``; its result, or :class:`CommandFailed` / :class:`SessionClosed`."""
        return self._call(lambda arm: arm.send(command), timeout)

    @property
    def latest_telemetry(self) -> Feedback | None:
        """The most recent TELEMETRY state (None before the first).

        A plain read: it does not kick the watchdog, but raises
        :class:`WatchdogExpired` once it has expired (the state is stale).
        """
        self._check_expired()
        return self._arm.latest_telemetry if self._arm is not None else None

    def reinitialize(self) -> CommandResult:
        return self.send(build.reinitialize())

    def status(self) -> CommandResult:
        return self.send(build.status())

    def open_fingers(self, opening: float = 0.0) -> CommandResult:
        return self.send(build.open_fingers(opening))

    def close_fingers(self) -> CommandResult:
        return self.send(build.close_fingers())

    def move_to(
        self,
        p: Sequence[float],
        s: Sequence[float] | None = None,
        a: Sequence[float] | None = None,
    ) -> CommandResult:
        return self.send(build.move_to(p, s, a))

    def move_joints(self, joints: Sequence[float]) -> CommandResult:
        return self.send(build.move_joints(joints))

    def move_joint(self, joint: int, amount: float) -> CommandResult:
        return self.send(build.move_joint(joint, amount))

    def transform_to_pose(self, joints: Sequence[float]) -> CommandResult:
        return self.send(build.transform_to_pose(joints))

    def transform_to_joints(
        self, p: Sequence[float], s: Sequence[float], a: Sequence[float]
    ) -> CommandResult:
        return self.send(build.transform_to_joints(p, s, a))

    def squeeze(self, force: float) -> CommandResult:
        return self.send(build.squeeze(force))

    def weigh(self) -> CommandResult:
        return self.send(build.weigh())

    def change_speed(self, fraction: float) -> CommandResult:
        return self.send(build.change_speed(fraction))

    def center_fingers(self) -> CommandResult:
        return self.send(build.center_fingers())

    def terminate(self) -> CommandResult:
        return self.send(build.terminate())

    def move_delta(
        self,
        dp: Sequence[float],
        drot: Sequence[float] = (0.0, 0.0, 0.0),
        *,
        pose_change: bool = False,
    ) -> CommandResult:
        return self.send(build.move_delta(dp, drot, pose_change=pose_change))

    def move_path(self, points: Sequence[Sequence[float]], blend: float = 0.0) -> CommandResult:
        return self.send(build.move_path(points, blend))

    def emergency_stop(self) -> CommandResult:
        return self.send(build.emergency_stop())

    def add_obstacle(self, minimum: Sequence[float], maximum: Sequence[float]) -> CommandResult:
        return self.send(build.add_obstacle(minimum, maximum))
