"""The command line's I/O: lines from a terminal or a script, commands through an arm client.

:func:`run_command_line` moves lines into a
:class:`~linksim.control._command_line.CommandStack` and carries out what it
hands back: it submits the commands through a connected
:class:`tcpstream.ArmClient`, sends the emergency stop at once, feeds every
reply back (one task applies them, oldest command first, as
:class:`~linksim.control._control.TaskRun` does, so a run on a virtual clock
is the same run every time), and feeds the telemetry to the model.  Every
wait it makes for the arm is bounded (``timeout``); the wait for a line is
the operator's and can always be cancelled (Ctrl-C).

Line sources: :func:`script_lines` (a list: piped input, tests) and
:class:`TerminalLines` (the stdlib's ``readline``: history with the arrow
keys, Tab completion from the stack, read on a worker thread that Ctrl-C
abandons).
"""

from __future__ import annotations

import readline
import sys
from collections.abc import Awaitable, Callable, Sequence
from typing import TextIO

import trio

from tcpstream import ArmClient, CommandFailed, CommandHandle, SessionError

from ._command_line import (
    CommandStack,
    EmergencyStop,
    EntryState,
    Output,
    Quit,
    Say,
    Submit,
    WaitIdle,
    complete_line,
)
from ._control import _notify_on_progress, _Wake

__all__ = ["LineSource", "TerminalLines", "run_command_line", "script_lines"]

LineSource = Callable[[], Awaitable[str | None]]
"""Returns the next line, or None at the end of input."""

PROMPT = "telelink> "


def script_lines(lines: Sequence[str], echo: Callable[[str], None] | None = None) -> LineSource:
    """The lines of a script, one per call, then None; ``echo`` shows each (``> line``)."""
    it = iter(list(lines))

    async def next_line() -> str | None:
        await trio.lowlevel.checkpoint()
        line = next(it, None)
        if line is not None and echo is not None:
            echo(f"{PROMPT}{line}")
        return line

    return next_line


class TerminalLines:
    """Lines typed at a terminal, with readline's history and Tab completion.

    ``input()`` blocks, so it runs on a worker thread that a cancellation
    (Ctrl-C) abandons: the session ends at once, the thread dies with the
    process.  :meth:`say` prints a message without mangling the line being
    typed.
    """

    def __init__(
        self,
        *,
        prompt: str = PROMPT,
        out: TextIO | None = None,
        complete: Callable[[str], list[str]] = complete_line,
    ) -> None:
        self._completions = complete
        self._prompt = prompt
        self._out = out if out is not None else sys.stderr
        self._reading = False
        # input() edits the line with readline, prompt on stdout, only when stdout
        # is the terminal too; with stdout redirected (--json > FILE) the prompt
        # goes to stderr, the results stay clean, and the line is read plainly.
        self._editing = sys.stdout.isatty()
        readline.set_completer_delims(" \t")
        readline.set_completer(self._complete)
        readline.parse_and_bind("tab: complete")

    def _complete(self, text: str, state: int) -> str | None:
        line = readline.get_line_buffer()[: readline.get_endidx()]
        options = self._completions(line)
        return options[state] if state < len(options) else None

    async def __call__(self) -> str | None:
        self._reading = True
        try:
            return await trio.to_thread.run_sync(self._read, abandon_on_cancel=True)
        except EOFError:
            print(file=self._out)
            return None
        finally:
            self._reading = False

    def _read(self) -> str:
        if self._editing:
            return input(self._prompt)
        print(self._prompt, end="", file=self._out, flush=True)
        return input()

    def say(self, text: str) -> None:
        if self._reading:
            # Over the prompt, then the prompt and what was typed so far again.
            print("\r\x1b[K" + text, file=self._out, flush=True)
            prompt = sys.stdout if self._editing else self._out
            prompt.write(self._prompt + readline.get_line_buffer())
            prompt.flush()
        else:
            print(text, file=self._out, flush=True)


async def run_command_line(
    client: ArmClient,
    stack: CommandStack,
    next_line: LineSource,
    say: Callable[[str], None],
    *,
    timeout: float,
) -> None:
    """Run the command line until the lines end or ``quit``, then wait (at most
    ``timeout`` s of the run's clock) for the commands still pending.

    ``wait`` lines wait at most ``timeout`` too.  A session error (the link
    died, the arm ended the session) ends the lines: it is raised, as itself,
    once what was seen has been shown.
    """
    handles: list[tuple[int, CommandHandle]] = []
    wake = _Wake()  # a reply may have arrived: apply them
    settled = _Wake()  # the replies seen so far are applied

    def show(outputs: list[Output]) -> None:
        for output in outputs:
            if isinstance(output, Say):
                say(output.text)

    def apply() -> None:
        now = trio.current_time()
        for index, handle in handles:
            entry = stack.entry(index)
            if entry.state is EntryState.SENT and handle.position is not None:
                show(stack.accepted(index, now, handle.position))
            if not (entry.state.pending and handle.done):
                continue
            error = handle.error
            if error is None:
                assert handle.result is not None
                show(stack.completed(index, now, handle.result))
            elif isinstance(error, CommandFailed):
                reason = error.reason.name
                show(stack.failed(index, now, reason, error.message, error.feedback))
            else:
                name = type(error).__name__
                show(stack.failed(index, now, name, str(error), session=True))
        handles[:] = [(i, h) for i, h in handles if stack.entry(i).state.pending]
        settled.set()

    async def applier() -> None:
        while True:
            await wake.wait()
            apply()

    async def telemetry() -> None:
        async for feedback in client.telemetry():
            stack.telemetry(feedback, trio.current_time())

    async def emergency_stop() -> None:
        try:
            result = await client.emergency_stop()
        except SessionError as exc:
            show(stack.stopped(trio.current_time(), error=f"{type(exc).__name__}: {exc}"))
        except CommandFailed as exc:
            error = f"{exc.reason.name}: {exc.message}"
            show(stack.stopped(trio.current_time(), error=error))
        else:
            show(stack.stopped(trio.current_time(), result.feedback))
        wake.set()

    async def wait_idle() -> None:
        with trio.move_on_after(timeout) as scope:
            while not stack.idle:
                await settled.wait()
        if scope.cancelled_caught:
            say(f"wait: gave up after {timeout:g} s with {len(stack.pending)} commands pending")

    async def submit(nursery: trio.Nursery, output: Submit) -> None:
        try:
            handle = await client.submit(output.command)
        except CommandFailed as exc:  # refused by the client before it was sent
            show(stack.failed(output.index, trio.current_time(), exc.reason.name, exc.message))
            return
        except SessionError as exc:
            now = trio.current_time()
            show(stack.failed(output.index, now, type(exc).__name__, str(exc), session=True))
            raise
        show(stack.sent(output.index, trio.current_time()))
        handles.append((output.index, handle))
        nursery.start_soon(_notify_on_progress, handle, wake)
        await trio.lowlevel.checkpoint()  # an immediate rejection is seen before the next line
        wake.set()

    async def lines(nursery: trio.Nursery) -> None:
        while True:
            line = await next_line()
            if line is None:
                return
            for output in stack.feed(line, trio.current_time()):
                if isinstance(output, Say):
                    say(output.text)
                elif isinstance(output, Submit):
                    await submit(nursery, output)
                elif isinstance(output, EmergencyStop):
                    nursery.start_soon(emergency_stop)
                elif isinstance(output, WaitIdle):
                    await wait_idle()
                elif isinstance(output, Quit):
                    return

    failure: SessionError | None = None
    async with trio.open_nursery() as nursery:
        nursery.start_soon(applier)
        nursery.start_soon(telemetry)
        try:
            await lines(nursery)
            await wait_idle()
        except SessionError as exc:
            failure = exc  # raised below, outside the nursery's exception group
        nursery.cancel_scope.cancel()
    if failure is not None:
        raise failure
