"""A packet trace: a port wrapper that logs every packet in both directions, decoded.

:class:`TracingStream` wraps the port under a serial socket and runs a
private :class:`~serialsocket.packets.PacketParser` over each direction's bytes.
Every packet (and every rejected chunk) becomes one DEBUG record on the
``serialsocket.trace`` logger, e.g.::

    tx D seq=5 len=128 data=b'MOVE 0.3 0.1 0.5\\n...' (118 bytes)
    rx Y seq=5 len=9 field=b'6P'
    rx rejected bad check len=128 seq=6

The trace costs a second parse of the traffic, so it is only wrapped in when
asked for (``--trace``); when off, nothing of it runs.
"""

from __future__ import annotations

import logging

import trio

from ._checks import BlockCheck
from ._encoding import PRINTABLE, Encoding
from ._errors import MalformedDataError, RemoteProtocolError
from ._expedited import URGENT
from ._latest import LATEST
from ._params import DataCodec, InitParameters, Negotiated, negotiate, self_agreement
from ._parser import PacketParser, PacketReceived
from ._port import PortStatistics, port_statistics
from ._wire import MAX_PACKET_LENGTH, PacketType

__all__ = ["TracingStream"]

log = logging.getLogger("serialsocket.trace")

_INIT_ANSWER = 12
"""An ACK with at least this many data characters answers an init (PROTOCOL.md 9)."""

_PREVIEW = 48
"""Decoded bytes shown per data packet: enough to recognise a command line."""


class _Direction:
    def __init__(self, name: str, encoding: DataCodec) -> None:
        self.name = name
        self.encoding = encoding
        self.head = 0
        self.init: InitParameters | None = None
        self.other: _Direction | None = None
        # The largest packet anyone may negotiate: the trace must see them all.
        self.parser = PacketParser(
            max_length=MAX_PACKET_LENGTH,
            check=BlockCheck.CRC16,
            init_check=BlockCheck.CRC16,
            error_fallback=False,  # as the endpoint parses (PROTOCOL.md section 2)
        )

    def _on_init(self, data: bytes) -> None:
        """Follow the init exchange: once both directions carried one, decode
        what comes after with the agreed encoding and check (dense encodings
        and CRC-32 included, PROTOCOL.md section 10)."""
        try:
            self.init = InitParameters.decode(data)
            other = self.other
            if other is None or other.init is None:
                if self.init.flight is not None:
                    # A first flight follows, cut as the request's agreement
                    # with itself says (PROTOCOL.md 14).
                    self._follow(self_agreement(self.init), [self])
                return
            agreed = negotiate(self.init, other.init)
        except RemoteProtocolError:
            return
        self._follow(agreed, [self, other])

    @staticmethod
    def _follow(agreed: Negotiated, directions: list[_Direction]) -> None:
        for d in directions:
            d.encoding = agreed.encoding
            d.parser.check = agreed.check
            d.parser.correction = agreed.correction  # a d shows as the D it carries
            d.head = 2 if agreed.long_seq else 0

    def feed(self, data: bytes | bytearray | memoryview) -> None:
        self.parser.receive_data(bytes(data))
        while (event := self.parser.next_event()) is not None:
            if isinstance(event, PacketReceived):
                pkt = event.packet
                head = f"{self.name} {pkt.type} seq={pkt.seq} len={event.length}"
                if pkt.seq == 0 and (
                    pkt.type == PacketType.INIT
                    or (pkt.type == PacketType.ACK and len(pkt.data) >= _INIT_ANSWER)
                ):
                    self._on_init(pkt.data)
                if pkt.type in (PacketType.DATA, URGENT, LATEST):
                    # An expedited fragment (PROTOCOL.md 11): tochar(more), then data;
                    # a latest value (12): tochar(number >> 6), then data.
                    skip = self.head if pkt.type == PacketType.DATA else 1
                    if pkt.type == URGENT and pkt.data:
                        head += f" expedited more={pkt.data[0] - 32}"
                    if pkt.type == LATEST and pkt.data:
                        head += f" latest value={(pkt.data[0] - 32) << 6 | pkt.seq}"
                    try:
                        payload = self.encoding.decode(pkt.data[skip:])
                    except MalformedDataError as exc:
                        log.debug("%s undecodable field %r: %s", head, pkt.data[:_PREVIEW], exc)
                        continue
                    more = "..." if len(payload) > _PREVIEW else ""
                    log.debug(
                        "%s data=%r%s (%d bytes)", head, payload[:_PREVIEW], more, len(payload)
                    )
                else:
                    log.debug("%s field=%r", head, pkt.data[:_PREVIEW])
            else:
                where = "" if event.seq is None else f" seq={event.seq}"
                log.debug(
                    "%s rejected %s len=%d%s", self.name, event.reason.value, event.length, where
                )


class TracingStream(trio.abc.Stream):
    """A transparent wrapper around ``inner`` that logs the packets passing through.

    Closing it closes ``inner``.  ``encoding`` decodes data fields for display
    until the init exchange has been seen both ways; from then on the agreed
    encoding and block check do (PRINTABLE by default).
    """

    def __init__(self, inner: trio.abc.Stream, encoding: Encoding | None = None) -> None:
        self.inner = inner
        start = encoding or PRINTABLE
        self._tx = _Direction("tx", start)
        self._rx = _Direction("rx", start)
        self._tx.other, self._rx.other = self._rx, self._tx

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        await self.inner.send_all(data)
        if log.isEnabledFor(logging.DEBUG):
            self._tx.feed(data)

    async def wait_send_all_might_not_block(self) -> None:
        await self.inner.wait_send_all_might_not_block()

    async def receive_some(self, max_bytes: int | None = None) -> bytes | bytearray:
        data = await self.inner.receive_some(max_bytes)
        if log.isEnabledFor(logging.DEBUG):
            self._rx.feed(data)
        return data

    async def aclose(self) -> None:
        await self.inner.aclose()

    def statistics(self) -> PortStatistics | None:
        """The inner port's counters when it is a :class:`SerialPort` (else None)."""
        return port_statistics(self.inner)
