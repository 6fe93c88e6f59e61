"""The teleoperation channel over a trio stream: the thin loops around the sans-I/O ends.

One reader (bytes in, events out) and one writer per end.  The writer hands the
stream a sample (or a reply) only when :meth:`OperatorChannel.poll` says the
line can take it; until then newer samples replace the waiting one.  While a
sample is held back the writer looks again every ``poll_interval`` (the
transport's figures change without telling us).

When the stream has a latest-value lane (:func:`~tcpstream._pump.latest_lane`:
a serial socket between telelink ends, or the sample channel of a mux over
one) samples and replies go there (PROTOCOL.md 14.8) and a third task reads
it; a value still waiting for the line counts as backlog.
"""

from __future__ import annotations

import abc
import contextlib
import logging
import math
import secrets
from collections.abc import AsyncIterator, Callable

import trio

from ._pump import LatestStream, latest_lane
from ._teleop_connection import ArmChannel, OperatorChannel
from ._teleop_packet import Reply, Sample
from ._teleop_state import (
    Backlog,
    ChannelClosed,
    ChannelState,
    ChannelStatistics,
    Granted,
    OperatorArrived,
    RefuseCode,
    Refused,
    ReplyReceived,
    SampleArrived,
    StopArrived,
    TeleopEvent,
)

__all__ = ["TeleopArm", "TeleopOperator", "TeleopRefused", "open_teleop"]

log = logging.getLogger(__name__)

_READ = 4096
"""Bytes per receive: 37 samples; the parser's buffer never holds more than this plus one packet."""

BacklogProbe = Callable[[], Backlog | None]

HANDSHAKE_TIMEOUT = 60.0
"""Seconds from HELLO to GRANT before either end gives up: several round trips of the
Earth-Moon line behind a serial socket's retransmissions (a keyed handshake is two)."""


class TeleopRefused(Exception):
    """The arm refused the channel, or it ended before the grant."""

    def __init__(self, reason: RefuseCode, message: str) -> None:
        super().__init__(message)
        self.reason = reason


class _Pump(abc.ABC):
    def __init__(
        self,
        stream: trio.abc.Stream,
        backlog: BacklogProbe | None,
        poll_interval: float,
    ) -> None:
        self._stream = stream
        self._backlog = backlog
        self._poll_interval = poll_interval
        self._lane: LatestStream | None = latest_lane(stream)
        self._wake = trio.Event()
        self.closed = trio.Event()
        self.writer_done = trio.Event()

    def wake(self) -> None:
        self._wake.set()

    @abc.abstractmethod
    def _events(self, events: list[TeleopEvent]) -> None:
        """Handle what the channel reported."""

    @abc.abstractmethod
    def _channel(self) -> OperatorChannel | ArmChannel:
        """The sans-I/O end this pump drives."""

    @abc.abstractmethod
    def _holding(self) -> bool:
        """Whether output is being held back (the line is busy)."""

    async def _reader(self) -> None:
        ch = self._channel()
        try:
            while ch.state is not ChannelState.CLOSED:
                data = await self._stream.receive_some(_READ)
                if not data:
                    self._events([ChannelClosed(RefuseCode.NORMAL, by_peer=True)])
                    break
                self._events(ch.receive_data(bytes(data), trio.current_time()))
                self.wake()
        except (trio.BrokenResourceError, trio.ClosedResourceError) as exc:
            log.debug("teleop reader ended: %r", exc)
        finally:
            self.closed.set()
            self.wake()

    def _to_lane(self, ch: OperatorChannel | ArmChannel) -> bool:
        """Hand the channel's lane message, if any, to the lane.  True when the
        writer must look again at once: the message went, or the lane refused
        it and it now waits in the channel's stream output."""
        message = ch.lane_to_send()
        if message is None or self._lane is None:
            return False
        # A value the transport still holds for the line is replaced by this
        # fresher one: the line carries the newest, and the count says so.
        replacing = self._lane.latest_waiting
        try:
            self._lane.send_latest(message)
        except ValueError as exc:
            # Longer than one packet at the negotiated length: the stream takes
            # it, and every later one (PROTOCOL.md 14.8).
            log.info("teleop: the latest-value lane refused a packet (%s); using the stream", exc)
            self._lane = None
            ch.lane_refused(message)
            return True  # it waits in the stream output: send it now, not at a later wake
        if replacing:
            ch.lane_replaced()
        return True

    async def _lane_reader(self) -> None:
        lane = self._lane
        assert lane is not None
        ch = self._channel()
        try:
            while ch.state is not ChannelState.CLOSED:
                message = await lane.receive_latest()
                self._events(ch.receive_lane(message, trio.current_time()))
                self.wake()
        except (trio.BrokenResourceError, trio.ClosedResourceError) as exc:
            log.debug("teleop lane reader ended: %r", exc)

    def start(self, nursery: trio.Nursery) -> None:
        """Start the reader (and the lane's) in ``nursery``; the writer is the caller's."""
        nursery.start_soon(self._reader)
        if self._lane is not None:
            self._channel().use_lane()
            nursery.start_soon(self._lane_reader)

    async def _writer(self) -> None:
        ch = self._channel()
        try:
            while True:
                self._wake = trio.Event()
                data = ch.data_to_send()
                if not data:
                    backlog = self._backlog() if self._backlog is not None else None
                    if ch.poll(trio.current_time(), backlog):
                        data = ch.data_to_send()
                if self._to_lane(ch) and not data:
                    await trio.lowlevel.checkpoint()
                    continue
                if data:
                    await self._stream.send_all(data)
                    continue
                if ch.state is ChannelState.CLOSED or self.closed.is_set():
                    return
                wait = self._poll_interval if self._holding() else math.inf
                with trio.move_on_after(wait):
                    await self._wake.wait()
        except (trio.BrokenResourceError, trio.ClosedResourceError) as exc:
            log.debug("teleop writer ended: %r", exc)
            self.closed.set()
        finally:
            self.writer_done.set()


class TeleopOperator(_Pump):
    """The operator's end of a granted channel (from :func:`open_teleop`)."""

    def __init__(
        self,
        stream: trio.abc.Stream,
        channel: OperatorChannel,
        backlog: BacklogProbe | None,
        poll_interval: float,
        on_reply: Callable[[Reply, float], None] | None,
    ) -> None:
        super().__init__(stream, backlog, poll_interval)
        self.channel = channel
        self._on_reply = on_reply
        self.granted: Granted | None = None
        self.refused: RefuseCode | None = None
        self._decided = trio.Event()

    def _channel(self) -> OperatorChannel:
        return self.channel

    def _holding(self) -> bool:
        return self.channel.pending is not None or self.channel.repeating_stop

    def _events(self, events: list[TeleopEvent]) -> None:
        for ev in events:
            if isinstance(ev, Granted):
                self.granted = ev
                self._decided.set()
            elif isinstance(ev, Refused):
                self.refused = ev.reason
                self._decided.set()
            elif isinstance(ev, ReplyReceived) and self._on_reply is not None:
                self._on_reply(ev.reply, ev.now)
            elif isinstance(ev, ChannelClosed):
                self.refused = self.refused if self.granted else ev.reason
                self._decided.set()

    def submit(self, sample: Sample) -> None:
        """Offer the newest sample (never blocks; an older unsent one is dropped)."""
        if self.channel.state is ChannelState.OPEN:
            self.channel.offer(sample)
            self.wake()

    def emergency_stop(self) -> None:
        """Send STOP ahead of every sample not yet on the line."""
        self.channel.emergency_stop()
        self.wake()

    @property
    def last_reply(self) -> Reply | None:
        return self.channel.last_reply

    def statistics(self) -> ChannelStatistics:
        return self.channel.statistics()


@contextlib.asynccontextmanager
async def open_teleop(
    stream: trio.abc.Stream,
    *,
    identity: str,
    key: bytes | None = None,
    backlog: BacklogProbe | None = None,
    on_reply: Callable[[Reply, float], None] | None = None,
    poll_interval: float = 0.002,
    nonce_source: Callable[[int], bytes] = secrets.token_bytes,
    handshake_timeout: float = HANDSHAKE_TIMEOUT,
) -> AsyncIterator[TeleopOperator]:
    """Open the teleoperation channel on ``stream`` and yield the granted operator end.

    ``backlog`` returns the transport's own figures (for a
    :class:`serialsocket.SerialSocket`: ``Backlog(st.link.bytes_queued,
    st.link.line_backlog)``); without it the channel paces itself by the
    replies.  Raises :class:`TeleopRefused` when the arm refuses.  On exit
    the channel says BYE and the stream is left open for its owner.
    """
    ch = OperatorChannel(identity, key, nonce_source(16))
    op = TeleopOperator(stream, ch, backlog, poll_interval, on_reply)
    # The loops live in a nursery entered by hand (as ArmClient's), so that an
    # exception from the caller's block reaches the caller as itself, not
    # wrapped in an exception group; the loops catch their own stream errors.
    nursery_cm = trio.open_nursery()
    nursery = await nursery_cm.__aenter__()
    try:
        op.start(nursery)
        nursery.start_soon(op._writer)
        ch.connect()
        op.wake()
        with trio.move_on_after(handshake_timeout):
            await op._decided.wait()
        if not op._decided.is_set():
            raise TeleopRefused(
                RefuseCode.NORMAL, f"no answer from the arm within {handshake_timeout:g} s"
            )
        if op.granted is None:
            reason = op.refused if op.refused is not None else RefuseCode.NORMAL
            raise TeleopRefused(reason, f"the arm refused the teleoperation channel: {reason.name}")
        yield op
    finally:
        if ch.state is not ChannelState.CLOSED:
            ch.close()
            op.wake()
            with trio.move_on_after(1.0) as scope:
                scope.shield = True
                await op.writer_done.wait()  # the writer flushes the BYE, then ends
        nursery.cancel_scope.cancel()
        await nursery_cm.__aexit__(None, None, None)


class TeleopArm:
    """The arm's side: serves one operator at a time and keeps the newest sample.

    The arm's control loop calls :meth:`latest` every tick and :meth:`reply`
    with what it did; ``on_stop`` runs at once when a STOP arrives (halt the
    arm there); ``on_sample``, if given, sees every sample as it arrives (an
    arm that servos on arrival rather than on its own tick).  A second
    operator while one is connected is refused BUSY.
    """

    def __init__(
        self,
        *,
        key: bytes | None = None,
        rate_deadman: float,
        control_rate: float,
        on_stop: Callable[[], None] | None = None,
        on_sample: Callable[[Sample, float], None] | None = None,
        nonce_source: Callable[[int], bytes] = secrets.token_bytes,
        poll_interval: float = 0.002,
        handshake_timeout: float = HANDSHAKE_TIMEOUT,
    ) -> None:
        self.handshake_timeout = handshake_timeout
        self._key = key
        self._on_sample = on_sample
        self.rate_deadman = rate_deadman
        self.control_rate = control_rate
        self._on_stop = on_stop
        self._nonce_source = nonce_source
        self._poll_interval = poll_interval
        self._current: _ArmPump | None = None
        self._retired: list[ChannelStatistics] = []
        self.stops = 0
        self.refused = 0

    @property
    def connected(self) -> bool:
        return self._current is not None and self._current.channel.state is ChannelState.OPEN

    def latest(self) -> tuple[Sample, float] | None:
        """The newest sample not yet taken, with its arrival time; None if none."""
        return None if self._current is None else self._current.channel.take_latest()

    def last_heard(self) -> float | None:
        return None if self._current is None else self._current.channel.last_heard

    def reply(self, reply: Reply) -> None:
        if self._current is not None and self._current.channel.state is ChannelState.OPEN:
            self._current.channel.reply(reply)
            self._current.wake()

    def statistics(self) -> ChannelStatistics | None:
        if self._current is not None:
            return self._current.channel.statistics()
        return self._retired[-1] if self._retired else None

    def _sample(self, sample: Sample, now: float) -> None:
        if self._on_sample is not None:
            self._on_sample(sample, now)

    def _stopped(self) -> None:
        self.stops += 1
        if self._on_stop is not None:
            self._on_stop()

    async def serve_stream(
        self, stream: trio.abc.Stream, *, backlog: BacklogProbe | None = None
    ) -> None:
        """Run the channel on ``stream`` until it closes (the stream is left to its owner)."""
        ch = ArmChannel(
            self._key,
            self._nonce_source(16),
            rate_deadman=self.rate_deadman,
            control_rate=self.control_rate,
        )
        pump = _ArmPump(stream, ch, backlog, self._poll_interval, self)
        async with trio.open_nursery() as nursery:
            pump.start(nursery)
            nursery.start_soon(self._handshake_deadline, ch, pump)
            # The writer returns once the channel is over and its REFUSE or BYE is out.
            await pump._writer()
            nursery.cancel_scope.cancel()
        if self._current is pump:
            self._retired.append(ch.statistics())
            self._current = None

    async def _handshake_deadline(self, ch: ArmChannel, pump: _ArmPump) -> None:
        """A peer that is not granted within the handshake timeout is let go: no
        half-open connection holds a task for ever."""
        await trio.sleep(self.handshake_timeout)
        if ch.state is not ChannelState.OPEN and ch.state is not ChannelState.CLOSED:
            ch.close(RefuseCode.NORMAL)
            self.refused += 1
            pump.closed.set()
            pump.wake()


class _ArmPump(_Pump):
    def __init__(
        self,
        stream: trio.abc.Stream,
        channel: ArmChannel,
        backlog: BacklogProbe | None,
        poll_interval: float,
        owner: TeleopArm,
    ) -> None:
        super().__init__(stream, backlog, poll_interval)
        self.channel = channel
        self._owner = owner

    def _channel(self) -> ArmChannel:
        return self.channel

    def _holding(self) -> bool:
        return self.channel.pending_reply is not None

    def _events(self, events: list[TeleopEvent]) -> None:
        for ev in events:
            if isinstance(ev, OperatorArrived):
                if self._owner.connected:
                    self.channel.refuse(RefuseCode.BUSY)
                    self._owner.refused += 1
                else:
                    self.channel.grant()
                    self._owner._current = self
            elif isinstance(ev, StopArrived):
                self._owner._stopped()
            elif isinstance(ev, Refused):
                self._owner.refused += 1
            elif isinstance(ev, SampleArrived):
                self._owner._sample(ev.sample, ev.now)
        self.wake()
