"""What a close reports (issue 17, finding 5): ``close_error`` is None exactly when
every byte we were given was acknowledged and the peer's EOF arrived.

The netcat's exit status is that; so a close must never report success while
data is missing (the side that "exited 0 with nothing on stderr"), and never
report failure when all data is in and only the closing handshake's last ACK
went missing.  Virtual time, seeded in-memory lines.
"""

from __future__ import annotations

import random
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import pytest
import trio
import trio.testing

from linksim.link import (
    DirectionConfig,
    ImpairedLink,
    LinkConfig,
    endpoint_config_for,
    open_impaired_link,
    serial_socket_pair,
)
from serialsocket import EndpointConfig, SerialSocket, State, accept, connect, listen

from .borrowed import Borrowed


def _run(fn):  # type: ignore[no-untyped-def]
    return trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


async def _read_all(sock: SerialSocket) -> bytes:
    got = bytearray()
    while chunk := await sock.receive_some():
        got += chunk
    return bytes(got)


@asynccontextmanager
async def connected_pair(
    port_a: trio.abc.Stream, port_b: trio.abc.Stream, cfg: EndpointConfig
) -> AsyncIterator[tuple[SerialSocket, SerialSocket]]:
    """``(client, server)`` over two ports; closed (in parallel) on exit."""
    async with trio.open_nursery() as nursery:
        accepted: list[SerialSocket] = []

        async def do_accept() -> None:
            accepted.append(await accept(port_b, cfg, nursery=nursery))

        async with trio.open_nursery() as handshake:
            handshake.start_soon(do_accept)
            client = await connect(port_a, cfg, nursery=nursery)
        try:
            yield client, accepted[0]
        finally:
            async with trio.open_nursery() as closing:
                closing.start_soon(client.aclose)
                closing.start_soon(accepted[0].aclose)


class Cuttable(trio.abc.Stream):
    """A port whose outgoing line can be cut: afterwards what we write is lost.

    The far end hears nothing more (no EOF either), as when a peer's process
    ends on a relay: a lost last ACK, deterministically.
    """

    def __init__(self, inner: trio.abc.Stream) -> None:
        self.inner = inner
        self.cut = False

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        if self.cut:
            await trio.lowlevel.checkpoint()
            return
        await self.inner.send_all(data)

    async def wait_send_all_might_not_block(self) -> None:
        await self.inner.wait_send_all_might_not_block()

    async def receive_some(self, max_bytes: int | None = None) -> bytes:
        return await self.inner.receive_some(max_bytes)

    async def aclose(self) -> None:
        await self.inner.aclose()


LINE = LinkConfig.symmetric(DirectionConfig(rate=9600, delay=0.1), seed=2)
CFG = endpoint_config_for(LINE, dead_after=6.0, send_buffer=8192)


def test_all_data_in_but_the_last_ack_lost_is_a_clean_close() -> None:
    """The server's bytes are all acknowledged and the client's EOF is in; then
    the client's line goes silent, so the ACK of the server's EOF never comes.
    Nothing is missing: the close is given up after a dead-link interval of
    silence, but reports no error (it reported one before)."""
    data = random.Random(1).randbytes(3000)
    outcome: dict[str, object] = {}

    async def main() -> None:
        async with open_impaired_link(LINE) as (port_a, port_b):
            cut = Cuttable(port_a)
            async with connected_pair(cut, port_b, CFG) as (client, server):
                await client.send_eof()
                await server.send_all(data)
                got = b""
                while len(got) < len(data):
                    got += await client.receive_some()
                assert got == data
                assert await _read_all(server) == b""
                while not server.endpoint.all_acknowledged:
                    await trio.sleep(0.01)
                cut.cut = True
                await server.aclose()  # its EOF arrives; the ACK of it is lost
                outcome["state"] = server.endpoint.state
                outcome["error"] = server.close_error

    _run(main)
    assert outcome["state"] is State.DEAD  # the close itself was given up (silence)...
    assert outcome["error"] is None  # ...with every byte delivered both ways


def test_a_line_cut_with_data_in_flight_is_reported_with_the_counts() -> None:
    data = random.Random(2).randbytes(3000)
    outcome: dict[str, object] = {}

    async def main() -> None:
        async with open_impaired_link(LINE) as (port_a, port_b):
            cut = Cuttable(port_a)
            async with connected_pair(cut, port_b, CFG) as (client, server):
                await client.send_eof()
                assert await _read_all(server) == b""
                cut.cut = True  # from now on nothing is acknowledged
                await server.send_all(data)
                await server.aclose()
                outcome["error"] = server.close_error
                outcome["stats"] = server.statistics().link

    _run(main)
    error = outcome["error"]
    assert isinstance(error, str)
    assert error.startswith("the connection did not close cleanly: ")
    # Silence, so the verdict is a dead link (not "no progress"), with its report.
    assert "link dead after 6.0 s of silence" in error
    st = outcome["stats"]
    assert st.bytes_acknowledged == 0  # type: ignore[attr-defined]
    assert st.bytes_in_flight + st.bytes_queued == len(data)  # type: ignore[attr-defined]
    assert f"sent: 0 bytes acknowledged, {st.bytes_in_flight} in flight" in error  # type: ignore[attr-defined]


def test_a_close_that_ends_in_our_own_abort_is_reported() -> None:
    """The peer keeps sending after we close: we refuse its data with an E
    packet (TCP's RST).  Its data never arrived, so this is no clean close
    (it used to leave close_error None: nobody had *told* us anything)."""
    outcome: dict[str, object] = {}

    async def main() -> None:
        async with serial_socket_pair(LINE, endpoint=CFG) as (client, server):

            async def keep_sending() -> None:
                try:
                    while True:
                        await client.send_all(b"telemetry " * 20)
                except trio.BrokenResourceError as exc:
                    outcome["client"] = str(exc)

            async with trio.open_nursery() as nursery:
                nursery.start_soon(keep_sending)
                await server.aclose()
            outcome["error"] = server.close_error

    _run(main)
    error = outcome["error"]
    assert isinstance(error, str)
    assert error.startswith(
        "the connection did not close cleanly: "
        "this side aborted the connection: Connection closed: data refused; sent: 0 bytes"
    )
    assert "its EOF not received" in error
    assert outcome["client"] == "the peer aborted the connection: Connection closed: data refused"


def test_a_link_broken_before_the_close_is_reported_by_the_close_too() -> None:
    outcome: dict[str, object] = {}

    async def main() -> None:
        async with serial_socket_pair(LINE, endpoint=CFG) as (client, server):
            await client.send_all(b"x" * 500)
            with trio.CancelScope() as scope:
                scope.cancel()
                await client.aclose()  # cancelled: the connection is aborted
            with pytest.raises(trio.BrokenResourceError):
                await _read_all(server)
            await server.aclose()
            outcome["error"] = server.close_error

    _run(main)
    error = outcome["error"]
    assert isinstance(error, str)
    # What the server notices first -- the client's E packet, the line closing
    # behind it, or a write to the closed line failing -- depends on the task
    # order; whichever it is, the close reports a failure with the counts.
    assert error.startswith("the connection did not close cleanly: ")
    assert "sent: 0 bytes acknowledged" in error


def test_closing_an_old_session_leaves_the_next_connection_alone() -> None:
    """A listener's session whose connection ended (both EOFs exchanged) and
    was replaced by a new one: closing the old session object must not close
    the new connection (it did: aclose looked at the endpoint's current state),
    and it reports how its own connection ended (cleanly)."""
    cfg = EndpointConfig(one_way_delay=0.05)
    outcome: dict[str, object] = {}

    async def main() -> None:
        line = ImpairedLink(LinkConfig.symmetric(DirectionConfig(delay=0.05)))
        async with trio.open_nursery() as nursery, listen(line.b, cfg) as listener:
            sessions: list[SerialSocket] = []

            async def do_accept() -> None:
                sessions.append(await listener.accept())

            async with trio.open_nursery() as handshake:
                handshake.start_soon(do_accept)
                first = await connect(Borrowed(line.a), cfg, nursery=nursery)
            old = sessions[0]
            await first.send_all(b"one")
            await first.send_eof()
            await old.send_eof()
            assert await _read_all(old) == b"one"
            assert await _read_all(first) == b""
            await first.aclose()  # the old session is left open on purpose

            async with trio.open_nursery() as handshake:
                handshake.start_soon(do_accept)
                second = await connect(Borrowed(line.a), cfg, nursery=nursery)
            new = sessions[1]
            await old.aclose()  # must not touch `new`
            outcome["old_error"] = old.close_error
            await new.send_all(b"two")
            await new.send_eof()
            await second.send_eof()
            assert await _read_all(second) == b"two"
            assert await _read_all(new) == b""
            async with trio.open_nursery() as closing:
                closing.start_soon(new.aclose)
                closing.start_soon(second.aclose)
            outcome["errors"] = (first.close_error, new.close_error, second.close_error)
            nursery.cancel_scope.cancel()

    _run(main)
    assert outcome["old_error"] is None
    assert outcome["errors"] == (None, None, None)
