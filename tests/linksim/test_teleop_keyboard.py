"""The keyboard operator: keys move the intent; a piped key file drives a whole run."""

from __future__ import annotations

import os

import numpy as np

from linksim.link import run_virtual
from linksim.teleop import TeleopOptions, run_teleop
from linksim.teleop._keyboard import KeyboardScript


def test_keys_move_the_handle_and_press_the_buttons() -> None:
    k = KeyboardScript()
    for key in "wwwadrrq gp?":
        k.press(key)
    offset, rotation, w = k.at(1.0)
    np.testing.assert_allclose(offset, [0.015, 0.0, 0.010])
    np.testing.assert_allclose(rotation, [0.0, 0.0, 0.05])
    assert not w.engaged  # the space released the index button
    assert w.trigger == 255
    assert w.pose_change
    k.press("0")
    np.testing.assert_allclose(k.at(2.0)[0], 0.0)
    assert not k.stop_requested
    assert not k.done
    k.press("x")
    k.press("Q")
    assert k.stop_requested
    assert k.done


def test_piped_keys_drive_a_virtual_run() -> None:
    r_fd, w_fd = os.pipe()
    os.write(w_fd, b"f" * 24 + b"w" * 10)  # 12 cm down onto the table, then 5 cm along x
    os.close(w_fd)
    saved = os.dup(0)
    os.dup2(r_fd, 0)
    try:
        r = run_virtual(run_teleop, TeleopOptions(keyboard=True, preset="moon", duration=10.0))
    finally:
        os.dup2(saved, 0)
        os.close(saved)
        os.close(r_fd)
    assert r.ok
    assert 29.0 < r.max_contact_force_n <= 30.0 + 1e-6  # on the table, shared compliance
    assert r.samples_applied > 50
