"""The teleoperation view renders as exact text."""

from __future__ import annotations

import io

from linksim.teleop._view import LiveView, ViewState, force_bar, render
from tcpstream.teleop import Buttons, ContactFlags, Reply, ReplyStatus, Sample, TeleopMode


def test_force_bar_is_signed_and_marks_the_excess() -> None:
    assert force_bar(0.0, 50.0) == " " * 20 + "|" + " " * 20
    assert force_bar(25.0, 50.0) == " " * 20 + "|" + "#" * 10 + " " * 10
    assert force_bar(-50.0, 50.0) == "#" * 20 + "|" + " " * 20
    assert force_bar(80.0, 50.0) == " " * 20 + "|" + "!" * 20


def test_render_shows_mode_buttons_forces_poses_age_and_link() -> None:
    sample = Sample(40, TeleopMode.INDEX, Buttons.SHARED_COMPLIANCE, 128, 10.0, (0.0,) * 6)
    reply = Reply(
        30,
        ReplyStatus.FOLLOWING,
        ContactFlags.CONTACT | ContactFlags.COMPLIANT,
        4,
        64,
        9.0,
        0.1,
        (0.0, 0.0, 30.0, 1.0, 0.0, 0.0),
        (0.5, -0.15, -0.05, 0.0, 0.0, 0.0),
        (0.5, -0.15, -0.035, 0.0, 0.0, 0.0),
    )
    lines = render(
        ViewState(
            now=12.0,
            sample=sample,
            reply=reply,
            reply_at=11.8,
            predicted=(0.5, -0.15, -0.05),
            channel=None,
            force_limit=50.0,
            one_way_delay=1.3,
        )
    )
    assert lines[0] == (
        "teleop  t=   12.00 s  mode index     buttons CLUTCH SHARED WORLD  trigger 128"
    )
    assert lines[1].startswith("arm     FOLLOWING   flags CONTACT COMPLIANT")
    assert lines[4] == "  Fz    30.00 N  " + " " * 20 + "|" + "#" * 12 + " " * 8
    assert lines[8] == "hand mm  predicted    500.0   -150.0    -50.0"
    assert lines[10] == "         confirmed    500.0   -150.0    -35.0"
    # 2.8 s from sampling to the reply, 0.1 s held, 1.3 s back: executed about 1.4 s old.
    assert "sample to reply  2.800 s; at execution about  1.400 s" in lines[11]


def test_the_live_view_draws_only_on_a_terminal() -> None:
    out = io.StringIO()
    live = LiveView(out)
    assert not live.enabled
    live.draw(ViewState(0.0, None, None, None, None, None, force_limit=50.0, one_way_delay=0.0))
    assert out.getvalue() == ""
