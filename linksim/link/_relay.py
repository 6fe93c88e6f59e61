"""The pty relay: an impaired line between two real ttys (``linksim relay``).

By default the relay creates two pty pairs, sets both to raw mode and hands out
the slave paths; the user's programs open those (``minicom -p /dev/pts/5``,
``kermit -l /dev/pts/6``, or our own CLI).  A device may also be a TCP serial
server, ``socket://HOST:PORT`` (ser2net style): the relay connects to it and
treats the connection as that side's port; the server closing it ends the run.
Bytes written on one side pass through the :class:`~linksim.LinkDirection` of
that direction and come out on the other side at their modelled arrival time.
With ``devices`` it attaches to existing ttys instead.  With a
:class:`~linksim.ModemPair`, each side talks to an emulated Hayes modem first.

Flow control is by back-pressure, never by loss: a side is not read while its
direction's UART backlog holds ``tx_buffer`` bytes (so a writer is paced by the
line rate, as on a real port) or while ``out_buffer`` bytes wait to be written
to the far tty.  A program closing its end of a pty is normal (the master then
reads EIO until someone opens the slave again): the relay keeps running and
polls every ``_HUP_POLL`` seconds.

With a :class:`serialsocket.capture.CaptureFile`, each side's tty is one
interface of the capture: what its program wrote is recorded outbound when the
relay reads it, what the line delivers to it inbound at its modelled arrival
time (so the capture shows the impairments).
"""

from __future__ import annotations

import contextlib
import errno
import math
import os
import select
import socket
import time
import tty
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import trio

from serialsocket.capture import CaptureFile, Direction

from ._config import LinkConfig
from ._impair import DirectionStatistics, LinkDirection
from ._modem import ModemPair

__all__ = ["RelayStatistics", "run_relay"]

# How often to retry a tty whose other end is closed (EIO / POLLHUP): short
# enough that a program reopening the pty loses nothing it sends, long enough
# to cost nothing while nobody is attached.
_HUP_POLL = 0.02
# One read: the pty layer hands out at most 4095 bytes per read anyway.
_READ_SIZE = 65536
# Bytes waiting to be written to a tty before the other side stops being read.
DEFAULT_OUT_BUFFER = 1 << 20
DEFAULT_TX_BUFFER = 4096


@dataclass(frozen=True, slots=True)
class RelayStatistics:
    """Counters of a relay run: both directions, and the link time elapsed."""

    elapsed: float
    a_to_b: DirectionStatistics
    b_to_a: DirectionStatistics


class _StreamEnded(Exception):
    """A TCP serial server closed its connection (the relay ends once the line is empty)."""


class _Port:
    """One side's tty: the fd we read and write, and the path users open."""

    def __init__(self, fd: int, path: str, *, stream: bool = False) -> None:
        self.fd = fd
        self.path = path
        self.stream = stream
        """A TCP connection, not a tty: its end (EOF, reset) is final."""
        self.out = bytearray()  # waiting to be written to this tty
        self.out_ready = trio.Event()
        self.drained = trio.Event()

    def hung_up(self) -> bool:
        """True when nobody holds the other end (POLLHUP on a pty master)."""
        p = select.poll()
        p.register(self.fd, select.POLLOUT)
        return any(ev & select.POLLHUP for _, ev in p.poll(0))

    async def read(self) -> bytes:
        """Some bytes from the tty (waits through EIO while the other end is closed)."""
        while True:
            try:
                data = os.read(self.fd, _READ_SIZE)
            except BlockingIOError:
                await trio.lowlevel.wait_readable(self.fd)
                continue
            except OSError as exc:
                if exc.errno != errno.EIO:
                    raise
                await trio.sleep(_HUP_POLL)  # slave closed: POLLHUP would spin
                continue
            if data:
                # Drain what else is there without a scheduler round trip.
                chunks = [data]
                total = len(data)
                while total < _READ_SIZE:
                    try:
                        more = os.read(self.fd, _READ_SIZE - total)
                    except OSError:
                        break
                    if not more:
                        break
                    chunks.append(more)
                    total += len(more)
                return b"".join(chunks)
            if self.stream:
                raise _StreamEnded(f"{self.path}: the server closed the connection")
            await trio.sleep(_HUP_POLL)  # EOF on a device: nothing to read yet

    async def write_all(self) -> None:
        """Write everything in :attr:`out` (waits while the tty is full or unattached)."""
        while self.out:
            try:
                n = os.write(self.fd, self.out)
            except BlockingIOError:
                if self.hung_up():
                    await trio.sleep(_HUP_POLL)
                else:
                    await trio.lowlevel.wait_writable(self.fd)
                continue
            except OSError as exc:
                if exc.errno != errno.EIO:
                    raise
                await trio.sleep(_HUP_POLL)
                continue
            del self.out[:n]
            self.drained.set()


def _socket_address(url: str) -> tuple[str, int]:
    """``socket://HOST:PORT`` as an address; ValueError saying what is wrong."""
    host, sep, port = url.removeprefix("socket://").partition("?")[0].rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"{url}: a TCP serial server is socket://HOST:PORT")
    return host.strip("[]"), int(port)


def _check_devices(devices: Sequence[str]) -> None:
    """Refuse device lists the relay cannot carry, before opening anything."""
    if len(devices) != 2:
        raise ValueError(f"give exactly two devices (--device A --device B), not {len(devices)}")
    for path in devices:
        if "://" in path and not path.startswith("socket://"):
            raise ValueError(
                f"{path}: the relay attaches to ttys by path, or to a TCP serial server "
                "as socket://HOST:PORT (other pyserial URLs are for the serialsocket and "
                "arm-server ports)"
            )
        if path.startswith("socket://"):
            _socket_address(path)  # refuse a malformed one before opening anything
    if os.path.realpath(devices[0]) == os.path.realpath(devices[1]):
        raise ValueError(f"both devices are {devices[0]}: give two different ttys")


def _open_ports(devices: Sequence[str] | None) -> tuple[list[_Port], list[int]]:
    """Open the two sides; returns the ports and every fd to close at the end."""
    ports: list[_Port] = []
    fds: list[int] = []
    try:
        if devices:
            _check_devices(devices)
            for path in devices:
                if path.startswith("socket://"):
                    # A TCP serial server (ser2net style): the socket is the port.
                    sock = socket.create_connection(_socket_address(path), timeout=10)
                    sock.setblocking(False)
                    fd = sock.detach()
                    fds.append(fd)
                    ports.append(_Port(fd, path, stream=True))
                    continue
                fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
                fds.append(fd)
                if not os.isatty(fd):
                    # A file or /dev/null reads as an endless EOF: the relay
                    # would spin and carry nothing.
                    raise ValueError(f"{path} is not a terminal: the relay attaches to ttys")
                tty.setraw(fd)
                ports.append(_Port(fd, path))
        else:
            for _ in range(2):
                master, slave = os.openpty()
                fds.append(master)
                try:
                    tty.setraw(slave)  # the setting lives with the pty, not this fd
                    path = os.ttyname(slave)
                finally:
                    os.close(slave)
                os.set_blocking(master, False)
                ports.append(_Port(master, path))
    except BaseException:
        for fd in fds:
            os.close(fd)
        raise
    return ports, fds


class _Relay:
    def __init__(
        self,
        config: LinkConfig,
        ports: list[_Port],
        modems: ModemPair | None,
        tx_buffer: int,
        out_buffer: int,
        capture: CaptureFile | None = None,
    ) -> None:
        self.engines = (
            LinkDirection(config.a_to_b, seed=config.seed, direction=0),
            LinkDirection(config.b_to_a, seed=config.seed, direction=1),
        )
        self.ports = ports
        self.modems = modems
        self.tx_buffer = tx_buffer
        self.out_buffer = out_buffer
        self.origin = trio.current_time()
        self.wake = trio.Event()
        self.signal = [True, True]  # line signal into side 0 / side 1
        self.capture = capture
        self.wall_origin = time.time()  # link time 0 as a capture timestamp
        if capture is not None:
            for name, port in zip("ab", ports, strict=True):
                capture.add_interface(port.path, description=f"linksim relay side {name}")

    def now(self) -> float:
        return trio.current_time() - self.origin

    def _record(self, side: int, data: bytes, direction: Direction, now: float) -> None:
        if self.capture is not None:
            self.capture.record(side, data, direction, self.wall_origin + now)

    def _emit(self, side: int, data: bytes, now: float) -> None:
        if data:
            self._record(side, data, Direction.INBOUND, now)
            port = self.ports[side]
            port.out += data
            port.out_ready.set()

    def _flush_modems(self, now: float) -> None:
        """Move modem output to the ttys and onto the line."""
        m = self.modems
        if m is None:
            return
        for side in (0, 1):
            line = m.data_to_line(side)
            if line:
                self.engines[side].send(line, now)
            self._emit(side, m.data_to_dte(side), now)

    def deliver(self, now: float) -> None:
        """Hand everything that has arrived by ``now`` to the far side."""
        m = self.modems
        if m is not None:
            for side in (0, 1):
                # The signal into `side` comes over the other side's direction.
                present = not self.engines[1 - side].in_outage(now)
                if present != self.signal[side]:
                    self.signal[side] = present
                    m.set_signal(side, present, now)
            m.handle_timer(now)
        for src in (0, 1):
            data = self.engines[src].receive(now)
            if m is None:
                self._emit(1 - src, data, now)
            elif data:
                m.from_line(1 - src, data, now)
        self._flush_modems(now)

    def next_event(self) -> float:
        times = [t for e in self.engines if (t := e.next_delivery()) is not None]
        if self.modems is not None:
            if (t := self.modems.next_timer()) is not None:
                times.append(t)
            now = self.now()
            for e in self.engines:  # outage edges change the modems' carrier
                times += [x for o in e.config.outages for x in (o.start, o.end) if x > now]
        return min(times, default=math.inf)

    async def reader(self, side: int) -> None:
        engine, far = self.engines[side], self.ports[1 - side]
        port = self.ports[side]
        while True:
            # Back-pressure: the UART backlog, and what the far tty has not taken.
            while engine.queued(self.now()) >= self.tx_buffer:
                await trio.sleep_until(self.origin + engine.drained_at(self.tx_buffer - 1))
            while len(far.out) >= self.out_buffer or len(port.out) >= self.out_buffer:
                blocked = far if len(far.out) >= self.out_buffer else port
                blocked.drained = trio.Event()
                await blocked.drained.wait()
            try:
                data = await port.read()
            except _StreamEnded as ended:
                # What the server sent before it closed is still on the line:
                # deliver it, then end the run.
                while engine.statistics().bytes_in_flight or far.out:
                    await trio.sleep(_HUP_POLL)
                raise ConnectionError(str(ended)) from None
            now = self.now()
            self._record(side, data, Direction.OUTBOUND, now)
            if self.modems is None:
                engine.send(data, now)
            else:
                self.modems.from_dte(side, data, now)
                self._flush_modems(now)
            self.deliver(now)  # zero-delay bytes go out without a task switch
            self.wake.set()

    async def writer(self, side: int) -> None:
        port = self.ports[side]
        while True:
            await port.out_ready.wait()
            port.out_ready = trio.Event()
            await port.write_all()

    async def clock(self) -> None:
        """Deliver bytes and fire modem timers at their times."""
        while True:
            target = self.next_event()
            with trio.move_on_at(self.origin + target) as scope:
                await self.wake.wait()
            self.wake = trio.Event()
            now = max(self.now(), target) if scope.cancelled_caught else self.now()
            self.deliver(now)

    def statistics(self) -> RelayStatistics:
        return RelayStatistics(
            self.now(), self.engines[0].statistics(), self.engines[1].statistics()
        )


async def run_relay(
    config: LinkConfig,
    *,
    devices: Sequence[str] | None = None,
    modems: ModemPair | None = None,
    duration: float | None = None,
    stop: trio.Event | None = None,
    on_ready: Callable[[str, str], None] | None = None,
    on_stats: Callable[[RelayStatistics], None] | None = None,
    stats_interval: float = 1.0,
    tx_buffer: int = DEFAULT_TX_BUFFER,
    out_buffer: int = DEFAULT_OUT_BUFFER,
    capture: CaptureFile | None = None,
) -> RelayStatistics:
    """Relay between two ttys through ``config``'s impairments.

    Runs until ``duration`` seconds have passed or ``stop`` is set (then it
    returns the final counters), or until cancelled.  ``on_ready(path_a,
    path_b)`` is called once both ttys can be opened; ``on_stats`` every
    ``stats_interval`` seconds.  The fds it opened are closed on the way out.
    ``capture`` records both ttys' traffic (interfaces 0 and 1, named by their
    paths); it stays open: closing it is the caller's.
    """
    ports, fds = _open_ports(devices)
    try:
        relay = _Relay(config, ports, modems, tx_buffer, out_buffer, capture)
        if on_ready is not None:
            on_ready(ports[0].path, ports[1].path)
        with trio.move_on_after(math.inf if duration is None else duration):
            async with trio.open_nursery() as nursery:
                for side in (0, 1):
                    nursery.start_soon(relay.reader, side)
                    nursery.start_soon(relay.writer, side)
                nursery.start_soon(relay.clock)
                if stop is not None:
                    stop_event = stop

                    async def stopper() -> None:
                        await stop_event.wait()
                        nursery.cancel_scope.cancel()

                    nursery.start_soon(stopper)
                if on_stats is not None:
                    report = on_stats

                    async def reporter() -> None:
                        while True:
                            await trio.sleep(stats_interval)
                            report(relay.statistics())

                    nursery.start_soon(reporter)
        return relay.statistics()
    finally:
        for fd in fds:
            with contextlib.suppress(OSError):
                os.close(fd)
