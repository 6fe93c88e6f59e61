"""The lines a teleoperation run goes over: a serial socket on the impaired line (in
memory, or two real ptys joined by the relay), TCP with the line's delay, and the
stream mux when the command session shares the line; with each, the transport's
own figures the sample channel paces by.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import AsyncIterator, Callable
from typing import Any

import trio

from linksim.link import (
    DirectionConfig,
    LinkConfig,
    endpoint_config_for,
    open_impaired_link,
    run_relay,
    serial_socket_pair,
)
from serialsocket import SerialSocket, accept, connect, open_port
from tcpstream.teleop import TELEOP, Backlog, StreamMux, open_mux

__all__ = ["SAMPLE_RATE", "Probe", "SerialFigures", "line_interval", "open_channels"]

SAMPLE_RATE = 104.0
"""Hz: seed 004's closed loop ("approximately 104 Hz")."""


class SerialFigures:
    """The serial socket's own figures, as a :class:`Backlog` for the channel's pacing.

    ``bytes_queued`` is what the socket holds unsent.  Its ``line_backlog`` is
    as of the endpoint's last event and goes stale while the link is idle, so
    the line's queue is followed from the socket's ``port_bytes_out`` instead:
    every byte written to the port takes one character time of the line, and
    the line drains at its rate.  ``slack`` seconds of that queue are
    forgiven (both ends use none: what is handed over then waits behind nothing
    of ours, and at most one sample or reply is ever in the line's queue).
    """

    def __init__(self, sock: SerialSocket, char_time: float, slack: float) -> None:
        self._sock = sock
        self._char_time = char_time
        self._slack = slack
        self._out = 0
        self._line = 0.0
        self._at = trio.current_time()
        self.max_line = 0.0
        """The most line time (s) ever committed ahead of a sample: no queue grows."""
        self.max_queued = 0

    def __call__(self) -> Backlog:
        st = self._sock.statistics()
        now = trio.current_time()
        self._line = max(0.0, self._line - (now - self._at))
        self._line += (st.port_bytes_out - self._out) * self._char_time
        self._out, self._at = st.port_bytes_out, now
        self.max_line = max(self.max_line, self._line)
        self.max_queued = max(self.max_queued, st.link.bytes_queued)
        return Backlog(st.link.bytes_queued, max(0.0, self._line - self._slack))

    def link_figures(self) -> dict[str, Any]:
        """What the console's link line shows: the socket's own figures."""
        s = self._sock.statistics().link
        return {
            "rtt_s": s.smoothed_rtt,
            "retransmissions": s.retransmissions,
            "check_failures": s.check_failures,
            "packets_sent": s.packets_sent,
            "packets_received": s.packets_received,
            "bytes_sent": s.bytes_acknowledged,
            "bytes_received": s.bytes_delivered,
        }


@contextlib.asynccontextmanager
async def _streams(
    transport: str, real: bool, link: LinkConfig, holder: dict[str, SerialFigures]
) -> AsyncIterator[
    tuple[
        trio.abc.Stream, trio.abc.Stream, Callable[[], Backlog] | None, Callable[[], Backlog] | None
    ]
]:
    if transport == "serial":
        pair = _pty_pair(link) if real else serial_socket_pair(link)
        async with pair as (ctl, arm):
            char = link.a_to_b.char_time
            holder["operator"] = SerialFigures(ctl, char, 0.0)
            # No slack at the arm either: a reply let in behind the one on the line (it
            # had a sample's line time of slack) kept every ACK and NAK of the sample
            # stream behind up to two replies, 1.3 s at 2400 bit/s (a lost STOP took
            # 5.45 s to reach the arm with it, 4.84 s without).
            yield ctl, arm, holder["operator"], SerialFigures(arm, char, 0.0)
        return
    d = link.a_to_b
    line = LinkConfig.symmetric(DirectionConfig(delay=d.delay, jitter=d.jitter))
    if real:
        async with _tcp_through(line) as (ctl_end, arm_end):
            yield ctl_end, arm_end, None, None
        return
    async with open_impaired_link(line) as (ctl_end, arm_end):
        yield ctl_end, arm_end, None, None


@contextlib.asynccontextmanager
async def _tcp_through(line: LinkConfig) -> AsyncIterator[tuple[trio.abc.Stream, trio.abc.Stream]]:
    """Real TCP on 127.0.0.1, the operator's end seen through ``line`` (its delay, as
    ``linksim demo --transport tcp`` does): an in-memory delayed line whose far end
    is copied to and from the socket."""
    listeners = await trio.open_tcp_listeners(0, host="127.0.0.1")
    port = listeners[0].socket.getsockname()[1]
    async with (
        listeners[0],
        await trio.open_tcp_stream("127.0.0.1", port) as tcp,
        await listeners[0].accept() as arm_end,
        open_impaired_link(line) as (near, far),
        trio.open_nursery() as nursery,
    ):
        nursery.start_soon(_copy, far, tcp)
        nursery.start_soon(_copy, tcp, far)
        try:
            yield near, arm_end
        finally:
            nursery.cancel_scope.cancel()


async def _copy(source: trio.abc.Stream, sink: trio.abc.Stream) -> None:
    with contextlib.suppress(trio.BrokenResourceError, trio.ClosedResourceError):
        while data := await source.receive_some():
            await sink.send_all(data)
    with contextlib.suppress(trio.BrokenResourceError, trio.ClosedResourceError):
        await sink.aclose()


@contextlib.asynccontextmanager
async def _pty_pair(link: LinkConfig) -> AsyncIterator[tuple[SerialSocket, SerialSocket]]:
    """Two serial sockets on two real ptys joined by ``linksim relay``'s impaired line."""
    rate = link.a_to_b.rate
    baud = int(rate) if rate is not None else 115200
    paths: list[str] = []
    ready = trio.Event()
    stop = trio.Event()

    def on_ready(a: str, b: str) -> None:
        paths.extend([a, b])
        ready.set()

    async with trio.open_nursery() as nursery:
        nursery.start_soon(functools.partial(run_relay, link, stop=stop, on_ready=on_ready))
        await ready.wait()
        port_a = await open_port(paths[0], baud)
        port_b = await open_port(paths[1], baud)
        config = endpoint_config_for(link)
        sockets: dict[str, SerialSocket] = {}
        try:
            async with trio.open_nursery() as handshake:

                async def accept_b() -> None:
                    sockets["b"] = await accept(port_b, config)

                handshake.start_soon(accept_b)
                sockets["a"] = await connect(port_a, config)
            yield sockets["a"], sockets["b"]
        finally:
            with trio.move_on_after(5.0) as scope:
                scope.shield = True
                for sock in sockets.values():
                    await sock.aclose()
                await port_a.aclose()
                await port_b.aclose()
            stop.set()


Probe = Callable[[], Backlog] | None


def _with_mux(mux: StreamMux, inner: Probe) -> Callable[[], Backlog]:
    """The sample channel's backlog through the mux: the mux's bytes ahead of it (commands
    first) plus the transport's own figures."""

    def probe() -> Backlog:
        below = inner() if inner is not None else Backlog(0)
        return Backlog(below.queued_bytes + mux.backlog(TELEOP), below.line_seconds)

    return probe


@contextlib.asynccontextmanager
async def open_channels(
    transport: str,
    real: bool,
    commands: bool,
    link: LinkConfig,
    holder: dict[str, SerialFigures],
) -> AsyncIterator[
    tuple[
        trio.abc.Stream,
        trio.abc.Stream,
        Probe,
        Probe,
        trio.abc.Stream | None,
        trio.abc.Stream | None,
    ]
]:
    """(operator's sample stream, arm's, their probes, operator's command stream, arm's)."""
    async with _streams(transport, real, link, holder) as (ctl, arm, ctl_probe, arm_probe):
        if not commands:
            yield ctl, arm, ctl_probe, arm_probe, None, None
            return
        async with open_mux(ctl) as ctl_mux, open_mux(arm) as arm_mux:
            yield (
                ctl_mux.teleop,
                arm_mux.teleop,
                _with_mux(ctl_mux, ctl_probe),
                _with_mux(arm_mux, arm_probe),
                ctl_mux.commands,
                arm_mux.commands,
            )


def line_interval(link: LinkConfig) -> float:
    """Seconds one sample takes on the line (prefix-encoded), or one sampling interval."""
    d = link.a_to_b
    if d.rate is None:
        return 1.0 / SAMPLE_RATE
    return max(1.0 / SAMPLE_RATE, (56 * 1.6 + 20) * d.bits_per_char / d.rate)
