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
from ._encoding import Encoding
from ._errors import MalformedDataError
from ._parser import PacketParser, PacketReceived
from ._port import PortStatistics, port_statistics
from ._wire import MAX_PACKET_LENGTH, PacketType

__all__ = ["TracingStream"]

log = logging.getLogger("serialsocket.trace")

_PREVIEW = 48
"""Decoded bytes shown per data packet: enough to recognise a command line."""


class _Direction:
    def __init__(self, name: str, encoding: Encoding) -> None:
        self.name = name
        self.encoding = encoding
        # The largest packet anyone may negotiate: the trace must see them all.
        self.parser = PacketParser(
            max_length=MAX_PACKET_LENGTH, check=BlockCheck.CRC16, init_check=BlockCheck.CRC16
        )

    def feed(self, data: bytes | bytearray | memoryview) -> None:
        self.parser.receive_data(bytes(data))
        while (event := self.parser.next_event()) is not None:
            if isinstance(event, PacketReceived):
                pkt = event.packet
                head = f"{self.name} {pkt.type} seq={pkt.seq} len={event.length}"
                if pkt.type == PacketType.DATA:
                    try:
                        payload = self.encoding.decode(pkt.data)
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
    (the profile the endpoints use; PRINTABLE by default).
    """

    def __init__(self, inner: trio.abc.Stream, encoding: Encoding) -> None:
        self.inner = inner
        self._tx = _Direction("tx", encoding)
        self._rx = _Direction("rx", encoding)

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
