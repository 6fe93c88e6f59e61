"""The emergency stop on the sample channel (PROTOCOL.md 14.5): copies of the STOP until
the arm says STOPPED, so that a lost STOP is repaired when the next packet shows the
gap rather than when the transport's timer fires; and the ends' input bounds."""

from __future__ import annotations

import itertools

import pytest

from tcpstream._teleop_connection import MAX_STOP_COPIES, STOP_REPEAT
from tcpstream.teleop import (
    ArmChannel,
    Backlog,
    Buttons,
    ChannelState,
    ContactFlags,
    OperatorChannel,
    Reply,
    ReplyStatus,
    Sample,
    StopArrived,
    TeleopKind,
    TeleopMode,
    TeleopPacketError,
    decode_header,
)

KEY = b"telelink-test-vector-key-000001!"
ZERO6 = (0.0,) * 6
IDLE = Backlog(0, 0.0)
BUSY = Backlog(0, 0.1)


def opened() -> tuple[OperatorChannel, ArmChannel]:
    op = OperatorChannel("operator", KEY, bytes(range(16)))
    arm = ArmChannel(KEY, bytes(range(16, 32)), rate_deadman=3.0, control_rate=125.0)
    op.connect()
    arm.receive_data(op.data_to_send(), 0.0)
    op.receive_data(arm.data_to_send(), 0.0)
    arm.receive_data(op.data_to_send(), 0.0)
    arm.grant()
    op.receive_data(arm.data_to_send(), 0.0)
    assert op.state is arm.state is ChannelState.OPEN
    return op, arm


def kinds(data: bytes) -> list[TeleopKind]:
    out = []
    while data:
        kind, _, size = decode_header(data)
        out.append(kind)
        data = data[size:]
    return out


def stopped_reply() -> Reply:
    return Reply(0, ReplyStatus.STOPPED, ContactFlags(0), 0, 0, 0.0, 0.0, ZERO6, ZERO6, ZERO6)


def test_a_copy_follows_the_stop_as_soon_as_the_line_is_idle_then_every_interval() -> None:
    op, arm = opened()
    op.offer(Sample(1, TeleopMode.CARTESIAN, Buttons.ENGAGED, 0, 0.0, ZERO6))
    op.emergency_stop()
    wire = op.data_to_send()
    assert kinds(wire) == [TeleopKind.STOP]  # the pending sample is dropped
    assert op.poll(0.0, BUSY) is False  # the STOP has just been queued
    assert op.poll(0.05, BUSY) is False  # still on the line: a copy would share its packet
    assert op.poll(0.06, IDLE) is True  # the first copy: at once on an idle line
    assert op.poll(0.06 + STOP_REPEAT - 0.01, IDLE) is False
    assert op.poll(0.06 + STOP_REPEAT, IDLE) is True
    wire += op.data_to_send()
    assert kinds(wire) == [TeleopKind.STOP] * 3
    # The arm latches the first and reports it once; the copies are only counted.
    assert arm.receive_data(wire, 2.0) == [StopArrived(2.0)]
    assert arm.statistics().stops_received == 3
    # Its REPLY saying STOPPED ends the copies.
    arm.reply(stopped_reply())
    assert arm.poll(2.0)
    op.receive_data(arm.data_to_send(), 3.0)
    assert op.stop_confirmed
    assert not op.repeating_stop
    assert op.poll(10.0, IDLE) is False
    assert op.data_to_send() == b""
    st = op.statistics()
    assert (st.stops_sent, st.stops_repeated, st.samples_sent) == (1, 2, 0)


def test_stop_copies_are_bounded_and_paced_without_transport_figures() -> None:
    op, _ = opened()
    op.emergency_stop()
    op.data_to_send()
    sent_at = []
    t = 0.0
    while t < 10.0:
        if op.poll(t):
            sent_at.append(t)
        t = round(t + 0.05, 2)
    assert len(sent_at) == MAX_STOP_COPIES == op.statistics().stops_repeated
    assert sent_at[0] == STOP_REPEAT  # TCP: no figures say the line is idle, so wait
    assert all(b - a >= STOP_REPEAT for a, b in itertools.pairwise(sent_at))
    assert not op.repeating_stop


def test_a_closed_end_keeps_no_bytes() -> None:
    """Regression: a closed end buffered everything fed to it (the reader stops there, but
    the sans-I/O core's bound must not depend on that); found by fuzz/fuzz_session.py."""
    op, arm = opened()
    op.close()
    arm.receive_data(op.data_to_send() + b"T" * 500, 1.0)
    assert arm.state is ChannelState.CLOSED
    assert len(arm._buf) == 0
    arm.receive_data(b"TT" * 1000, 2.0)
    assert len(arm._buf) == 0


@pytest.mark.parametrize("data", [b"", b"T", b"TT\x01\x06\x00\x00\x00"])
def test_a_short_header_is_a_typed_error(data: bytes) -> None:
    """Regression: fewer than 8 bytes raised struct.error (fuzz/fuzz_command_packet.py)."""
    with pytest.raises(TeleopPacketError):
        decode_header(data)
