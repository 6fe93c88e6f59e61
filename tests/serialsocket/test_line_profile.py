"""8-bit by default where the line is 8-bit (issue 21; PROTOCOL.md section 8).

The profile comes from the port's character format (8N1: 8-bit; 7 data bits
or parity: printable) when the configuration leaves ``encoding`` to the line;
an explicit choice wins; the netcat's ``--profile`` chooses among the three.
"""

from __future__ import annotations

import argparse
import os

import pytest
import trio

from serialsocket import EndpointConfig, accept, connect, open_port, open_pty_pair
from serialsocket._config import line_encoding
from serialsocket._netcat import _config as netcat_config
from serialsocket._netcat import add_arguments
from serialsocket._pyserial import port_encoding
from serialsocket.packets import EIGHT_BIT_CLEAN, PRINTABLE, EscapeEncoding, Radix91Encoding


@pytest.mark.parametrize(
    ("bytesize", "parity", "expected"),
    [
        (8, "N", EIGHT_BIT_CLEAN),
        (8, "E", PRINTABLE),
        (8, "O", PRINTABLE),
        (7, "E", PRINTABLE),
        (7, "N", PRINTABLE),
        (5, "N", PRINTABLE),
    ],
)
def test_the_character_format_chooses_the_profile(
    bytesize: int, parity: str, expected: object
) -> None:
    assert line_encoding(bytesize, parity) == expected


def test_a_raw_pty_is_8_bit_and_a_7e1_url_is_printable() -> None:
    assert port_encoding(None) == EIGHT_BIT_CLEAN

    async def main() -> None:
        a, b = open_pty_pair()
        async with a, b:
            assert a.encoding == b.encoding == EIGHT_BIT_CLEAN
        async with await open_port("loop://", bytesize=7, parity="E") as seven:
            assert seven.encoding == PRINTABLE
        async with await open_port("loop://") as eight:
            assert eight.encoding == EIGHT_BIT_CLEAN

    trio.run(main)


def test_an_explicit_encoding_wins_over_the_line() -> None:
    class Port:
        encoding = EIGHT_BIT_CLEAN

    assert EndpointConfig(dense=True).for_line(Port()).encoding == EIGHT_BIT_CLEAN
    assert EndpointConfig(dense=True, encoding=PRINTABLE).for_line(Port()).encoding == PRINTABLE
    assert EndpointConfig(dense=True).for_line(object()).encoding is None
    assert EndpointConfig(dense=True).line_encoding() == PRINTABLE  # no line seen: printable


@pytest.mark.parametrize(
    ("cfg", "codec"),
    [
        (EndpointConfig(dense=True), EscapeEncoding),  # the pty is 8N1: 8-bit, the escape code
        (EndpointConfig(dense=True, encoding=PRINTABLE), Radix91Encoding),
    ],
)
def test_connect_and_accept_over_ptys_take_the_profile_from_the_port(
    cfg: EndpointConfig, codec: type
) -> None:
    async def main() -> None:
        a, b = open_pty_pair()
        async with trio.open_nursery() as nursery:

            async def server() -> None:
                sock = await accept(b, cfg, nursery=nursery)
                data = await sock.receive_some(1000)
                await sock.send_all(data)
                await sock.aclose()

            nursery.start_soon(server)
            sock = await connect(a, cfg, nursery=nursery)
            params = sock.endpoint.parameters
            assert params is not None
            assert type(params.encoding) is codec
            await sock.send_all(bytes(range(256)))
            got = b""
            while len(got) < 256:
                got += await sock.receive_some(1000)
            assert got == bytes(range(256))
            await sock.aclose()

    async def bounded() -> None:
        with trio.fail_after(30):  # a hang, not a timing assertion
            await main()

    trio.run(bounded)


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        ([], None),
        (["--profile", "auto"], None),
        (["--profile", "8bit"], EIGHT_BIT_CLEAN),
        (["--profile", "printable"], PRINTABLE),
    ],
)
def test_netcat_profile_option(argv: list[str], expected: object) -> None:
    ap = argparse.ArgumentParser()
    add_arguments(ap, listening=False)
    args = ap.parse_args([os.devnull, *argv])
    assert netcat_config(args, None).encoding == expected
