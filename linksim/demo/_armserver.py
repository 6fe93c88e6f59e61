"""The arm server (``linksim arm-server``): the simulated arm behind a command server.

On a serial line or TCP.

Seed 003 section 9: the manipulator listens; a controlling agent connects
(over TCP, or over a serial socket after dialing its modem); when the session
is over "the manipulator will reset and listen for further connection
requests".  One :class:`tcpstream.Server` lives across sessions, so its
exactly-once memory survives a reconnect.

When it is listening it prints one JSON line on stdout, ``{"ready": true,
"transport": ..., ...}`` (with ``"tcp_port"`` for TCP), so a parent process
knows when to connect.

With a :class:`serialsocket.capture.CaptureFile`, the serial port is one
interface of the capture (the serial socket's Kermit packets, both ways);
over TCP each connection is one (the 216-byte tcpstream packets,
``LINKTYPE_TCPSTREAM``).
"""

from __future__ import annotations

import json
import logging
from typing import Any

import trio

import serialsocket
from serialsocket.capture import LINKTYPE_TCPSTREAM, CaptureFile, CapturingStream
from tcpstream import Server

__all__ = ["serve_arm_serial", "serve_arm_tcp"]

log = logging.getLogger(__name__)


def _ready(**fields: Any) -> None:
    print(json.dumps({"ready": True, **fields}), flush=True)


async def serve_arm_serial(
    server: Server,
    path: str,
    endpoint: serialsocket.EndpointConfig,
    *,
    baud: int = 9600,
    answer: bool = False,
    sessions: int | None = None,
    capture: CaptureFile | None = None,
) -> None:
    """Serve sessions over the serial port at ``path`` (answering a modem call first).

    Returns after ``sessions`` sessions (None: forever, until cancelled).
    Without a modem one listener serves every session; with one, each
    session is a call: answer, serve, hang up, answer the next.
    """
    served = 0
    interface = None if capture is None else capture.add_interface(path, description="arm server")
    while sessions is None or served < sessions:
        port = await serialsocket.open_port(path, baud)
        if answer:
            _ready(transport="serial", port=path, modem=True)
            connection = await serialsocket.answer(port, timeout=None)
            log.info("answered: %s", connection)
        line: trio.abc.Stream = port
        if capture is not None and interface is not None:
            line = CapturingStream(port, capture, interface)
        async with serialsocket.listen(line, endpoint) as listener:
            if not answer:
                _ready(transport="serial", port=path, modem=False)
            while sessions is None or served < sessions:
                sock = await listener.accept()
                try:
                    await server.serve_stream(sock)
                except (trio.BrokenResourceError, trio.ClosedResourceError) as exc:
                    log.info("session ended: %s", exc)
                finally:
                    await sock.aclose()
                served += 1
                if answer:
                    break  # the call is over; the port is closed and reopened for the next


def _capturing(stream: trio.abc.Stream, capture: CaptureFile) -> trio.abc.Stream:
    """``stream`` recorded on a new interface of ``capture`` named after the peer."""
    sock = getattr(stream, "socket", None)
    peer = "tcp"
    if sock is not None:
        address = sock.getpeername()
        peer = f"tcp {address[0]}:{address[1]}"
    interface = capture.add_interface(
        peer, linktype=LINKTYPE_TCPSTREAM, description="arm server connection"
    )
    return CapturingStream(stream, capture, interface)


async def serve_arm_tcp(
    server: Server,
    port: int,
    *,
    host: str = "127.0.0.1",
    sessions: int | None = None,
    capture: CaptureFile | None = None,
) -> None:
    """Serve sessions on ``host:port`` (0 picks a free port, printed in the ready line)."""
    listeners = await trio.open_tcp_listeners(port, host=host)
    bound = listeners[0].socket.getsockname()[1]
    _ready(transport="tcp", host=host, tcp_port=bound)
    served = 0
    try:
        async with trio.open_nursery() as nursery:
            while sessions is None or served < sessions:
                stream: trio.abc.Stream = await listeners[0].accept()
                if capture is not None:
                    stream = _capturing(stream, capture)
                served += 1
                if sessions is not None and served >= sessions:
                    # The last session: serve it here, then stop listening.
                    await server.serve_stream(stream)
                    break
                nursery.start_soon(server.serve_stream, stream)
    finally:
        for listener in listeners:
            await listener.aclose()
