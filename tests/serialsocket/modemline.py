"""Two emulated Hayes modems as in-memory trio streams, on trio time (no ptys).

The DTE side of each modem of a :class:`linksim.ModemPair` is a trio stream;
the telephone line between the modems is a perfect wire.  Modem timers (dial
time, rings, S7, guard times) run on trio's clock, so under
``MockClock(autojump_threshold=0)`` a 50-second NO ANSWER takes no wall time.
"""

from __future__ import annotations

import trio

from linksim import ModemConfig, ModemPair


class ModemLine:
    """``line.ends[0]`` and ``line.ends[1]``: what the two programs read and write.

    Run :meth:`run` in a nursery (it fires the modems' timers).
    """

    def __init__(self, config: ModemConfig | None = None) -> None:
        self.pair = ModemPair(config)
        self.inbox = (bytearray(), bytearray())
        self.changed = trio.Event()
        self.ends = (_End(self, 0), _End(self, 1))

    def pump(self) -> None:
        """Carry line bytes between the modems and collect bytes for the programs."""
        now = trio.current_time()
        self.pair.handle_timer(now)
        while True:
            moved = False
            for side in (0, 1):
                line = self.pair.data_to_line(side)
                if line:
                    self.pair.from_line(1 - side, line, now)
                    moved = True
            for side in (0, 1):
                self.inbox[side].extend(self.pair.data_to_dte(side))
            if not moved:
                break
        self.changed.set()
        self.changed = trio.Event()

    async def run(self) -> None:
        while True:
            deadline = self.pair.next_timer()
            changed = self.changed
            with trio.move_on_at(deadline if deadline is not None else float("inf")):
                await changed.wait()
            self.pump()


class _End(trio.abc.Stream):
    def __init__(self, line: ModemLine, side: int) -> None:
        self.line = line
        self.side = side
        self.written = bytearray()  # everything this program sent (for assertions)

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        await trio.lowlevel.checkpoint()
        self.written += data
        self.line.pair.from_dte(self.side, bytes(data), trio.current_time())
        self.line.pump()

    async def wait_send_all_might_not_block(self) -> None:
        await trio.lowlevel.checkpoint()

    async def receive_some(self, max_bytes: int | None = None) -> bytes:
        inbox = self.line.inbox[self.side]
        while not inbox:
            await self.line.changed.wait()
        n = max_bytes or len(inbox)
        out = bytes(inbox[:n])
        del inbox[:n]
        await trio.lowlevel.checkpoint()
        return out

    async def aclose(self) -> None:
        await trio.lowlevel.checkpoint()
