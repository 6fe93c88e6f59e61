"""Entry points: serve an arm over TCP or any stream, connect a controller to one."""

from __future__ import annotations

import dataclasses
import ssl
from typing import Any, NoReturn, Unpack

import trio

from ._client import ArmClient, StreamFactory
from ._commands import Executor
from ._config import ServerConfig
from ._options import ClientConfig, ClientOptions, client_config
from ._server import Server

__all__ = ["DEFAULT_PORT", "connect_stream", "connect_tcp", "serve_stream", "serve_tcp"]

DEFAULT_PORT = 7010
"""A port of our choosing (unassigned by IANA); pass your own."""


async def serve_tcp(
    executor: Executor,
    port: int = DEFAULT_PORT,
    *,
    host: str | None = "127.0.0.1",
    ssl_context: ssl.SSLContext | None = None,
    config: ServerConfig | None = None,
    task_status: trio.TaskStatus[list[trio.abc.Listener[Any]]] = trio.TASK_STATUS_IGNORED,
    **options: Any,
) -> NoReturn:
    """Serve ``executor`` on ``host:port`` until cancelled (TLS with ``ssl_context``).

    ``host`` defaults to loopback: an arm is not put on the network by
    accident.  Pass ``host=None`` for every interface -- and a ``key``.
    ``options`` are :class:`ServerConfig` fields (``key=``, ``rtt_hint=`` ...).
    ``task_status.started`` receives the listeners (port 0 picks a free port).
    """
    cfg = _config(config, options)
    listeners: list[trio.abc.Listener[Any]]
    if ssl_context is not None:
        listeners = list(await trio.open_ssl_over_tcp_listeners(port, ssl_context, host=host))
    else:
        listeners = list(await trio.open_tcp_listeners(port, host=host))
    async with Server(executor, cfg) as server:
        await server.serve_listeners(listeners, task_status=task_status)
    raise AssertionError("serve_listeners returned")  # pragma: no cover


async def serve_stream(
    executor: Executor,
    stream: trio.abc.Stream,
    *,
    config: ServerConfig | None = None,
    **options: Any,
) -> None:
    """Run one session over ``stream`` (a serial socket, a TCP stream...) and return.

    A one-off server: its exactly-once memory ends with the call.  To resume
    sessions across streams, keep one :class:`Server` and call its
    :meth:`Server.serve_stream` for each.
    """
    async with Server(executor, _config(config, options)) as server:
        await server.serve_stream(stream)


def _config(config: ServerConfig | None, options: dict[str, Any]) -> ServerConfig:
    if config is not None and options:
        raise TypeError(f"give either config= or ServerConfig fields, not both: {sorted(options)}")
    return config if config is not None else ServerConfig(**options)


def connect_tcp(
    host: str,
    port: int = DEFAULT_PORT,
    *,
    ssl_context: ssl.SSLContext | None = None,
    server_hostname: str | None = None,
    config: ClientConfig | None = None,
    **options: Unpack[ClientOptions],
) -> ArmClient:
    """``async with connect_tcp(host, port, key=..., identity=...) as arm:``.

    Options: a :class:`ClientConfig` and/or its fields as keywords (these win).
    Reconnects (and resumes, section 9 of PROTOCOL.md) by opening a new TCP
    connection to the same place, ``reconnect_attempts`` times at most.  With
    ``ssl_context`` the stream is TLS (``server_hostname`` defaults to ``host``).
    """

    async def factory() -> trio.abc.Stream:
        tcp = await trio.open_tcp_stream(host, port)
        if ssl_context is None:
            return tcp
        tls = trio.SSLStream(tcp, ssl_context, server_hostname=server_hostname or host)
        try:
            await tls.do_handshake()
        except BaseException:
            await trio.aclose_forcefully(tls)
            raise
        return tls

    return ArmClient(factory, client_config(config, options))


def connect_stream(
    stream: trio.abc.Stream,
    *,
    reconnect: StreamFactory | None = None,
    config: ClientConfig | None = None,
    **options: Unpack[ClientOptions],
) -> ArmClient:
    """``async with connect_stream(serial_socket, key=...) as arm:`` over any trio stream.

    ``reconnect``, when given, opens a replacement stream after a failure
    (for example: dial again and open a new serial socket); without it a
    broken stream ends the client (no reconnection whatever
    ``reconnect_attempts`` says; pending commands end OutcomeUnknown).
    """
    first: list[trio.abc.Stream] = [stream]

    async def factory() -> trio.abc.Stream:
        if first:
            return first.pop()
        if reconnect is None:
            raise OSError("the stream broke and no reconnect factory was given")
        return await reconnect()

    settings = client_config(config, options)
    if reconnect is None:
        settings = dataclasses.replace(settings, reconnect_attempts=0)
    return ArmClient(factory, settings)
