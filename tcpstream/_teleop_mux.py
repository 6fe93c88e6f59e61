"""Two streams over one, commands first: the command session and the sample channel on one line.

A serial line is one stream; the command session and the teleoperation
channel each want their own.  :func:`open_mux` splits a reliable stream into
two, :attr:`StreamMux.commands` (channel 0) and :attr:`StreamMux.teleop`
(channel 1), both ends alike.  Framing (PROTOCOL.md 14.7)::

    offset size field
         0    1 channel   0 commands, 1 teleoperation
         1    2 length    payload bytes, 1..1024 (u16); 0 = this channel is closed
         3    n payload

**Priority**: the one writer always sends what the command channel holds
before anything of the teleoperation channel's, one frame at a time, so a
command (an emergency stop) waits at most behind the one frame already being
written.  The teleoperation channel's pacing (``Backlog``) sees the mux's own
queue (:meth:`StreamMux.backlog`) added to the transport's.

Each channel is a :class:`trio.abc.Stream` (it passes trio's
``check_two_way_stream``).  Closing one sends its close frame: the peer's
channel then reads EOF and its writes fail (``BrokenResourceError``), like a
TCP connection's.  The end of the underlying stream ends both.

**The expedited lane** (PROTOCOL.md 14.6, 15): when the underlying stream
has one (a serial socket between telelink ends), the command channel offers
it too -- each message goes on the stream's lane behind one byte naming the
channel -- so the command session's EMERGENCY_STOP overtakes even the frame
being written and whatever the transport holds.

**The latest-value lane** (PROTOCOL.md 14.8): when the underlying stream
has one, the sample channel offers it -- each value behind the channel's
byte -- so a sample (a reply) travels beside the frames and a lost one never
holds a newer one.  The command channel has none: commands are not values
that supersede each other.
"""

from __future__ import annotations

import contextlib
import operator
import struct
from collections.abc import AsyncIterator

import trio

from ._pump import expedited_lane, latest_lane

__all__ = ["COMMANDS", "MAX_FRAME", "TELEOP", "MuxChannel", "StreamMux", "open_mux"]

COMMANDS = 0
TELEOP = 1
MAX_FRAME = 1024
"""Payload bytes per frame: a few packets; a command waits behind at most this much of ours."""
MAX_QUEUED = 65536
"""Bytes one channel may hold unsent before ``send_all`` waits (flow control)."""
MAX_UNREAD = 262144
"""Bytes received and not yet read on one channel before the mux stops reading the line."""
MAX_LANE_UNREAD = 8
"""Lane messages held for the command channel before the mux stops taking them."""
_HEAD = struct.Struct("!BH")


class MuxChannel(trio.abc.Stream):
    """One of the mux's two streams."""

    def __init__(self, mux: StreamMux, number: int) -> None:
        self._mux = mux
        self.number = number
        self._out = bytearray()
        self._in = bytearray()
        self._eof = False  # the peer closed its side (or the line ended)
        self._closed = False  # we closed
        self._broken: BaseException | None = None
        self._sending = False
        self._receiving = False
        self._changed = trio.Event()
        self._lane_in: list[bytes] = []
        self._latest_in: bytes | None = None

    def _notify(self) -> None:
        self._changed.set()
        self._changed = trio.Event()

    @property
    def queued(self) -> int:
        """Bytes handed to ``send_all`` and not yet written to the line."""
        return len(self._out)

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        if self._sending:
            raise trio.BusyResourceError("another task is sending on this channel")
        self._sending = True
        try:
            await trio.lowlevel.checkpoint()
            view = memoryview(data).cast("B")
            while True:
                self._check_send()
                room = MAX_QUEUED - len(self._out)
                if room > 0 and view:
                    take = view[:room]
                    self._out += take
                    view = view[len(take) :]
                    self._mux._wake()
                if not view:
                    return
                await self._changed.wait()
        finally:
            self._sending = False

    def _check_send(self) -> None:
        if self._closed:
            raise trio.ClosedResourceError("this channel was closed")
        if self._broken is not None:
            raise trio.BrokenResourceError("the line failed") from self._broken
        if self._eof:
            raise trio.BrokenResourceError("the peer closed this channel")

    async def wait_send_all_might_not_block(self) -> None:
        if self._sending:
            raise trio.BusyResourceError("another task is sending on this channel")
        self._sending = True
        try:
            await trio.lowlevel.checkpoint()
            while True:
                if self._closed:
                    raise trio.ClosedResourceError("this channel was closed")
                if self._eof or self._broken is not None or len(self._out) < MAX_QUEUED:
                    return
                await self._changed.wait()
        finally:
            self._sending = False

    async def receive_some(self, max_bytes: int | None = None) -> bytes:
        if max_bytes is not None:
            max_bytes = operator.index(max_bytes)  # TypeError for 1.5, as trio's streams
            if max_bytes < 1:
                raise ValueError("max_bytes must be >= 1")
        if self._receiving:
            raise trio.BusyResourceError("another task is receiving on this channel")
        self._receiving = True
        try:
            await trio.lowlevel.checkpoint()
            while True:
                if self._closed:
                    raise trio.ClosedResourceError("this channel was closed")
                if self._in:
                    n = len(self._in) if max_bytes is None else min(max_bytes, len(self._in))
                    out = bytes(self._in[:n])
                    del self._in[:n]
                    self._mux._room()  # the reader may have paused for room
                    return out
                if self._broken is not None:
                    raise trio.BrokenResourceError("the line failed") from self._broken
                if self._eof:
                    return b""
                await self._changed.wait()
        finally:
            self._receiving = False

    @property
    def expedited(self) -> bool:
        """This channel has an expedited lane: the command channel, over a
        stream that has one."""
        return self.number == COMMANDS and self._mux._lane is not None

    async def send_expedited(self, message: bytes | bytearray | memoryview) -> None:
        """Send ``message`` on the stream's lane, ahead of every queued frame."""
        lane = self._mux._lane
        if lane is None or self.number != COMMANDS:
            raise trio.BrokenResourceError("this channel has no expedited lane")
        self._check_send()
        await lane.send_expedited(bytes((self.number,)) + bytes(message))

    async def receive_expedited(self) -> bytes:
        """The next lane message for this channel; waits for one."""
        await trio.lowlevel.checkpoint()
        while True:
            if self._closed:
                raise trio.ClosedResourceError("this channel was closed")
            if self._lane_in:
                message = self._lane_in.pop(0)
                self._mux._room()
                return message
            if self._broken is not None:
                raise trio.BrokenResourceError("the line failed") from self._broken
            if self._eof:
                raise trio.BrokenResourceError("the peer closed this channel")
            await self._changed.wait()

    @property
    def latest(self) -> bool:
        """This channel has a latest-value lane: the sample channel, over a
        stream that has one."""
        return self.number == TELEOP and self._mux._latest is not None

    @property
    def latest_waiting(self) -> bool:
        """A value given to :meth:`send_latest` has not yet reached the line."""
        lane = self._mux._latest
        return lane is not None and lane.latest_waiting

    def send_latest(self, value: bytes | bytearray | memoryview) -> None:
        """Offer ``value`` on the stream's latest-value lane (never waits)."""
        lane = self._mux._latest
        if lane is None or self.number != TELEOP:
            raise trio.BrokenResourceError("this channel has no latest-value lane")
        self._check_send()
        lane.send_latest(bytes((self.number,)) + bytes(value))

    async def receive_latest(self) -> bytes:
        """The newest lane value for this channel not yet received; waits for one."""
        await trio.lowlevel.checkpoint()
        while True:
            if self._closed:
                raise trio.ClosedResourceError("this channel was closed")
            if self._latest_in is not None:
                value, self._latest_in = self._latest_in, None
                return value
            if self._broken is not None:
                raise trio.BrokenResourceError("the line failed") from self._broken
            if self._eof:
                raise trio.BrokenResourceError("the peer closed this channel")
            await self._changed.wait()

    async def aclose(self) -> None:
        if not self._closed:
            self._closed = True  # what is queued still goes, then the close frame
            self._mux._close_channel(self.number)
            self._notify()
        await trio.lowlevel.checkpoint()


class StreamMux:
    """The two channels over ``stream``; run :meth:`run` in a nursery (:func:`open_mux` does)."""

    def __init__(self, stream: trio.abc.Stream) -> None:
        self._stream = stream
        self._lane = expedited_lane(stream)
        self._latest = latest_lane(stream)
        self.commands = MuxChannel(self, COMMANDS)
        self.teleop = MuxChannel(self, TELEOP)
        self._channels = (self.commands, self.teleop)
        self._close_frames: list[int] = []
        self._wake_event = trio.Event()
        self._room_event = trio.Event()
        self.frames_out = [0, 0]
        self.frames_in = [0, 0]
        self.bad_frames = 0

    def _wake(self) -> None:
        self._wake_event.set()

    def _room(self) -> None:
        self._room_event.set()

    def _close_channel(self, number: int) -> None:
        self._close_frames.append(number)
        self._wake()

    def backlog(self, number: int) -> int:
        """Bytes the mux holds for the line: channel ``number``'s and, ahead of it, commands'."""
        if number == COMMANDS:
            return self.commands.queued
        return self.commands.queued + self.teleop.queued

    def _fail(self, exc: BaseException) -> None:
        for ch in self._channels:
            if ch._broken is None:
                ch._broken = exc
            ch._notify()

    async def _writer(self) -> None:
        try:
            while True:
                self._wake_event = trio.Event()
                frame = self._next_frame()
                if frame is None:
                    await self._wake_event.wait()
                    continue
                await self._stream.send_all(frame)
        except (trio.BrokenResourceError, trio.ClosedResourceError) as exc:
            self._fail(exc)

    def _next_frame(self) -> bytes | None:
        for ch in self._channels:  # commands first: that is the priority
            if ch._out:
                payload = bytes(ch._out[:MAX_FRAME])
                del ch._out[:MAX_FRAME]
                self.frames_out[ch.number] += 1
                ch._notify()
                return _HEAD.pack(ch.number, len(payload)) + payload
        if self._close_frames:
            return _HEAD.pack(self._close_frames.pop(0), 0)
        return None

    async def _reader(self) -> None:
        buf = bytearray()
        try:
            while True:
                while len(buf) >= _HEAD.size:
                    number, length = _HEAD.unpack_from(buf)
                    if number > TELEOP:
                        # Not our framing: nothing after it can be trusted.
                        self.bad_frames += 1
                        raise trio.BrokenResourceError(f"mux frame for channel {number}")
                    if len(buf) < _HEAD.size + length:
                        break
                    ch = self._channels[number]
                    payload = buf[_HEAD.size : _HEAD.size + length]
                    del buf[: _HEAD.size + length]
                    self.frames_in[number] += 1
                    if length == 0:
                        ch._eof = True
                    elif not ch._closed:
                        ch._in += payload
                    ch._notify()
                while any(len(ch._in) >= MAX_UNREAD for ch in self._channels):
                    self._room_event = trio.Event()
                    await self._room_event.wait()  # flow control: a reader makes room
                data = await self._stream.receive_some(MAX_FRAME + _HEAD.size)
                if not data:
                    for ch in self._channels:
                        ch._eof = True
                        ch._notify()
                    return
                buf += data
        except (trio.BrokenResourceError, trio.ClosedResourceError) as exc:
            self._fail(exc)

    async def _lane_reader(self) -> None:
        """Route the stream's lane messages to the command channel (the only
        one with a lane); anything else is counted and dropped."""
        lane = self._lane
        assert lane is not None
        try:
            while True:
                while len(self.commands._lane_in) >= MAX_LANE_UNREAD:
                    self._room_event = trio.Event()
                    await self._room_event.wait()  # unread: the transport's lane holds the rest
                message = await lane.receive_expedited()
                if message[:1] != bytes((COMMANDS,)):
                    self.bad_frames += 1
                    continue
                self.commands._lane_in.append(message[1:])
                self.commands._notify()
        except (trio.BrokenResourceError, trio.ClosedResourceError):
            # The connection ended: the stream's reader reports how (and a
            # graceful end must stay an EOF, not turn into a failure here).
            return

    async def _latest_reader(self) -> None:
        """Route the stream's latest values to the sample channel (the only one
        with that lane), newest over unread; anything else is counted and dropped."""
        lane = self._latest
        assert lane is not None
        try:
            while True:
                value = await lane.receive_latest()
                if value[:1] != bytes((TELEOP,)):
                    self.bad_frames += 1
                    continue
                self.teleop._latest_in = value[1:]
                self.teleop._notify()
        except (trio.BrokenResourceError, trio.ClosedResourceError):
            return  # the stream's reader reports how the connection ended

    async def run(self, *, task_status: trio.TaskStatus[None] = trio.TASK_STATUS_IGNORED) -> None:
        async with trio.open_nursery() as nursery:
            nursery.start_soon(self._reader)
            nursery.start_soon(self._writer)
            if self._lane is not None:
                nursery.start_soon(self._lane_reader)
            if self._latest is not None:
                nursery.start_soon(self._latest_reader)
            task_status.started()


@contextlib.asynccontextmanager
async def open_mux(stream: trio.abc.Stream) -> AsyncIterator[StreamMux]:
    """``async with open_mux(stream) as mux:`` -- ``mux.commands`` and ``mux.teleop``.

    Use the same on both ends.  On exit the mux stops (its channels break);
    the underlying stream is left to its owner.
    """
    mux = StreamMux(stream)
    # Entered by hand (as open_teleop's): the caller's exceptions reach it unwrapped.
    nursery_cm = trio.open_nursery()
    nursery = await nursery_cm.__aenter__()
    try:
        await nursery.start(mux.run)
        yield mux
    finally:
        nursery.cancel_scope.cancel()
        await nursery_cm.__aexit__(None, None, None)
