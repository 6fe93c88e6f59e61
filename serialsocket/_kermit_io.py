"""Kermit file transfer over a trio stream: the loop around the sans-I/O machines.

:func:`kermit_send` and :func:`kermit_receive` move bytes between a port
(any ``trio.abc.Stream``: :func:`open_port`, one side of
:func:`open_pty_pair`) and a :class:`KermitSender` / :class:`KermitReceiver`,
fire their timers, and do the file I/O the cores leave out.  Received files
are written to ``NAME.part`` and renamed when their Z arrives, so an
interrupted transfer never leaves a truncated file under the real name.
"""

from __future__ import annotations

import logging
import math
import os
import pathlib
from collections.abc import Callable, Sequence
from typing import BinaryIO

import trio

from ._kermit import (
    FileCompleted,
    FileData,
    FileStarted,
    KermitEvent,
    KermitStatistics,
    OutgoingFile,
    TransferComplete,
    TransferFailed,
)
from ._kermit_params import KermitConfig
from ._kermit_receiver import KermitReceiver
from ._kermit_sender import KermitSender

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
) -> None:
    """Drive ``side`` until it finishes; ``on_event`` sees every event in order."""
    failure: TransferFailed | None = None
    while True:
        out = side.data_to_send()
        if out:
            await port.send_all(out)
        while (event := side.next_event()) is not None:
            if isinstance(event, TransferFailed):
                failure = event
            on_event(event)
        if side.finished:
            break
        deadline = side.get_timer()
        data: bytes | bytearray = b""
        with trio.move_on_at(math.inf if deadline is None else deadline):
            data = await port.receive_some(_READ_SIZE)
            if not data:
                side.abort("Line closed", message="the line was closed (end of file on the port)")
                continue
        now = trio.current_time()
        if data:
            side.receive_data(data, now)
        else:
            side.handle_timer(now)
    if failure is not None:
        raise KermitTransferError(
            failure.message, by_peer=failure.by_peer, statistics=side.statistics()
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
        The final counters.

    Raises:
        OSError: a file cannot be opened (checked for all files before the
            transfer starts).
        KermitTransferError: the transfer failed; its ``by_peer`` says who
            gave up.
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
        await _run(port, sender, on_event or _log_event)
        return sender.statistics()
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

    Raises:
        OSError: ``directory`` is not a writable directory.
        KermitTransferError: the transfer failed (the partial file stays as
            ``NAME.part``).
    """
    config = config or KermitConfig()
    target = pathlib.Path(directory)
    if not target.is_dir():
        raise NotADirectoryError(f"{target} is not a directory: create it or pick another")
    receiver = KermitReceiver(config, trio.current_time())
    current: list[tuple[BinaryIO, pathlib.Path, pathlib.Path]] = []

    def handle(event: KermitEvent) -> None:
        (on_event or _log_event)(event)
        if isinstance(event, FileStarted):
            final = target / safe_file_name(event.name)
            part = final.with_name(final.name + ".part")
            try:
                current.append((part.open("wb"), part, final))
            except OSError as exc:
                receiver.abort("Cannot create file", message=f"cannot create {part}: {exc}")
        elif isinstance(event, FileData) and current:
            current[-1][0].write(event.data)
        elif isinstance(event, FileCompleted) and current:
            f, part, final = current.pop()
            f.close()
            if event.discarded:
                part.unlink()
            else:
                part.replace(final)

    try:
        await _run(port, receiver, handle)
    finally:
        for f, _, _ in current:
            f.close()
    return receiver.statistics()


def _log_event(event: KermitEvent) -> None:
    if isinstance(event, FileStarted):
        log.info("file %s", event.name)
    elif isinstance(event, FileCompleted):
        log.info("file %s %s", event.name, "discarded" if event.discarded else "complete")
    elif isinstance(event, TransferComplete):
        if event.break_acknowledged:
            log.info("transfer complete")
        else:
            log.info("transfer complete (every file acknowledged; the ACK of B was lost)")
    elif isinstance(event, TransferFailed):
        # Info, not a warning: the failure is raised (KermitTransferError) and
        # reported by whoever catches it; a warning here printed it twice.
        log.info("transfer failed: %s", event.message)
