"""An interrupted Kermit transfer tells the peer (the sibling of the serial
socket's interrupted close): Ctrl-C cancels the command's whole run, and the
transfer loop used to unwind without a word, leaving the peer to retry to
its limit.  Now it sends an E packet, as C-Kermit does.  Virtual time over
the simulator's line.
"""

from __future__ import annotations

import pathlib
import random

import pytest
import trio
import trio.testing

from linksim.link import DirectionConfig, ImpairedLink, LinkConfig
from serialsocket.kermit import KermitConfig, KermitTransferError, kermit_receive, kermit_send

LINE = LinkConfig.symmetric(DirectionConfig(rate=9600, delay=0.3), seed=1)


@pytest.mark.parametrize("interrupted", ["sender", "receiver"])
def test_an_interrupted_transfer_sends_E_and_the_peer_reports_it(
    tmp_path: pathlib.Path, interrupted: str
) -> None:
    src = tmp_path / "big.bin"
    src.write_bytes(random.Random(7).randbytes(60_000))
    out = tmp_path / "out"
    out.mkdir()
    config = KermitConfig(timeout=5.0)
    failures: list[KermitTransferError] = []
    ended_at: list[float] = []

    async def main() -> None:
        line = ImpairedLink(LINE)
        async with trio.open_nursery() as nursery:

            async def side(name: str) -> None:
                with trio.CancelScope() as scope:
                    if name == interrupted:
                        scope.deadline = trio.current_time() + 8.0  # Ctrl-C, 8 s in
                    try:
                        if name == "sender":
                            await kermit_send(line.a, [src], config)
                        else:
                            await kermit_receive(line.b, out, config)
                    except KermitTransferError as exc:
                        failures.append(exc)
                        ended_at.append(trio.current_time())

            nursery.start_soon(side, "receiver")
            nursery.start_soon(side, "sender")

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    assert len(failures) == 1
    assert failures[0].by_peer
    assert "Transfer interrupted" in str(failures[0])
    # Not after the retry limit (33 tries of 5 s).  An interrupted sender's
    # E drops what its UART held and arrives one way later; an interrupted
    # receiver's reaches a sender that reads again only when its write of a
    # whole window returns (the Kermit loop is not paced: 10.7 s here).
    if interrupted == "sender":
        assert ended_at[0] < 8.0 + 0.3 + 0.1, ended_at
    else:
        assert ended_at[0] < 8.0 + 4 * 5.0, ended_at
    assert not (out / "big.bin").exists()
