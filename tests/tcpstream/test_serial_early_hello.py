"""The HELLO rides in the serial socket's connection request (virtual time).

Over ``serialsocket.connect(port, defer=True)`` the session's first packet is
the deferred socket's first write, so it goes inside the connection request
(serialsocket/PROTOCOL.md section 13) and the arm reads it one one-way delay
after the start instead of three: the session is granted one round trip
sooner.  tcpstream knows nothing of it: the test joins the two packages
through ``trio.abc.Stream`` only, as test_serial.py does.
"""

from __future__ import annotations

import dataclasses

import pytest
import trio

from linksim import LinkConfig, endpoint_config_for
from linksim.link import ImpairedLink
from serialsocket import EndpointConfig, connect, listen
from tcpstream import Server, ServerConfig, connect_stream
from tcpstream.commands import PACKET_SIZE

from .fakearm import FakeArm
from .harness import KEY, run

MOON = LinkConfig.preset("moon")  # 9600 bit/s, 1.3 s each way, clean
RTT = 2 * MOON.a_to_b.delay
CPS = (MOON.a_to_b.rate or 0) / MOON.a_to_b.bits_per_char
# The HELLO's 216 bytes are about 424 characters in the init's fixed printable
# encoding (182 of them are zero bytes, two characters each).  The init takes
# that much early data only with packets of 850 characters or more (half a
# packet), or on a line whose round trip holds 200 times as many characters:
# the Moon at 9600 bit/s holds 2500, so 1024-character packets here.
CFG = dataclasses.replace(endpoint_config_for(MOON), max_packet_length=1024)
EARLY_FIELD_TIME = 430 / CPS
"""The early field's own line time: what the init costs over a short one."""


async def _session_setup(cfg: EndpointConfig, *, defer: bool, key: bytes | None) -> float:
    """Seconds from the start to the session granted, with the arm's early bytes."""
    line = ImpairedLink(MOON)
    early: list[int] = []
    async with (
        Server(FakeArm(), ServerConfig(key=key, rtt_hint=6.0)) as server,
        trio.open_nursery() as nursery,
        listen(line.b, cfg) as listener,
    ):

        async def serve() -> None:
            sock = await listener.accept()
            early.append(sock.statistics().link.early_received)
            await server.serve_stream(sock)

        nursery.start_soon(serve)
        start = trio.current_time()
        sock = await connect(line.a, cfg, nursery=nursery, defer=defer)
        async with sock, connect_stream(sock, key=key, identity="earth") as client:
            granted = trio.current_time() - start
            assert client.parameters is not None
            await client.status()
        nursery.cancel_scope.cancel()
    assert early == [PACKET_SIZE if defer else 0]
    return granted


@pytest.mark.parametrize(
    ("key", "plain_rtts"),
    [
        pytest.param(None, 2, id="hello-grant"),
        pytest.param(KEY, 3, id="hello-challenge-auth-grant"),
    ],
)
def test_the_hello_in_the_connection_request_saves_a_round_trip(
    key: bytes | None, plain_rtts: int
) -> None:
    times: dict[bool, float] = {}

    async def main() -> None:
        with trio.fail_after(600):
            for defer in (False, True):
                times[defer] = await _session_setup(CFG, defer=defer, key=key)

    run(main)
    plain, deferred = times[False], times[True]
    print(f"session granted after {plain:.3f} s (connect first), {deferred:.3f} s (deferred)")
    # Connecting first: the serial handshake's round trip, then the session's
    # own (one without a key, two with), plus line times.
    assert plain_rtts * RTT < plain < plain_rtts * RTT + 1.0
    # Deferred: one round trip fewer, less the early field's extra line time
    # (the HELLO as a data packet is shorter, in the 8-bit encoding).
    saved = plain - deferred
    assert RTT - EARLY_FIELD_TIME < saved < RTT
