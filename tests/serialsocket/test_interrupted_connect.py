"""A program interrupted mid-transfer tells its peer (the sibling of issue 17's
cancellation findings, seen in real time with the netcat): Ctrl-C cancels the
whole run, the serial socket's driver tasks with it, and the close's abort
then had no writer left to send its E.  The peer heard silence and reported
"link dead after 26.4 s of silence" instead of "the peer aborted".  Now the
close writes the E itself when the writer is gone.  Virtual time.
"""

from __future__ import annotations

import random

import trio
import trio.testing

from linksim.link import DirectionConfig, ImpairedLink, LinkConfig, endpoint_config_for
from serialsocket import PeerAborted, accept, connect

from .borrowed import Borrowed

LINE = LinkConfig.symmetric(DirectionConfig(rate=2400, delay=1.3), seed=1)


def test_a_run_cancelled_mid_transfer_says_so_to_the_peer() -> None:
    cfg = endpoint_config_for(LINE)
    data = random.Random(5).randbytes(20000)
    heard: list[BaseException] = []
    at: list[float] = []

    async def main() -> None:
        line = ImpairedLink(LINE)
        async with trio.open_nursery() as outer:

            async def listener() -> None:
                async with trio.open_nursery() as nursery:
                    sock = await accept(line.b, cfg, nursery=nursery)
                    try:
                        while await sock.receive_some():
                            pass
                    except trio.BrokenResourceError as exc:
                        heard.append(exc)
                        at.append(trio.current_time())
                    finally:
                        await sock.aclose()

            outer.start_soon(listener)
            # The connecting program, structured as the netcat is: its socket's
            # driver runs in the program's own nursery, and Ctrl-C cancels
            # the whole run (serialsocket.interrupt.run_interruptibly).
            with trio.CancelScope() as run:
                async with trio.open_nursery() as nursery:
                    # Borrowed: the program exiting closes its end, not the
                    # line (the simulator's end would break the far end's
                    # writes), as on a real serial line.
                    sock = await connect(Borrowed(line.a), cfg, nursery=nursery)
                    try:

                        async def interrupt() -> None:
                            await trio.sleep(10.0)
                            at.append(trio.current_time())
                            run.cancel()

                        nursery.start_soon(interrupt)
                        await sock.send_all(data)
                    finally:
                        await sock.aclose()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    assert len(heard) == 1
    cause = heard[0].__cause__
    assert isinstance(cause, PeerAborted), repr(cause)
    assert "closed by the application" in str(cause)
    # Behind whatever the line still held of the transfer, not after a
    # silence verdict (which needs dead_after of silence: over 8 s here).
    assert at[1] - at[0] < 1.3 + 1.0, at
