"""Kermit server mode over a trio stream, and the client's GET and REMOTE commands.

:func:`kermit_server` serves one directory tree to a Kermit client (C-Kermit
``kermit -g``, ``remote dir``; G-Kermit ``-g``; ours ``serialsocket kermit
get|remote``) until FINISH or BYE.  Every path a client names is resolved
inside the served tree; anything that would leave it (``..``, an absolute
path, a symbolic link out) is refused with an E packet, and the server stays
up.  :func:`kermit_get` and :func:`kermit_remote` are the client side.
"""

from __future__ import annotations

import datetime
import fnmatch
import logging
import math
import os
import pathlib
import shutil
from collections.abc import Callable
from typing import BinaryIO

import trio

from ._attributes import AttributeReply, FileAttributes
from ._core import FileCompleted, FileStarted, KermitStatistics, OutgoingFile, TransferFailed
from ._io import _DATE_FORMAT, _READ_SIZE, _for_port, _Store, kermit_receive
from ._params import KermitConfig
from ._server import (
    KermitServer,
    Refuse,
    Reply,
    SendFiles,
    ServerAnswer,
    ServerEvent,
    ServerRequest,
    ShowText,
    TransactionEnded,
    TransactionStarted,
)

__all__ = ["REMOTE_COMMANDS", "kermit_get", "kermit_remote", "kermit_server"]

log = logging.getLogger(__name__)

REMOTE_COMMANDS = {"dir": "D", "space": "U", "cd": "C", "delete": "E", "finish": "F", "bye": "L"}
"""Our client's REMOTE commands and their G subcommand letters."""
_MAX_FILES = 1000
"""Files one GET may send (a bound on open handles)."""


class _Served:
    """The served tree: the working directory inside it, and the answers to requests."""

    def __init__(self, root: pathlib.Path) -> None:
        self.root = root.resolve()
        self.cwd = self.root
        self.handles: list[BinaryIO] = []
        """Files opened for the request being answered, not yet its transaction's."""
        self.current: list[BinaryIO] = []
        """Files of the transaction in progress."""
        self.store = _Store(self.cwd)

    def inside(self, name: str) -> pathlib.Path | None:
        """``name`` (relative to the working directory) if it stays inside the tree."""
        path = (self.cwd / name).resolve()
        if path == self.root or self.root in path.parents:
            return path
        return None

    def _where(self, path: pathlib.Path) -> str:
        rel = path.relative_to(self.root).as_posix()
        return "/" if rel == "." else "/" + rel

    def _matches(self, spec: str) -> list[pathlib.Path] | Refuse:
        folder, _, pattern = spec.replace("\\", "/").rpartition("/")
        where = self.inside(folder or ".")
        if where is None:
            return Refuse(f"Access denied: {spec} is outside the served directory")
        if not where.is_dir():
            return Refuse(f"No such directory: {folder}")
        found = sorted(p for p in where.iterdir() if fnmatch.fnmatchcase(p.name, pattern or "*"))
        return [p for p in found if self.inside(str(p)) is not None]

    def __call__(self, request: ServerRequest) -> ServerAnswer:
        try:
            return self._answer(request)
        except OSError as exc:
            return Refuse(f"{request.kind} failed: {exc.strerror or exc}")

    def _answer(self, request: ServerRequest) -> ServerAnswer:
        kind, arg = request.kind, request.argument.strip()
        if kind in ("get", "reget"):
            matches = self._matches(arg)
            if isinstance(matches, Refuse):
                return matches
            files = [p for p in matches if p.is_file()][:_MAX_FILES]
            if not files:
                return Refuse(f"No files match {arg}")
            return SendFiles([self._open(p) for p in files])
        if kind == "dir":
            matches = self._matches(arg or "*")
            if isinstance(matches, Refuse):
                return matches
            lines = [f"Directory {self._where(self.cwd)}"]
            for p in matches:
                st = p.stat()
                when = datetime.datetime.fromtimestamp(st.st_mtime).strftime("%Y-%m-%d %H:%M:%S")
                size = "<DIR>" if p.is_dir() else str(st.st_size)
                lines.append(f"{p.name:<32} {size:>12}  {when}")
            text = "\r\n".join(lines) + "\r\n"
            return ShowText("Directory listing", text.encode("utf-8", "replace"))
        if kind == "cd":
            target = self.inside(arg) if arg and arg != "/" else self.root
            if target is None:
                return Refuse(f"Access denied: {arg} is outside the served directory")
            if not target.is_dir():
                return Refuse(f"No such directory: {arg}")
            self.cwd = target
            return Reply(self._where(target))
        if kind == "delete":
            matches = self._matches(arg)
            if isinstance(matches, Refuse):
                return matches
            files = [p for p in matches if p.is_file()]
            if not arg or not files:
                return Refuse(f"No files match {arg}")
            for p in files:
                p.unlink()
            return Reply(f"{len(files)} file{'s' if len(files) != 1 else ''} deleted")
        if kind == "space":
            return Reply(f"{shutil.disk_usage(self.cwd).free} bytes free")
        if kind in ("finish", "bye"):
            return Reply("")
        return Refuse("Unimplemented server function")

    def _open(self, path: pathlib.Path) -> OutgoingFile:
        f: BinaryIO = path.open("rb")
        self.handles.append(f)
        st = os.fstat(f.fileno())
        date = datetime.datetime.fromtimestamp(st.st_mtime).strftime(_DATE_FORMAT)
        return OutgoingFile(path.name, st.st_size, f, date)

    def decide(self, name: str, attributes: FileAttributes) -> AttributeReply:
        return self.store.decide(name, attributes)

    def begin(self) -> None:
        """A transaction started: the files opened for its request are its own."""
        self.current, self.handles = self.handles, []

    def end(self) -> None:
        """The transaction ended: close its files (not those a request that
        arrived in the same read has opened already -- they belong to the
        next one, whose start is reported after this end)."""
        for f in self.current:
            f.close()
        self.current.clear()
        self.store.close()

    def close(self) -> None:
        for f in (*self.current, *self.handles):
            f.close()
        self.current.clear()
        self.handles.clear()
        self.store.close()


async def kermit_server(
    port: trio.abc.Stream,
    directory: str | os.PathLike[str] = ".",
    config: KermitConfig | None = None,
    *,
    on_event: Callable[[ServerEvent], None] | None = None,
) -> int:
    """Serve ``directory`` on ``port`` until the client says FINISH or BYE.

    Returns:
        The number of transactions carried out (including refused ones).

    Raises:
        NotADirectoryError: ``directory`` is not a directory.
        trio.BrokenResourceError: the port failed.
        EOFError: the port closed before FINISH or BYE.
    """
    config = _for_port(config, port)
    root = pathlib.Path(directory)
    if not root.is_dir():
        raise NotADirectoryError(f"{root} is not a directory: create it or pick another")
    served = _Served(root)
    server = KermitServer(config, trio.current_time(), served, policy=served.decide)

    def handle(event: ServerEvent) -> None:
        (on_event or _log_server_event)(event)
        if isinstance(event, TransactionStarted):
            served.begin()
            if event.request.kind == "send":
                served.store = _Store(served.cwd)
        elif isinstance(event, TransactionEnded):
            # Closing every handle here closed the file of a GET whose request
            # came in the same read as the last ACK of the one before, and its
            # sender then read a closed file ("ValueError: read of closed
            # file", the server crashed; one run in four under load).
            served.end()
        elif server.request.kind == "send" and not isinstance(event, TransferFailed):
            receiver = server.receiver
            if receiver is None:
                return
            try:
                served.store.on_event(event, receiver.attributes)
            except OSError as exc:
                server.abort(f"Cannot store file: {exc.strerror or exc}")

    try:
        while True:
            while (event := server.next_event()) is not None:
                handle(event)
            out = server.data_to_send()
            if out:
                await port.send_all(out)
            if server.finished:
                return server.transactions
            deadline = server.get_timer()
            data: bytes | bytearray = b""
            with trio.move_on_at(math.inf if deadline is None else deadline):
                data = await port.receive_some(_READ_SIZE)
                if not data:
                    raise EOFError("the line was closed before FINISH or BYE")
            now = trio.current_time()
            if data:
                server.receive_data(data, now)
            else:
                server.handle_timer(now)
    finally:
        served.close()


def _log_server_event(event: ServerEvent) -> None:
    if isinstance(event, TransactionStarted):
        req = event.request
        log.info("request: %s %s", req.kind, req.argument)
    elif isinstance(event, TransactionEnded) and event.failure:
        log.info("%s failed: %s", event.request.kind, event.failure)
    elif isinstance(event, FileStarted) and not event.screen:
        log.info("file %s", event.name)
    elif isinstance(event, FileCompleted) and not event.discarded:
        log.info("file %s complete", event.name)


async def kermit_get(
    port: trio.abc.Stream,
    spec: str,
    directory: str | os.PathLike[str] = ".",
    config: KermitConfig | None = None,
    *,
    recover: bool = False,
) -> KermitStatistics:
    """GET: ask a Kermit server for the files ``spec`` names; store them in ``directory``.

    ``recover``: REGET (a J packet): the server sends each file with RESEND,
    and only what ``directory`` does not hold yet crosses the line.

    Raises:
        KermitTransferError: as :func:`kermit_receive` (the server's E text,
            e.g. "No files match", is in the message).
    """
    ptype = "J" if recover else "R"
    return await kermit_receive(port, directory, config, request=(ptype, spec.encode("utf-8")))


async def kermit_remote(
    port: trio.abc.Stream,
    command: str,
    argument: str = "",
    config: KermitConfig | None = None,
) -> str:
    """A REMOTE command (``dir``, ``cd``, ``delete``, ``space``, ``finish``, ``bye``).

    Returns:
        The server's answer: its short reply, or the text it sent for the screen.

    Raises:
        KeyError: an unknown command.
        KermitTransferError: the server refused (its E text is in the message).
    """
    letter = REMOTE_COMMANDS[command]
    raw = argument.encode("utf-8")
    field = letter.encode("ascii") + (bytes([32 + len(raw)]) + raw if raw else b"")
    shown: list[str] = []
    directory = pathlib.Path(".")
    await kermit_receive(port, directory, config, request=("G", field), screen=shown.append)
    return "".join(shown)
