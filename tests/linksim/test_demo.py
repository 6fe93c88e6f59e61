"""``linksim demo``, ``arm-server`` and ``control``: the whole chain, asserted by its report."""

from __future__ import annotations

import dataclasses
import json
import math
import pathlib
import subprocess
import sys

import pytest

from linksim import DEFAULT_WORLD, DemoOptions, LinkConfig, rock_task, run_demo
from linksim.arm import ObjectSpec
from tcpstream.commands import PACKET_SIZE

LINKSIM = [sys.executable, "-m", "linksim"]
N_COMMANDS = len(rock_task(DEFAULT_WORLD).commands)


def virtual(**changes: object) -> DemoOptions:
    base = DemoOptions(link=LinkConfig.preset("noisy-moon"), virtual=True, progress=False)
    return dataclasses.replace(base, **changes)


def assert_task_done(report: dict[str, object]) -> None:
    assert report["ok"] is True, report["error"]
    assert report["error"] is None
    assert report["commands"] == {
        "sent": N_COMMANDS,
        "completed": N_COMMANDS,
        "failed": 0,
        "total": N_COMMANDS,
    }
    arm = report["arm"]
    assert isinstance(arm, dict)
    # The task ends by returning home, fingers open, with the rock weighed on the way.
    assert arm["joints_rad"] == pytest.approx(DEFAULT_WORLD.initial_joints, abs=1e-6)
    assert arm["finger_opening_m"] == pytest.approx(DEFAULT_WORLD.max_opening, abs=1e-6)
    assert arm["tactile"] == [False, False]
    assert arm["weighed_mass_kg"] == pytest.approx(0.85, abs=0.01)
    for key in ("a", "s"):
        assert math.hypot(*arm[key]) == pytest.approx(1.0, abs=1e-6)


def test_virtual_serial_demo_runs_the_rock_task_over_noisy_moon() -> None:
    report = run_demo(virtual()).as_dict()
    assert_task_done(report)
    assert report["transport"] == "serial"
    assert report["virtual"] is True
    link = report["link"]
    assert isinstance(link, dict)
    # A 1.3 s line each way: the round trip is at least 2.6 s.
    assert link["rtt_s"] > 2.6
    for key in ("retransmissions", "check_failures", "payload_sent_Bps", "bytes_sent"):
        assert key in link
    log = report["command_log"]
    assert isinstance(log, list)
    done = [entry["done_s"] for entry in log]
    assert done == sorted(done), "the arm executes in order"
    assert all(e["sent_s"] <= e["accepted_s"] <= e["done_s"] for e in log)


def test_virtual_demo_is_reproducible() -> None:
    # Same link seed, same run: byte for byte (trio's task-ordering RNG is
    # seeded by run_virtual; see tests/linksim/test_virtual.py).
    first, second = run_demo(virtual()).as_dict(), run_demo(virtual()).as_dict()
    assert first == second


def test_virtual_tcp_demo() -> None:
    report = run_demo(virtual(transport="tcp")).as_dict()
    assert_task_done(report)
    assert report["transport"] == "tcp"
    # A TCP run's figures are the command session's own counters.
    link = report["link"]
    assert link["bytes_sent"] == link["packets_sent"] * PACKET_SIZE > 0
    assert link["bytes_received"] == link["packets_received"] * PACKET_SIZE > 0
    assert link["payload_sent_Bps"] > 0


def test_a_refused_command_stops_the_arm_and_fails_the_run() -> None:
    # The rock lies beyond the arm's reach: the approach path is refused, and
    # nothing planned after it may run from the wrong place.
    far = ObjectSpec("rock", (1.5, 0.0, -0.315), 0.07, 0.85)
    world = dataclasses.replace(
        DEFAULT_WORLD, objects=(far, *[o for o in DEFAULT_WORLD.objects if o.name != "rock"])
    )
    report = run_demo(virtual(world=world)).as_dict()
    assert report["ok"] is False
    assert report["commands"]["completed"] == 1  # type: ignore[index]
    assert report["commands"]["failed"] == N_COMMANDS - 1  # type: ignore[index]
    log = report["command_log"]
    assert isinstance(log, list)
    assert log[1]["reason"] == "UNREACHABLE"
    assert all(e["state"] == "failed" for e in log[2:])
    assert "refused command #2" in str(report["error"])
    arm = report["arm"]
    assert isinstance(arm, dict)
    assert arm["joints_rad"] == pytest.approx(DEFAULT_WORLD.initial_joints, abs=1e-6)


def run_cli(*args: str, timeout: float = 240) -> subprocess.CompletedProcess[str]:
    # ``timeout`` is a hang guard, never a speed assertion.
    return subprocess.run(
        [*LINKSIM, *args], capture_output=True, text=True, timeout=timeout, check=False
    )


def test_cli_virtual_json_prints_only_the_report() -> None:
    done = run_cli("demo", "--virtual", "--json")
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)  # the whole of stdout is one JSON object
    assert_task_done(report)
    assert "rock task" in done.stderr  # progress goes to stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--transport", "tcp", "--dial", "5551234"], "--dial needs the serial transport"),
        (["--window", "40"], "window"),
        (["--preset", "noisy-moon", "--ber", "2"], "argument --ber/--byte-error-rate: must be"),
    ],
)
def test_cli_bad_options_exit_2(args: list[str], message: str) -> None:
    done = run_cli("demo", "--virtual", *args)
    assert done.returncode == 2
    assert message in done.stderr


@pytest.mark.slow
def test_real_time_demo_over_ptys_through_the_relay() -> None:
    # A shortened real-time run: the geo preset (0.27 s each way) instead of
    # noisy-moon, through real ptys, the relay and a separate arm-server process.
    done = run_cli("demo", "--preset", "geo", "--ber", "1e-4", "--seed", "3", "--json")
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert_task_done(report)
    assert report["virtual"] is False
    line = report["link"]["line"]
    assert line["controller_to_arm"]["bytes_delivered"] > 0
    # Never silent while connecting or closing (status lines on stderr).
    for status in (
        "starting the impaired relay",
        "connecting the serial socket",
        "authenticating",
        "closing the serial link",
        "serial link closed",
    ):
        assert status in done.stderr, done.stderr
    assert line["arm_to_controller"]["bytes_corrupted"] >= 0


@pytest.mark.slow
def test_real_time_demo_over_tcp() -> None:
    # The line's delay applies to TCP too (it was ignored: loopback at full speed).
    done = run_cli("demo", "--transport", "tcp", "--preset", "clean", "--delay", "0.2", "--json")
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert_task_done(report)
    assert report["transport"] == "tcp"
    assert "connecting through a 0.2 s one-way delay and authenticating" in done.stderr
    assert "session closed" in done.stderr


@pytest.mark.slow
def test_arm_server_and_control_as_two_programs() -> None:
    server = subprocess.Popen(
        [*LINKSIM, "arm-server", "--transport", "tcp", "--tcp-port", "0", "--sessions", "1"],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert server.stdout is not None
        ready = json.loads(server.stdout.readline())
        assert ready["ready"] is True
        done = run_cli(
            "control", "--transport", "tcp", "--tcp-port", str(ready["tcp_port"]), "--json"
        )
        assert done.returncode == 0, done.stderr
        assert_task_done(json.loads(done.stdout))
        assert server.wait(timeout=60) == 0  # one session served, then it exits
    finally:
        if server.poll() is None:
            server.kill()
            server.wait()


def test_cli_reads_a_world_file(tmp_path: pathlib.Path) -> None:
    world = tmp_path / "world.toml"
    world.write_text(DEFAULT_WORLD.to_toml())
    done = run_cli("demo", "--virtual", "--json", "--world", str(world))
    assert done.returncode == 0, done.stderr
    assert_task_done(json.loads(done.stdout))
    bad = tmp_path / "bad.toml"
    bad.write_text("speed = 7\n")
    done = run_cli("demo", "--virtual", "--world", str(bad))
    assert done.returncode == 2
    assert "speed" in done.stderr
