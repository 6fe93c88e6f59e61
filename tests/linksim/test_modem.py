"""The Hayes modem pair (sans-I/O): dialogues with exact times."""

from __future__ import annotations

import pytest

from linksim import ModemConfig, ModemPair
from linksim.link import CallOutcome, ModemState

OK = b"\r\nOK\r\n"


def typed(pair: ModemPair, side: int, text: str, now: float) -> bytes:
    """Type ``text`` at ``side``'s DTE; returns what the modem sends back right away."""
    pair.from_dte(side, text.encode(), now)
    return pair.data_to_dte(side)


def advance(pair: ModemPair, until: float) -> list[tuple[float, int, bytes]]:
    """Fire every timer up to ``until``; returns (time, side, output) events."""
    events = []
    while (t := pair.next_timer()) is not None and t <= until:
        pair.handle_timer(t)
        for side in (0, 1):
            if out := pair.data_to_dte(side):
                events.append((t, side, out))
    return events


def connected(**kw: object) -> ModemPair:
    """A pair in a call: 0 dialed at t=0, 1 answered at t=3, CONNECT at 4.5."""
    pair = ModemPair(ModemConfig(**kw))  # type: ignore[arg-type]
    typed(pair, 0, "ATE0\r", 0.0)
    typed(pair, 1, "ATE0\r", 0.0)
    assert typed(pair, 0, "ATDT5551234\r", 0.0) == b""
    assert advance(pair, 3.0) == [(2.0, 1, b"\r\nRING\r\n")]
    assert typed(pair, 1, "ATA\r", 3.0) == b""
    assert advance(pair, 10.0) == [
        (4.5, 0, b"\r\nCONNECT 2400\r\n"),
        (4.5, 1, b"\r\nCONNECT 2400\r\n"),
    ]
    return pair


def test_echo_ok_and_error() -> None:
    pair = ModemPair()
    assert typed(pair, 0, "ATZ\r", 0.0) == b"ATZ\r" + OK
    assert typed(pair, 0, "ATE0\r", 0.0) == b"ATE0\r" + OK
    assert typed(pair, 0, "AT\r", 0.0) == OK
    assert typed(pair, 0, "atq0v1s0=2\r", 0.0) == OK
    assert pair.register(0, 0) == 2
    assert typed(pair, 0, "ATS0?\r", 0.0) == b"\r\n002\r\n" + OK
    assert typed(pair, 0, "ATX9\r", 0.0) == b"\r\nERROR\r\n"
    assert typed(pair, 0, "ATS99=1\r", 0.0) == b"\r\nERROR\r\n"
    assert typed(pair, 0, "hello\r", 0.0) == b""  # not a command: ignored
    assert typed(pair, 0, "ATV0\r", 0.0) == b"0\r"  # numeric OK at once
    assert typed(pair, 0, "ATX\r", 0.0) == b"4\r"  # numeric ERROR
    # typed without echo (E0); Z restores echo and verbose results
    assert typed(pair, 0, "ATZ\r", 0.0) == OK
    assert typed(pair, 0, "AT\r", 0.0) == b"AT\r" + OK


def test_backspace_edits_the_command_line() -> None:
    pair = ModemPair()
    assert typed(pair, 0, "ATE0X\x08\r", 0.0).endswith(OK)


def test_dial_ring_answer_connect_data_escape_hangup() -> None:
    pair = connected()
    assert pair.state(0) is pair.state(1) is ModemState.ONLINE
    # data mode: DTE bytes go to the line, line bytes to the DTE
    pair.from_dte(0, b"MOVE 1 2 3\r", 5.0)
    assert pair.data_to_line(0) == b"MOVE 1 2 3\r"
    pair.from_line(1, b"MOVE 1 2 3\r", 5.1)
    assert pair.data_to_dte(1) == b"MOVE 1 2 3\r"
    # +++ after 1 s of silence, then 1 s of silence: command mode
    assert typed(pair, 0, "+++", 7.0) == b""
    assert pair.data_to_line(0) == b"+++"  # a real modem transmits them too
    assert advance(pair, 8.0) == [(8.0, 0, OK)]
    assert pair.state(0) is ModemState.ONLINE_COMMAND
    pair.from_line(0, b"lost while in command mode", 8.5)
    assert pair.data_to_dte(0) == b""
    assert typed(pair, 0, "ATO\r", 9.0) == b"\r\nCONNECT 2400\r\n"
    assert typed(pair, 0, "+++", 11.0) == b""
    advance(pair, 12.0)
    assert typed(pair, 0, "ATH\r", 13.0) == OK
    assert pair.state(0) is ModemState.IDLE
    # the far modem notices the carrier gone after S10 = 1.4 s
    assert advance(pair, 20.0) == [(13.0 + 1.4, 1, b"\r\nNO CARRIER\r\n")]
    assert pair.state(1) is ModemState.IDLE


def test_escape_needs_guard_time_before_and_after() -> None:
    pair = connected()
    pair.from_dte(0, b"data", 6.0)
    pair.from_dte(0, b"+++", 6.5)  # only 0.5 s after data: not an escape
    assert advance(pair, 10.0) == []
    pair.from_dte(0, b"+", 10.0)
    pair.from_dte(0, b"++", 10.2)  # split across writes is fine
    pair.from_dte(0, b"x", 10.9)  # data within the trailing guard: cancelled
    assert advance(pair, 20.0) == []
    assert pair.state(0) is ModemState.ONLINE
    pair.from_dte(0, b"++++", 30.0)  # four is not three
    assert advance(pair, 40.0) == []


def test_auto_answer_after_s0_rings() -> None:
    pair = ModemPair()
    typed(pair, 1, "ATE0S0=2\r", 0.0)
    typed(pair, 0, "ATE0DT123\r", 0.0)
    assert advance(pair, 20.0) == [
        (2.0, 1, b"\r\nRING\r\n"),
        (8.0, 1, b"\r\nRING\r\n"),
        (9.5, 0, b"\r\nCONNECT 2400\r\n"),
        (9.5, 1, b"\r\nCONNECT 2400\r\n"),
    ]


def test_busy_and_no_answer_from_phone_book() -> None:
    book = {"911": CallOutcome.BUSY, "555": CallOutcome.NO_ANSWER}
    pair = ModemPair(ModemConfig(phone_book=book, connect_rate=9600))
    typed(pair, 0, "ATE0\r", 0.0)
    typed(pair, 0, "ATDT911\r", 0.0)
    assert advance(pair, 10.0) == [(2.0, 0, b"\r\nBUSY\r\n")]
    typed(pair, 0, "ATS7=30DT555\r", 10.0)
    assert advance(pair, 100.0) == [(40.0, 0, b"\r\nNO ANSWER\r\n")]
    assert pair.state(1) is ModemState.IDLE  # never rang


def test_unanswered_call_times_out_and_stops_ringing() -> None:
    pair = ModemPair(ModemConfig(ring_interval=6.0))
    typed(pair, 0, "ATE0S7=15\r", 0.0)
    typed(pair, 0, "ATD42\r", 0.0)
    events = advance(pair, 100.0)
    assert events == [
        (2.0, 1, b"\r\nRING\r\n"),
        (8.0, 1, b"\r\nRING\r\n"),
        (14.0, 1, b"\r\nRING\r\n"),
        (15.0, 0, b"\r\nNO ANSWER\r\n"),
    ]
    assert pair.state(1) is ModemState.IDLE


def test_calling_a_modem_in_a_call_is_busy() -> None:
    pair = ModemPair()
    typed(pair, 1, "ATE0DT1\r", 0.0)  # 1 is off hook, dialing 0
    typed(pair, 0, "ATE0\r", 0.5)  # 0 is ringing, but types a command
    assert pair.state(0) is ModemState.RINGING
    pair2 = connected()
    typed(pair2, 0, "+++", 10.0)
    advance(pair2, 11.0)
    assert typed(pair2, 0, "ATD1\r", 12.0) == b"\r\nERROR\r\n"


def test_keypress_aborts_dialing() -> None:
    pair = ModemPair()
    typed(pair, 0, "ATE0D1\r", 0.0)
    assert typed(pair, 0, "x", 1.0) == b"\r\nNO CARRIER\r\n"
    assert pair.state(0) is pair.state(1) is ModemState.IDLE
    assert pair.next_timer() is None


@pytest.mark.parametrize(("outage", "dropped"), [(1.0, False), (2.0, True)])
def test_outage_longer_than_s10_drops_carrier(outage: float, dropped: bool) -> None:
    pair = connected()
    pair.set_signal(1, False, 20.0)
    events = advance(pair, 20.0 + outage)
    pair.set_signal(1, True, 20.0 + outage)
    events += advance(pair, 100.0)
    if dropped:
        # 1 loses carrier at 20 and hangs up at 21.4; 0 then loses it, drops at 22.8
        assert events == [
            (20.0 + 1.4, 1, b"\r\nNO CARRIER\r\n"),
            (20.0 + 1.4 + 1.4, 0, b"\r\nNO CARRIER\r\n"),
        ]
        assert pair.state(0) is pair.state(1) is ModemState.IDLE
    else:
        assert events == []
        assert pair.state(0) is pair.state(1) is ModemState.ONLINE


def test_ata_without_a_call_and_ato_offline() -> None:
    pair = ModemPair()
    typed(pair, 0, "ATE0\r", 0.0)
    assert typed(pair, 0, "ATA\r", 0.0) == b"\r\nNO CARRIER\r\n"
    assert typed(pair, 0, "ATO\r", 0.0) == b"\r\nERROR\r\n"
    assert typed(pair, 0, "ATI\r", 0.0) == b"\r\n242\r\n" + OK
