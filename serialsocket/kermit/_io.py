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

import dataclasses
import datetime
import logging
import math
import os
import pathlib
import shutil
from collections.abc import Callable, Sequence
from typing import BinaryIO

import trio

from serialsocket._socket import SerialSocket

from ._attributes import AttributeReply, FileAttributes
from ._core import (
    FileCompleted,
    FileData,
    FileStarted,
    KermitEvent,
    KermitStatistics,
    OutgoingFile,
    RemoteReply,
    TransferComplete,
    TransferFailed,
)
from ._params import KermitConfig
from ._receiver import KermitReceiver
from ._sender import KermitSender

_ABORT_GRACE = 2.0
"""Seconds an interrupted transfer may spend writing its E packet (a local
I/O bound: the line takes it at once unless flow control holds it)."""

_DATE_FORMAT = "%Y%m%d %H:%M:%S"
"""The A packet's date (C-Kermit's ``#`` attribute), local time."""
_SPACE_MARGIN = 1 << 20
"""Bytes kept free on the receiving file system besides the file itself."""

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


def _for_port(config: KermitConfig | None, port: trio.abc.Stream) -> KermitConfig:
    """``config`` (default: KermitConfig()) with streaming decided from the port when
    it is None: a serial socket is a reliable transport (C-Kermit's SET RELIABLE AUTO)."""
    config = config or KermitConfig()
    if config.streaming is None:
        config = dataclasses.replace(config, streaming=isinstance(port, SerialSocket))
    return config


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
    try:
        failure = await _loop(port, side, on_event)
    except trio.Cancelled:
        await _say_interrupted(port, side)
        raise
    if failure is not None:
        stats = side.statistics()
        raise KermitTransferError(
            f"{failure.message}; {progress(stats)}", by_peer=failure.by_peer, statistics=stats
        )


async def _say_interrupted(port: trio.abc.Stream, side: KermitSender | KermitReceiver) -> None:
    """The run was cancelled (Ctrl-C cancels a command's whole run): tell
    the peer with an E packet, as C-Kermit does, instead of leaving it to
    retry until its limit.  Shielded and bounded (``_ABORT_GRACE``); a port
    that fails now has nothing more to lose."""
    if side.finished:
        return
    side.abort("Transfer interrupted", message="the transfer was interrupted")
    out = side.data_to_send()
    if not out:
        return
    with trio.CancelScope(shield=True), trio.move_on_after(_ABORT_GRACE):
        try:
            discard = getattr(port, "discard_output", None)
            if callable(discard) and getattr(port, "can_discard_output", False):
                # Nothing queued matters any more: the E goes first, as the
                # serial socket's abort does (PROTOCOL.md 11).
                discard()
            await port.send_all(out)
        except (trio.BrokenResourceError, trio.ClosedResourceError, trio.BusyResourceError):
            return
        except OSError:
            return


async def _loop(
    port: trio.abc.Stream,
    side: KermitSender | KermitReceiver,
    on_event: Callable[[KermitEvent], None],
) -> TransferFailed | None:
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
    return failure


async def kermit_send(
    port: trio.abc.Stream,
    paths: Sequence[str | os.PathLike[str]],
    config: KermitConfig | None = None,
    *,
    on_event: Callable[[KermitEvent], None] | None = None,
    start_at: int = 0,
) -> KermitStatistics:
    """Send files to a Kermit receiver on ``port`` (C-Kermit ``-r``, G-Kermit ``-r``, ours).

    Each file is sent under its base name, in binary mode (text mode with
    ``config.text``).  ``start_at``: C-Kermit's PSEND -- each file is sent
    from this byte on (the receiver stores what arrives; the size attribute
    is what remains).

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
    config = _for_port(config, port)
    handles: list[BinaryIO] = []
    try:
        files = []
        for p in paths:
            path = pathlib.Path(p)
            f: BinaryIO = path.open("rb")
            handles.append(f)
            st = os.fstat(f.fileno())
            date = datetime.datetime.fromtimestamp(st.st_mtime).strftime(_DATE_FORMAT)
            start = min(start_at, st.st_size)
            f.seek(start)
            files.append(OutgoingFile(path.name, st.st_size - start, f, date))
        sender = KermitSender(files, config, trio.current_time())
        total = sum(f.size or 0 for f in files)
        discarded: list[str] = []

        def handle(event: KermitEvent) -> None:
            (on_event or _log_event)(event)
            if isinstance(event, FileCompleted) and event.discarded:
                why = f" ({event.reason})" if event.reason else ""
                discarded.append(event.name + why)

        def progress(stats: KermitStatistics) -> str:
            held = stats.resumed_bytes
            unacked = stats.file_bytes - (stats.acknowledged_bytes - held)
            return (
                f"the receiver confirmed {stats.files - len(discarded)} of {len(files)} "
                f"files whole; of {total} bytes, {stats.acknowledged_bytes} were acknowledged, "
                f"{unacked} sent but not acknowledged, "
                f"{max(total - stats.file_bytes - held, 0)} never sent"
                + (f", {held} already held by the receiver (recovery)" if held else "")
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
    request: tuple[str, bytes] | None = None,
    screen: Callable[[str], None] | None = None,
) -> KermitStatistics:
    """Receive files from a Kermit sender on ``port`` into ``directory``.

    ``request`` makes this a server's client: the R (GET) or G (REMOTE)
    packet sent first (see :class:`KermitReceiver`); text the server sends
    for the screen (X) and its short answers go to ``screen``.

    File names are reduced with :func:`safe_file_name`; an existing file of
    the same name is replaced when the new one is complete.  A file the
    sender discards (Z with ``D``) is deleted.  From the A packet: a file
    that does not fit the free space is refused (``N1``), the date becomes
    the file's modification time, and a RESEND is answered with the bytes
    already held in ``NAME.part`` (or, failing that, in ``NAME``: a partial
    file another Kermit left), which are then kept and appended to.

    Returns:
        The final counters, once the batch ended normally (B, in order after
        every file's Z) with every file stored whole.

    Raises:
        OSError: ``directory`` is not a directory.
        KermitTransferError: the transfer failed (the partial file stays as
            ``NAME.part``, ready for a RESEND), a file could not be stored, or
            the sender discarded a file; the message says how many files were
            stored.
    """
    config = _for_port(config, port)
    target = pathlib.Path(directory)
    if not target.is_dir():
        raise NotADirectoryError(f"{target} is not a directory: create it or pick another")
    store = _Store(target, screen)
    receiver = KermitReceiver(config, trio.current_time(), policy=store.decide, request=request)

    def handle(event: KermitEvent) -> None:
        (on_event or _log_event)(event)
        if isinstance(event, RemoteReply) and screen is not None:
            screen(event.text)
        try:
            store.on_event(event, receiver.attributes)
        except OSError as exc:
            # Before the ACK of Z leaves (_run): the abort drops it.
            receiver.abort("Cannot store file", message=f"cannot store {store.final}: {exc}")

    try:
        await _run(port, receiver, handle, store.progress)
    finally:
        store.close()
    stats = receiver.statistics()
    if store.discarded:
        raise KermitTransferError(
            f"the sender cancelled {', '.join(store.discarded)} (deleted); {store.progress(stats)}",
            by_peer=True,
            statistics=stats,
        )
    return stats


class _Store:
    """The receiver's file side: NAME.part while a file arrives, NAME once it is whole.

    The part file is opened at the first data (or at the end, for an empty
    file), not at the F packet: a RESEND's A packet must find the bytes a
    previous attempt left before anything truncates them.
    """

    def __init__(self, target: pathlib.Path, screen: Callable[[str], None] | None = None) -> None:
        self.target = target
        self.screen = screen
        self.showing = False
        self.final = target
        self.part = target
        self.file: BinaryIO | None = None
        self.append = False
        self.written = 0
        self.active = False
        self.stored: list[str] = []
        self.discarded: list[str] = []

    def decide(self, name: str, attributes: FileAttributes) -> AttributeReply:
        """The A packet's policy (see :class:`KermitReceiver`)."""
        self._paths(name)
        held = 0
        if attributes.disposition == "R":
            if not self.part.exists() and self.final.is_file():
                self.final.replace(self.part)  # another Kermit's partial file
            held = self.part.stat().st_size if self.part.is_file() else 0
            if attributes.size is not None and held > attributes.size:
                held = 0  # not a prefix of this file: start again
            self.append = held > 0
        if attributes.size is not None:
            free = shutil.disk_usage(self.target).free
            if attributes.size - held + _SPACE_MARGIN > free:
                return AttributeReply(refuse="1")
        return AttributeReply(resume_from=held if attributes.disposition == "R" else None)

    def _paths(self, name: str) -> None:
        self.final = self.target / safe_file_name(name)
        self.part = self.final.with_name(self.final.name + ".part")

    def _open(self) -> BinaryIO:
        if self.file is None:
            self.file = self.part.open("ab" if self.append else "wb")
            if self.append:
                self.written = self.file.tell()
        return self.file

    def on_event(self, event: KermitEvent, attributes: FileAttributes) -> None:
        """Store what the receiver reports (raises OSError when the disk fails)."""
        if isinstance(event, FileStarted) and event.screen:
            self.showing = True  # an X header: text for the screen, not a file
        elif isinstance(event, FileStarted):
            self.showing = False
            self._paths(event.name)
            self.file, self.append, self.written, self.active = None, False, 0, True
        elif isinstance(event, FileData) and self.showing:
            if self.screen is not None:
                self.screen(event.data.decode("utf-8", "replace"))
        elif isinstance(event, FileCompleted) and self.showing:
            self.showing = False
        elif isinstance(event, FileData) and self.active:
            self._open().write(event.data)
            self.written += len(event.data)
        elif isinstance(event, FileCompleted) and self.active:
            f = self._open()
            f.close()
            self.file = None
            if event.discarded:
                self.part.unlink()
                self.discarded.append(self.final.name)
            else:
                self.part.replace(self.final)
                self._set_date(attributes.date)
                self.stored.append(self.final.name)
            self.active = False

    def _set_date(self, date: str | None) -> None:
        """The A packet's date as the modification time (ignored when malformed)."""
        if not date:
            return
        try:
            when = datetime.datetime.strptime(date[:17], _DATE_FORMAT)
        except ValueError:
            try:
                when = datetime.datetime.strptime(date[:8], "%Y%m%d")
            except ValueError:
                return
        stamp = when.timestamp()
        os.utime(self.final, (stamp, stamp))

    def progress(self, stats: KermitStatistics) -> str:
        text = f"{len(self.stored)} files stored whole"
        if self.active:
            text += f"; {self.written} bytes of the file in progress kept in {self.part}"
        return text

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
            self.file = None


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
