"""The Hayes dialer and answerer against linksim's modem emulator, on virtual time."""

from __future__ import annotations

from collections.abc import Awaitable, Callable

import pytest
import trio
import trio.testing

from linksim.link import CallOutcome, ModemConfig, ModemState
from serialsocket import (
    LineBusy,
    ModemConnection,
    ModemError,
    ModemTimeout,
    NoAnswer,
    NoCarrier,
    NoDialtone,
    answer,
    dial,
    hangup,
)

from .modemline import ModemLine

FAST = ModemConfig(dial_time=2.0, ring_interval=6.0, handshake_time=1.5)


def run_with_line(body: Callable[[ModemLine], Awaitable[None]], config: ModemConfig = FAST) -> None:
    async def main() -> None:
        line = ModemLine(config)
        async with trio.open_nursery() as nursery:
            nursery.start_soon(line.run)
            await body(line)
            nursery.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))


def test_dial_and_answer_then_data_then_hangup() -> None:
    async def body(line: ModemLine) -> None:
        caller, callee = line.ends
        results: dict[str, ModemConnection] = {}

        async def do_answer() -> None:
            results["answer"] = await answer(callee, rings=2)

        async with trio.open_nursery() as nursery:
            nursery.start_soon(do_answer)
            await trio.sleep(1)  # the answerer has reset its modem
            t0 = trio.current_time()
            results["dial"] = await dial(caller, "5551234")
            # dial time, a second ring 6 s later, then 1.5 s of carrier training
            assert trio.current_time() - t0 == pytest.approx(2.0 + 6.0 + 1.5)
        assert results["dial"] == ModemConnection(2400, "CONNECT 2400")
        assert results["answer"] == ModemConnection(2400, "CONNECT 2400")
        assert caller.written == b"ATZ\rATDT5551234\r"
        assert callee.written == b"ATZ\rATA\r"

        await caller.send_all(b"\x00hello\xff")
        assert await callee.receive_some() == b"\x00hello\xff"

        t0 = trio.current_time()
        await hangup(caller)
        assert line.pair.state(0) is ModemState.IDLE
        # guard, +++, guard: 1.2 s of silence each side of the escape (S12 = 1 s)
        assert trio.current_time() - t0 == pytest.approx(1.2 + 1.0)
        await trio.sleep(2)  # S10 = 1.4 s: the far modem notices the carrier is gone
        assert line.pair.state(1) is ModemState.IDLE
        assert b"NO CARRIER" in await callee.receive_some()

    run_with_line(body)


def test_auto_answer() -> None:
    async def body(line: ModemLine) -> None:
        caller, callee = line.ends
        async with trio.open_nursery() as nursery:
            box: list[ModemConnection] = []

            async def do_answer() -> None:
                box.append(await answer(callee, auto_answer=True, rings=1))

            nursery.start_soon(do_answer)
            await trio.sleep(1)
            assert (await dial(caller, "1")).rate == 2400
        assert box == [ModemConnection(2400, "CONNECT 2400")]
        assert callee.written == b"ATZ\rATS0=1\r"  # the modem answered by itself

    run_with_line(body)


def test_busy_number() -> None:
    cfg = ModemConfig(phone_book={"5551234": CallOutcome.BUSY})

    async def body(line: ModemLine) -> None:
        with pytest.raises(LineBusy, match="5551234 is busy: try again later") as info:
            await dial(line.ends[0], "5551234")
        assert info.value.result == "BUSY"

    run_with_line(body, cfg)


def test_nobody_answers() -> None:
    async def body(line: ModemLine) -> None:
        # The far modem rings (RING, RING, ...) but its program never answers:
        # the caller's modem gives up after S7 = 50 s.
        t0 = trio.current_time()
        with pytest.raises(NoAnswer, match="auto-answer"):
            await dial(line.ends[0], "5550000")
        assert trio.current_time() - t0 == pytest.approx(50.0)
        assert (await line.ends[1].receive_some()).count(b"RING") == 8  # at 2, 8, ..., 44 s

    run_with_line(body)


def test_dial_timeout_aborts_the_call() -> None:
    async def body(line: ModemLine) -> None:
        with pytest.raises(ModemTimeout, match=r"no CONNECT from 42 within 5.0 s"):
            await dial(line.ends[0], "42", timeout=5.0)
        assert line.ends[0].written.endswith(b"ATDT42\r\r")  # the abort keystroke
        assert line.pair.state(0) is ModemState.IDLE
        assert line.pair.state(1) is ModemState.IDLE

    run_with_line(body)


def test_no_carrier_when_the_far_side_drops_during_training() -> None:
    async def body(line: ModemLine) -> None:
        caller, callee = line.ends

        async def answer_then_abort() -> None:
            with trio.move_on_after(100):
                while b"RING" not in await callee.receive_some():
                    pass
            await callee.send_all(b"ATA\r")
            await callee.send_all(b"x")  # a keystroke aborts the handshake

        async with trio.open_nursery() as nursery:
            nursery.start_soon(answer_then_abort)
            with pytest.raises(NoCarrier, match="check the number"):
                await dial(caller, "7")

    run_with_line(body)


def test_modem_error_and_silent_port() -> None:
    async def body(line: ModemLine) -> None:
        with pytest.raises(ModemError, match="ERROR to 'ATX9'"):
            await dial(line.ends[0], "1", init="ATX9")
        with pytest.raises(ValueError, match="cannot dial"):
            await dial(line.ends[0], "555; rm -rf")

    run_with_line(body)

    async def silent() -> None:
        left, _right = trio.testing.memory_stream_pair()
        t0 = trio.current_time()
        with pytest.raises(ModemTimeout, match="is a Hayes modem attached"):
            await dial(left, "1", command_timeout=3.0)
        assert trio.current_time() - t0 == pytest.approx(3.0)

    trio.run(silent, clock=trio.testing.MockClock(autojump_threshold=0))


def test_answer_times_out_without_a_call() -> None:
    async def body(line: ModemLine) -> None:
        with pytest.raises(ModemTimeout, match="no call within 30"):
            await answer(line.ends[1], timeout=30)

    run_with_line(body)


class ScriptedModem(trio.abc.Stream):
    """A modem that answers each command line with the next scripted reply."""

    def __init__(self, replies: list[bytes]) -> None:
        self.replies = replies
        self.out = bytearray()
        self.commands: list[bytes] = []
        self.line = bytearray()
        self.ready = trio.Event()

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        await trio.lowlevel.checkpoint()
        for byte in bytes(data):
            if byte == 13:
                self.commands.append(bytes(self.line))
                self.line.clear()
                if self.replies:
                    self.out += self.replies.pop(0)
                    self.ready.set()
            else:
                self.line.append(byte)

    async def wait_send_all_might_not_block(self) -> None:
        await trio.lowlevel.checkpoint()

    async def receive_some(self, max_bytes: int | None = None) -> bytes:
        while not self.out:
            self.ready = trio.Event()
            await self.ready.wait()
        n = max_bytes or len(self.out)
        chunk = bytes(self.out[:n])
        del self.out[:n]
        await trio.lowlevel.checkpoint()
        return chunk

    async def aclose(self) -> None:
        await trio.lowlevel.checkpoint()


@pytest.mark.parametrize(
    ("reply", "error", "message"),
    [
        (b"\r\nNO DIALTONE\r\n", NoDialtone, "line cable"),
        (b"7\r", LineBusy, "busy"),  # numeric result codes (ATV0)
        (b"8\r", NoAnswer, "did not answer"),
        (b"3\r", NoCarrier, "no carrier"),
        (b"4\r", ModemError, "rejected the dial command"),
    ],
)
def test_result_codes_verbose_and_numeric(
    reply: bytes, error: type[Exception], message: str
) -> None:
    async def main() -> None:
        modem = ScriptedModem([b"0\r", reply])
        with pytest.raises(error, match=message):
            await dial(modem, "123")
        assert modem.commands == [b"ATZ", b"ATDT123"]

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))


def test_numeric_and_bare_connect() -> None:
    async def main() -> None:
        assert await dial(ScriptedModem([b"0\r", b"10\r"]), "1") == ModemConnection(
            2400, "CONNECT 2400"
        )
        # A bare CONNECT (an original 300-baud Hayes) has no rate.
        assert (await dial(ScriptedModem([b"\r\nOK\r\n", b"\r\nCONNECT\r\n"]), "1")).rate is None

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))


def test_hangup_after_the_carrier_is_already_gone() -> None:
    async def body(line: ModemLine) -> None:
        caller, callee = line.ends
        async with trio.open_nursery() as nursery:
            nursery.start_soon(answer, callee)
            await trio.sleep(1)
            await dial(caller, "1")
        await hangup(callee)  # the answering side hangs up first
        await trio.sleep(5)  # the caller's modem reports NO CARRIER (S10)
        assert line.pair.state(0) is ModemState.IDLE
        await hangup(caller)  # nothing to escape from: still acknowledged
        assert caller.written.endswith(b"+++\rATH\r")

    run_with_line(body)
