"""A small fake executor for the session tests: motion is ``trio.sleep(duration)``."""

from __future__ import annotations

import trio

from tcpstream import (
    Command,
    CommandCode,
    CommandFailed,
    CommandResult,
    FailureReason,
    Feedback,
)

HOME = Feedback(
    joints=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    finger_opening=0.08,
    p=(0.5, 0.0, 0.4),
    s=(0.0, 1.0, 0.0),
    a=(0.0, 0.0, 1.0),
)


class FakeArm:
    """Records every command it executes; MOVE_* take ``move_time`` seconds.

    ``fail`` maps a command code to the reason it fails with.  ``halts`` records
    every halt reason; ``executed`` every command that *started*, in order, so
    a test can count executions exactly.
    """

    def __init__(self, move_time: float = 1.0, control_rate_hz: float = 125.0) -> None:
        self.move_time = move_time
        self._rate = control_rate_hz
        self.executed: list[Command] = []
        self.finished: list[Command] = []
        self.halts: list[FailureReason] = []
        self.halt_times: list[float] = []
        self.fail: dict[CommandCode, FailureReason] = {}
        self.joints = [0.0] * 6
        self.moving = False

    @property
    def control_rate_hz(self) -> float:
        return self._rate

    async def execute(self, command: Command) -> CommandResult:
        self.executed.append(command)
        if command.code in self.fail:
            raise CommandFailed(
                self.fail[command.code], "scripted failure", aux=(1.0, 2.0, 3.0, 4.0)
            )
        if command.code.name.startswith("MOVE"):
            self.moving = True
            try:
                await trio.sleep(self.move_time)
            finally:
                self.moving = False
            if command.code is CommandCode.MOVE_JOINTS:
                self.joints = list(command.args[:6])
        self.finished.append(command)
        aux = (1.25, 0.0, 0.0, 0.0) if command.code is CommandCode.WEIGH else (0.0,) * 4
        return CommandResult(self.state(), aux)

    def halt(self, reason: FailureReason) -> None:
        self.halts.append(reason)
        try:
            self.halt_times.append(trio.current_time())
        except RuntimeError:  # halted from outside a trio run (server teardown)
            self.halt_times.append(float("nan"))
        self.moving = False

    def state(self) -> Feedback:
        j = self.joints
        return Feedback(
            joints=(j[0], j[1], j[2], j[3], j[4], j[5]),
            finger_opening=HOME.finger_opening,
            p=HOME.p,
            s=HOME.s,
            a=HOME.a,
        )

    def count(self, code: CommandCode) -> int:
        return sum(1 for c in self.executed if c.code is code)
