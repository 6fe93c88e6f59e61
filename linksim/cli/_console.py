"""``linksim console``, ``linksim control`` and ``linksim plot``: argument parsing and exit status.

Exit status of ``console`` and ``control``: 0 when every command completed
(an observer: when the watched session ended or the timeout passed), 1 when
the run failed or the preview refused the plan (``--require-preview``, or a
task file without ``--force``), 2 for bad options or a bad task file, 130
on Ctrl-C.  ``plot``: 0 when the PNG was written, 1 when it could not be (no
matplotlib, an empty or malformed log).
"""

from __future__ import annotations

import argparse
import json
import sys
from functools import partial

import serialsocket
from linksim._errors import ConfigError
from linksim._plotting import PlotUnavailable
from linksim.arm import WorldConfig
from linksim.control import (
    TaskFile,
    TerminalLines,
    parse_log,
    plot_log,
    preview,
    resolve_task,
    script_lines,
)
from linksim.demo import (
    ConsoleOptions,
    DemoOptions,
    print_report,
    run_console,
    run_control,
    run_time_limit,
)
from linksim.link import DirectionConfig, LinkConfig, run_virtual
from serialsocket.interrupt import run_interruptibly

from . import _demo
from ._args import BAUD, SECONDS, SERIAL_PORT, TCP_PORT, FloatRange, load_world, read_key
from ._link import add_link_arguments, config_from_args

__all__ = [
    "add_console_arguments",
    "add_control_arguments",
    "add_plot_arguments",
    "console_main",
    "control_main",
    "plot_main",
]


_SPEEDUP = FloatRange(0.0, 1e6, unit="times real time")
"""--speedup: 0 runs as fast as possible; a million times real time is a typo's neighbour."""


def add_console_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim console`` (those of ``linksim control``, plus the console's)."""
    add_link_arguments(ap, default_preset="noisy-moon")
    ap.add_argument("--transport", choices=["serial", "tcp"], default="serial")
    ap.add_argument(
        "--virtual",
        "--demo",
        action="store_true",
        help="arm server, impaired link (--preset, default noisy-moon) and console in one "
        "process on a virtual clock: instant, deterministic",
    )
    ap.add_argument(
        "--speedup",
        type=_SPEEDUP,
        default=0.0,
        help="with --virtual: run the virtual clock this many times faster than real time "
        "to watch the run (default 0: as fast as possible)",
    )
    ap.add_argument("--observer", action="store_true", help="watch an arm (tcp); send nothing")
    _task_arguments(ap)
    ap.add_argument(
        "--interactive",
        "-i",
        action="store_true",
        help="type your own commands at a prompt (move_joint 1 20deg, path ..., estop, status, "
        "help; Tab completes): each is previewed on the local model, queued, sent, and its "
        "outcome shown against the prediction; piped in, the lines are a script",
    )
    ap.add_argument(
        "--require-preview",
        action="store_true",
        help="send nothing if the local model predicts a refusal",
    )
    ap.add_argument(
        "--preview-only",
        action="store_true",
        help="print what the local model predicts for the task and exit (connects to nothing)",
    )
    ap.add_argument("--log", metavar="FILE", help="write every state and command event (JSONL)")
    ap.add_argument(
        "--world", help="world configuration (TOML; - for stdin); default: the demo's table"
    )
    ap.add_argument("--port", type=SERIAL_PORT, help="serial device or pty path (serial transport)")
    ap.add_argument("--baud", type=BAUD, default=9600, help="line rate, bit/s (default 9600)")
    ap.add_argument("--dial", metavar="NUMBER", help="dial NUMBER through a Hayes modem first")
    ap.add_argument("--host", default="127.0.0.1", help="arm server address (tcp)")
    ap.add_argument("--tcp-port", type=TCP_PORT, default=7010, help="arm server port (tcp)")
    ap.add_argument("--key-file", help="file holding the pre-shared key as hex")
    ap.add_argument("--plain", action="store_true", help="line output even on a terminal")
    ap.add_argument("--json", action="store_true", help="print a final summary as JSON")
    ap.add_argument(
        "--timeout",
        type=SECONDS,
        help="give up after this many s (default: 600, or 40 round trips of a longer line)",
    )


def _task_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument(
        "--task",
        default="rock",
        metavar="rock|FILE",
        help="the commands to drive: rock (seed 000's rock task, the default) or a task file "
        "(.toml or .json, - for stdin; examples/tasks/ has some)",
    )
    ap.add_argument(
        "--force",
        action="store_true",
        help="send a task file even when the local model predicts the arm will refuse a command",
    )


def _check_stdin(args: argparse.Namespace) -> None:
    if args.task == "-" and args.world == "-":
        raise ConfigError("--task - and --world - cannot both read stdin")


def _load_task(args: argparse.Namespace, world: WorldConfig) -> TaskFile:
    """``--task``: the rock task or a task file, parsed and checked (errors: ValueError)."""
    stdin = sys.stdin.read((1 << 20) + 1) if args.task == "-" else None
    try:
        return resolve_task(args.task, world, stdin)
    except KeyError as exc:  # the rock task in a world without a rock or a bin
        raise ConfigError(f"--task rock: {exc.args[0]}") from None


def _is_file(task: TaskFile) -> bool:
    return task.source != "rock"


def _refusal(task: TaskFile, world: WorldConfig) -> str | None:
    """Why the preview refuses a task file (None: it passes, or it is a built-in task)."""
    if not _is_file(task):
        return None
    refusal = preview(task.commands, world).first_refusal
    if refusal is None:
        return None
    return (
        f"{task.where(refusal.index)} ({refusal.label}) would be refused by the arm: "
        f"{refusal.reason.name}: {refusal.message}; nothing was sent (--force sends it anyway)"
    )


_NOT_INTERACTIVE = (
    ("observer", "--observer"),
    ("force", "--force"),
    ("require_preview", "--require-preview"),
    ("preview_only", "--preview-only"),
    ("log", "--log"),
)


def _check_interactive(args: argparse.Namespace) -> None:
    """Options that would be ignored with ``--interactive`` are refused."""
    if not args.interactive:
        return
    for dest, flag in _NOT_INTERACTIVE:
        if getattr(args, dest):
            raise ConfigError(f"{flag} is for a task run; not with --interactive")
    if args.task != "rock":
        raise ConfigError("--interactive takes the commands you type; not with --task")
    if args.world == "-":
        raise ConfigError("--interactive reads its command lines on stdin; not with --world -")


MAX_SCRIPT = 1 << 20
"""Bytes of command lines piped to ``--interactive``: read whole, like a task file."""


def _lines(args: argparse.Namespace) -> tuple[TerminalLines | None, list[str] | None]:
    """A terminal's line reader, or the lines piped in (read now, so a virtual run
    is the same run every time)."""
    if sys.stdin.isatty():
        return TerminalLines(), None
    text = sys.stdin.read(MAX_SCRIPT + 1)
    if len(text) > MAX_SCRIPT:
        raise ConfigError(f"more than {MAX_SCRIPT} bytes of command lines on stdin")
    return None, text.splitlines()


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def console_main(args: argparse.Namespace) -> int:
    """``linksim console``."""
    try:
        _check_stdin(args)
        _check_interactive(args)
        if args.force and args.require_preview:
            raise ConfigError("--force and --require-preview contradict each other")
        if args.observer and (args.force or args.task != "rock"):
            raise ConfigError("--observer sends nothing: not with --task or --force")
        world = load_world(args.world)
        task = _load_task(args, world)
        key = read_key(args.key_file) if args.key_file else None
        if args.speedup < 0 or (args.speedup and not args.virtual):
            raise ConfigError("--speedup is a positive factor for --virtual runs")
        if args.observer and (args.virtual or args.require_preview):
            raise ConfigError(
                "--observer watches a running arm: not with --virtual/--require-preview"
            )
        if args.virtual:
            if args.config is None and args.preset is None:
                args.preset = "noisy-moon"
            link = config_from_args(args)
            preset = args.preset if args.config is None else str(args.config)
        else:
            if args.transport == "serial" and not args.port and not args.preview_only:
                raise ConfigError("--port PATH is needed for the serial transport")
            rate = args.baud if args.transport == "serial" else None
            link = LinkConfig.symmetric(DirectionConfig(rate=rate, delay=args.delay or 0.0))
            preset = None
        demo = DemoOptions(
            link=link,
            preset=preset,
            transport=args.transport,
            virtual=args.virtual,
            world=world,
            key=key,
            live=False if args.plain else None,
            timeout=args.timeout if args.timeout is not None else run_time_limit(link),
        )
        terminal, script = _lines(args) if args.interactive else (None, None)
        rate = args.speedup
        if terminal is not None and args.virtual and not rate:
            rate = 1.0  # someone is typing: the virtual clock keeps the wall clock's pace
        options = ConsoleOptions(
            demo,
            observer=args.observer,
            require_preview=args.require_preview or (_is_file(task) and not args.force),
            log=args.log,
            host=args.host,
            tcp_port=args.tcp_port,
            port=args.port,
            baud=args.baud,
            dial=args.dial,
            rate=rate,
            task=task,
            lines=terminal or (None if script is None else script_lines(script, echo=_say)),
            say=terminal.say if terminal is not None else _say,
        )
    except (ConfigError, ValueError, OSError, serialsocket.LocalProtocolError) as exc:
        print(f"linksim console: {exc}", file=sys.stderr)
        return 2
    if args.preview_only:
        return _preview_only(world, task, as_json=args.json)
    try:
        result = run_console(options)
    except KeyboardInterrupt:
        print("linksim console: interrupted", file=sys.stderr)
        return 130  # as a shell reports SIGINT
    if args.json:
        json.dump(result.as_dict(), sys.stdout)
        sys.stdout.write("\n")
    if result.error:
        print(f"linksim console: {result.error}", file=sys.stderr)
    return 0 if result.ok else 1


def _preview_only(world: WorldConfig, task: TaskFile, *, as_json: bool) -> int:
    """``--preview-only``: the task on the local model; 0 when nothing is refused."""
    report = preview(task.commands, world)
    if as_json:
        json.dump(report.as_dict(), sys.stdout)
        sys.stdout.write("\n")
    else:
        for o in report.outcomes:
            verdict = "ok" if o.ok else f"{o.reason.name}: {o.message}"
            # Results to stdout (`--preview-only > plan.txt`), diagnostics to stderr.
            print(f"#{o.index:<2} {o.start:6.2f} s +{o.duration:5.2f} s  {o.label}: {verdict}")
        p = ", ".join(f"{x:+.3f}" for x in report.final.p)
        print(
            f"{'OK' if report.ok else 'REFUSED'}: {report.duration:.2f} s of motion, "
            f"ends with the hand at ({p}) m"
        )
    return 0 if report.ok else 1


def add_control_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim control``: the connection's (``linksim demo``'s module), the task's."""
    _demo.add_control_arguments(ap)
    _task_arguments(ap)
    ap.add_argument(
        "--virtual",
        action="store_true",
        help="run the arm server in this process over a clean in-memory line of --baud and "
        "--delay, on a virtual clock: instant, deterministic (no arm-server needed)",
    )


def control_main(args: argparse.Namespace) -> int:
    """``linksim control``: run a task against a running ``linksim arm-server`` (or --virtual)."""
    prog = "linksim control"
    try:
        if args.virtual and (args.port or args.dial):
            raise ConfigError("--port and --dial reach a real arm server; not with --virtual")
        if args.virtual and (args.host != "127.0.0.1" or args.tcp_port != 7010):
            raise ConfigError("--host and --tcp-port reach a real arm server; not with --virtual")
        _demo.refuse_ignored_options(args)  # --dial or --window where they cannot act
        if not args.virtual and args.transport == "serial" and not args.port:
            raise ConfigError("--port PATH is needed for the serial transport (or use --virtual)")
        _check_stdin(args)
        world = load_world(args.world)
        task = _load_task(args, world)
        key = read_key(args.key_file) if args.key_file else None
        link = LinkConfig.symmetric(
            DirectionConfig(
                rate=args.baud if args.transport == "serial" else None, delay=args.delay
            )
        )
        options = DemoOptions(
            link=link,
            preset=None,
            transport=args.transport,
            virtual=args.virtual,
            window=args.window,
            max_len=args.max_len,
            world=world,
            key=key,
            progress=not args.quiet,
            live=False if args.plain else None,
            timeout=args.timeout if args.timeout is not None else run_time_limit(link),
        )
    except (ConfigError, ValueError, OSError, serialsocket.LocalProtocolError) as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    refusal = None if args.force else _refusal(task, world)
    if refusal is not None:
        print(f"{prog}: {refusal}", file=sys.stderr)
        return 1
    run = partial(
        run_control,
        options,
        key=key,
        host=args.host,
        tcp_port=args.tcp_port,
        port=args.port,
        baud=args.baud,
        dial=args.dial,
        commands=task.commands,
        task=task.name if _is_file(task) else "rock task",
    )
    try:
        if args.virtual:
            report = run_virtual(run)  # trio's virtual clock, its scheduler seeded
        else:
            report = run_interruptibly(run)
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130  # as a shell reports SIGINT
    print_report(report, as_json=args.json)
    if not report.ok:
        print(f"{prog}: {report.error or 'the run failed'}", file=sys.stderr)
        return 1
    return 0


def add_plot_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``linksim plot``."""
    ap.add_argument(
        "log", metavar="FILE", help="a telemetry log written by linksim console --log (- for stdin)"
    )
    ap.add_argument("--out", required=True, metavar="PNG", help="the image to write")


def plot_main(args: argparse.Namespace) -> int:
    """``linksim plot FILE --out PNG``."""
    try:
        log = parse_log(sys.stdin, "<stdin>") if args.log == "-" else args.log
        path = plot_log(log, args.out)
    except (PlotUnavailable, ValueError, OSError) as exc:
        print(f"linksim plot: {exc}", file=sys.stderr)
        return 1
    print(path)  # the result: where the plot is
    return 0
