"""A blocking facade for controller code that is not async.

::

    with tcpstream.BlockingClient.tcp("arm.example", 7010, key=KEY) as arm:
        arm.move_joints([0, 0.5, -0.3, 0, 0.2, 0])
        print(arm.weigh().aux[0])

A background thread runs trio and an :class:`ArmClient`; every method hands
its call to that thread and waits at most ``timeout`` seconds.  A timeout
stops the *wait* (raising :class:`TimeoutError`), not the command: it may
still run at the arm -- call :meth:`emergency_stop` if it must not.
"""

from __future__ import annotations

import contextlib
import ssl
import threading
from collections.abc import Awaitable, Callable, Sequence
from types import TracebackType
from typing import Any, TypeVar

import trio

from . import _builders as build
from ._client import ArmClient
from ._commands import Command, CommandResult, Feedback

__all__ = ["BlockingClient"]

T = TypeVar("T")


class BlockingClient:
    """The async client, driven from ordinary threads.  Use ``with``."""

    def __init__(self, make_client: Callable[[], ArmClient], *, timeout: float = 60.0) -> None:
        self._make = make_client
        self.timeout = timeout
        """Default seconds any call waits (connect, each command, close)."""
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
        port: int,
        *,
        timeout: float = 60.0,
        ssl_context: ssl.SSLContext | None = None,
        **options: Any,
    ) -> BlockingClient:
        """A blocking client for :func:`~tcpstream.connect_tcp` (same options)."""
        from ._api import connect_tcp

        return cls(
            lambda: connect_tcp(host, port, ssl_context=ssl_context, **options), timeout=timeout
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
        self._thread = threading.Thread(target=trio.run, args=(self._main,), daemon=True)
        self._thread.start()
        if not self._started.wait(self.timeout):
            raise TimeoutError(f"no session within {self.timeout} s")
        if self._error is not None:
            self._thread.join(self.timeout)
            raise self._error

    def close(self) -> None:
        """Finish outstanding commands, say goodbye, stop the thread."""
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
                self._started.set()
                await self._stop.wait()
        except BaseException as exc:  # handed to the calling thread
            self._error = exc
        finally:
            self._started.set()

    # --- calls ----------------------------------------------------------------

    def _call(self, fn: Callable[[ArmClient], Awaitable[T]], timeout: float | None) -> T:
        arm, token = self._arm, self._token
        if arm is None or token is None or self._thread is None:
            raise RuntimeError("not connected: use 'with BlockingClient...(...) as arm:'")
        limit = self.timeout if timeout is None else timeout

        async def bounded() -> T:
            with trio.fail_after(limit):
                return await fn(arm)

        try:
            return trio.from_thread.run(bounded, trio_token=token)
        except trio.TooSlowError:
            raise TimeoutError(f"no answer within {limit} s (the command may still run)") from None

    def send(self, command: Command, *, timeout: float | None = None) -> CommandResult:
        """Run ``command``; its result, or :class:`CommandFailed` / :class:`SessionClosed`."""
        return self._call(lambda arm: arm.send(command), timeout)

    @property
    def latest_telemetry(self) -> Feedback | None:
        """The most recent TELEMETRY state (None before the first)."""
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
