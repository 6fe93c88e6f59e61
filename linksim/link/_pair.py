"""``serial_socket_pair``: two connected serial sockets over the in-memory impaired link.

The endpoints are told the physics of the line they run on (one-way delay and
line rate of the a-to-b direction), so their timers, pacing and window bound
match it, as a user would configure them for a real line.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import trio

from serialsocket import EndpointConfig, SerialSocket, connect, listen

from ._channel import open_impaired_link
from ._config import LinkConfig
from ._tuning import endpoint_config_for

__all__ = ["connected_pair", "serial_socket_pair"]


@asynccontextmanager
async def serial_socket_pair(
    config: LinkConfig | str = "clean",
    *,
    seed: int = 0,
    endpoint: EndpointConfig | None = None,
    read_latency: float | None = None,
) -> AsyncIterator[tuple[SerialSocket, SerialSocket]]:
    """``async with serial_socket_pair("noisy-moon", seed=1) as (client, server):``.

    Args:
        config: a :class:`LinkConfig` or a preset name.
        seed: the impairment seed when ``config`` is a preset name.
        endpoint: endpoint configuration for both sides; default derived from
            the line by :func:`endpoint_config_for`.
        read_latency: see :func:`~linksim.open_impaired_link`.  Default: 16
            character times on a rate-limited line (what a UART's FIFO timeout
            does; one wake-up per byte would make long simulations slow), else 0.

    Yields:
        ``(client, server)``: the client connected, the server accepted.
        Both are closed on exit (gracefully if possible).
    """
    link = LinkConfig.preset(config, seed=seed) if isinstance(config, str) else config
    ep_cfg = endpoint or endpoint_config_for(link)
    if read_latency is None:
        read_latency = 16 * link.a_to_b.char_time
    async with (
        open_impaired_link(link, read_latency=read_latency) as (port_a, port_b),
        connected_pair(port_a, port_b, ep_cfg) as pair,
    ):
        yield pair


@asynccontextmanager
async def connected_pair(
    port_a: trio.abc.Stream, port_b: trio.abc.Stream, config: EndpointConfig
) -> AsyncIterator[tuple[SerialSocket, SerialSocket]]:
    """Two serial sockets over any two connected ports (ptys, the in-memory link...).

    ``port_b`` listens, ``port_a`` connects, both with ``config``.  Yields
    ``(client, server)``; both are closed on exit (gracefully if possible),
    and with them the ports.
    """
    async with trio.open_nursery() as nursery, listen(port_b, config) as listener:
        accepted: list[SerialSocket] = []

        async def accept() -> None:
            accepted.append(await listener.accept())

        async with trio.open_nursery() as handshake:
            handshake.start_soon(accept)
            client = await connect(port_a, config, nursery=nursery)
        server = accepted[0]
        try:
            yield client, server
        finally:
            with trio.CancelScope(shield=True):
                async with trio.open_nursery() as closing:
                    closing.start_soon(client.aclose)
                    closing.start_soon(server.aclose)
