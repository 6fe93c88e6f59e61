"""Kermit file transfer over a trio stream: the loop around the sans-I/O machines.

:func:`kermit_send` and :func:`kermit_receive` move bytes between a port
(any ``trio.abc.Stream``: :func:`open_port`, one side of
:func:`open_pty_pair`) and a :class:`KermitSender` / :class:`KermitReceiver`,
fire their timers, and do the file I/O the cores leave out.  Received files
are written to ``NAME.part`` and renamed when their Z arrives, so an
interrupted transfer never leaves a truncated file under the real name.

Each round hands the machine's events to the caller *before* its bytes go on
the line: the ACK of Z leaves only after the file is closed and renamed, and
if that fails the machine aborts and the ACK is never sent.

Both functions return only when the batch is complete and confirmed: every
file's Z acknowledged (sending) or received in order after all its data
(receiving), none of them discarded.  Anything else raises
:class:`KermitTransferError`, whose message says how far it got.
"""

from __future__ import annotations

import logging
import math
import os
import pathlib
from collections.abc import Callable, Sequence
from typing import BinaryIO

import trio

from ._core import (
    FileCompleted,
    FileData,
    FileStarted,
    KermitEvent,
    KermitStatistics,
    OutgoingFile,
    TransferComplete,
    TransferFailed,
)
from ._params import KermitConfig
from ._receiver import KermitReceiver
from ._sender import KermitSender

__all__ = ["KermitTransferError", "kermit_receive", "kermit_send", "safe_file_name"]

log = logging.getLogger(__name__)

_READ_SIZE = 65536
"""One read from the port: a pty hands out at most 4 KB, a window of long packets ~70 KB."""


class KermitTransferError(Exception):
    """A Kermit transfer failed.

    Attributes:
        by_peer: True when the peer ended it with an E packet (its message is
            in the text), False when we gave up (too many retries, a protocol
            violation, a local file error).
        statistics: the counters at the moment it failed.
    """

    def __init__(self, message: str, *, by_peer: bool, statistics: KermitStatistics) -> None:
        super().__init__(message)
        self.by_peer = by_peer
        self.statistics = statistics


def safe_file_name(name: str) -> str:
    """A peer's file name reduced to one safe path component.

    Directories are dropped (``../x`` and ``/etc/x`` both become ``x``), NUL
    and other control characters become ``_``, and names that are empty or
    only dots become ``unnamed``.
    """
    base = name.replace("\\", "/").rsplit("/", 1)[-1]
    base = "".join(c if c.isprintable() else "_" for c in base)
    if not base.strip(".").strip():
        return "unnamed"
    return base


async def _run(
    port: trio.abc.Stream,
    side: KermitSender | KermitReceiver,
    on_event: Callable[[KermitEvent], None],
    progress: Callable[[KermitStatistics], str],
) -> None:
    """Drive ``side`` until it finishes; ``on_event`` sees every event in order.

    Raises:
        KermitTransferError: ``side`` failed; the message ends with
            ``progress(statistics)`` (how far the transfer got).
    """
    failure: TransferFailed | None = None
    while True:
        # Events first: the caller stores what arrived before our ACKs of it
        # leave, and an abort while storing drops them (KermitSide.abort).
        while (event := side.next_event()) is not None:
            if isinstance(event, TransferFailed):
                failure = event
            on_event(event)
        out = side.data_to_send()
        if out:
            try:
                await port.send_all(out)
            except trio.BrokenResourceError as exc:
                side.abort("Line broken", message=f"the line failed: {exc}")
                continue
        if side.finished:
            break
        deadline = side.get_timer()
        data: bytes | bytearray = b""
        with trio.move_on_at(math.inf if deadline is None else deadline):
            try:
                data = await port.receive_some(_READ_SIZE)
            except trio.BrokenResourceError as exc:
                side.abort("Line broken", message=f"the line failed: {exc}")
                continue
            if not data:
                side.abort("Line closed", message="the line was closed (end of file on the port)")
                continue
        now = trio.current_time()
        if data:
            side.receive_data(data, now)
        else:
            side.handle_timer(now)
    if failure is not None:
        stats = side.statistics()
        raise KermitTransferError(
            f"{failure.message}; {progress(stats)}", by_peer=failure.by_peer, statistics=stats
        )


async def kermit_send(
    port: trio.abc.Stream,
    paths: Sequence[str | os.PathLike[str]],
    config: KermitConfig | None = None,
    *,
    on_event: Callable[[KermitEvent], None] | None = None,
) -> KermitStatistics:
    """Send files to a Kermit receiver on ``port`` (C-Kermit ``-r``, G-Kermit ``-r``, ours).

    Each file is sent under its base name, in binary mode.

    Returns:
        The final counters, once the receiver has acknowledged every file
        whole (the ACK of its Z; a Kermit receiver sends it only when it
        holds the whole file).

    Raises:
        OSError: a file cannot be opened (checked for all files before the
            transfer starts).
        KermitTransferError: the transfer failed, or the receiver refused or
            cancelled a file; ``by_peer`` says who gave up, and the message
            how many files the receiver confirmed and how many bytes it
            acknowledged, left unacknowledged in flight, or never got.
    """
    config = config or KermitConfig()
    handles: list[BinaryIO] = []
    try:
        files = []
        for p in paths:
            path = pathlib.Path(p)
            f: BinaryIO = path.open("rb")
            handles.append(f)
            files.append(OutgoingFile(path.name, os.fstat(f.fileno()).st_size, f))
        sender = KermitSender(files, config, trio.current_time())
        total = sum(f.size or 0 for f in files)
        discarded: list[str] = []

        def handle(event: KermitEvent) -> None:
            (on_event or _log_event)(event)
            if isinstance(event, FileCompleted) and event.discarded:
                discarded.append(event.name)

        def progress(stats: KermitStatistics) -> str:
            unacked = stats.file_bytes - stats.acknowledged_bytes
            return (
                f"the receiver confirmed {stats.files - len(discarded)} of {len(files)} "
                f"files whole; of {total} bytes, {stats.acknowledged_bytes} were acknowledged, "
                f"{unacked} sent but not acknowledged, "
                f"{max(total - stats.file_bytes, 0)} never sent"
            )

        await _run(port, sender, handle, progress)
        stats = sender.statistics()
        if discarded:
            raise KermitTransferError(
                f"the receiver refused or cancelled {', '.join(discarded)}; {progress(stats)}",
                by_peer=True,
                statistics=stats,
            )
        return stats
    finally:
        for f in handles:
            f.close()


async def kermit_receive(
    port: trio.abc.Stream,
    directory: str | os.PathLike[str] = ".",
    config: KermitConfig | None = None,
    *,
    on_event: Callable[[KermitEvent], None] | None = None,
) -> KermitStatistics:
    """Receive files from a Kermit sender on ``port`` into ``directory``.

    File names are reduced with :func:`safe_file_name`; an existing file of
    the same name is replaced when the new one is complete.  A file the
    sender discards (Z with ``D``) is deleted.

    Returns:
        The final counters, once the batch ended normally (B, in order after
        every file's Z) with every file stored whole.

    Raises:
        OSError: ``directory`` is not a directory.
        KermitTransferError: the transfer failed (the partial file stays as
            ``NAME.part``), a file could not be stored, or the sender
            discarded a file; the message says how many files were stored.
    """
    config = config or KermitConfig()
    target = pathlib.Path(directory)
    if not target.is_dir():
        raise NotADirectoryError(f"{target} is not a directory: create it or pick another")
    receiver = KermitReceiver(config, trio.current_time())
    current: list[tuple[BinaryIO, pathlib.Path, pathlib.Path]] = []
    stored: list[str] = []
    discarded: list[str] = []
    written = [0]  # bytes of the file in progress

    def handle(event: KermitEvent) -> None:
        (on_event or _log_event)(event)
        if isinstance(event, FileStarted):
            final = target / safe_file_name(event.name)
            part = final.with_name(final.name + ".part")
            try:
                current.append((part.open("wb"), part, final))
                written[0] = 0
            except OSError as exc:
                receiver.abort("Cannot create file", message=f"cannot create {part}: {exc}")
        elif isinstance(event, FileData) and current:
            try:
                current[-1][0].write(event.data)
                written[0] += len(event.data)
            except OSError as exc:
                receiver.abort("Cannot write file", message=f"cannot write {current[-1][1]}: {exc}")
        elif isinstance(event, FileCompleted) and current:
            f, part, final = current[-1]
            try:
                f.close()
                if event.discarded:
                    part.unlink()
                else:
                    part.replace(final)
            except OSError as exc:
                # Before the ACK of Z leaves (_run): the abort drops it.
                receiver.abort("Cannot store file", message=f"cannot store {final}: {exc}")
                return
            current.pop()
            (discarded if event.discarded else stored).append(final.name)

    def progress(stats: KermitStatistics) -> str:
        text = f"{len(stored)} files stored whole"
        if current:
            text += f"; {written[0]} bytes of the file in progress kept in {current[-1][1]}"
        return text

    try:
        await _run(port, receiver, handle, progress)
    finally:
        for f, _, _ in current:
            f.close()
    stats = receiver.statistics()
    if discarded:
        raise KermitTransferError(
            f"the sender cancelled {', '.join(discarded)} (deleted); {progress(stats)}",
            by_peer=True,
            statistics=stats,
        )
    return stats


def _log_event(event: KermitEvent) -> None:
    if isinstance(event, FileStarted):
        log.info("file %s", event.name)
    elif isinstance(event, FileCompleted):
        log.info("file %s %s", event.name, "discarded" if event.discarded else "complete")
    elif isinstance(event, TransferComplete):
        if event.break_acknowledged:
            log.info("transfer complete")
        else:
            # Not a failure: every file's Z was acknowledged, so the receiver
            # holds every file whole; only the end of the batch is unconfirmed.
            log.warning(
                "every file was acknowledged whole, but the ACK of B (end of batch) never came"
            )
    elif isinstance(event, TransferFailed):
        # Info, not a warning: the failure is raised (KermitTransferError) and
        # reported by whoever catches it; a warning here printed it twice.
        log.info("transfer failed: %s", event.message)
