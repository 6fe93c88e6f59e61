"""Configuration files speak the command line's language (issue 19): TOML keys
are the flag names, and ``--write-config`` / ``--write-world`` write commented
files that read back equal."""

from __future__ import annotations

import io
import pathlib

import pytest

from linksim import DEFAULT_WORLD, ConfigError, WorldConfig
from linksim.cli import main
from linksim.link import (
    PRESETS,
    DirectionConfig,
    FaultAction,
    GilbertElliott,
    LinkConfig,
    Outage,
    ScriptedFault,
)


@pytest.mark.parametrize("name", PRESETS)
def test_every_preset_round_trips_through_its_toml(name: str) -> None:
    config = LinkConfig.preset(name, seed=11)
    assert LinkConfig.from_toml(config.to_toml()) == config


def test_an_asymmetric_line_with_every_impairment_round_trips() -> None:
    out = DirectionConfig(
        rate=300,
        bits_per_char=11,
        delay=2.5,
        jitter=0.01,
        loss=1e-3,
        byte_error_rate=2e-4,
        noise=1e-5,
        burst=GilbertElliott(p_good_to_bad=1e-4, p_bad_to_good=0.1, error_bad=0.7, drop=True),
        outages=(Outage(10, 12.5), Outage(40, 41)),
        faults=(
            ScriptedFault(FaultAction.DROP, packet=3, starts_with=b"\x01??Y", wildcard=ord("?")),
            ScriptedFault(FaultAction.INSERT, byte=100, data=b'"\\\x7f\xff'),
        ),
    )
    back = DirectionConfig(rate=9600, burst=GilbertElliott(p_good_to_bad=1e-3, p_bad_to_good=0.5))
    config = LinkConfig(a_to_b=out, b_to_a=back, seed=5)
    text = config.to_toml()
    assert "[a_to_b]" in text
    assert "[b_to_a]" in text
    assert LinkConfig.from_toml(text) == config


def test_flag_names_are_keys() -> None:
    config = LinkConfig.from_toml(
        '[both]\nrate = 2400\nbits = 11\nber = 1e-4\nburst = "5e-5:0.05:0.3"\n'
        'outage = ["10:20", [30, 31]]\n'
    )
    d = config.a_to_b
    assert (d.rate, d.bits_per_char, d.byte_error_rate) == (2400, 11, 1e-4)
    assert d.burst == GilbertElliott(p_good_to_bad=5e-5, p_bad_to_good=0.05, error_bad=0.3)
    assert d.outages == (Outage(10, 20), Outage(30, 31))
    dashed = LinkConfig.from_toml("[both]\nbyte-error-rate = 1e-4\nbits-per-char = 11\n")
    assert dashed.a_to_b.byte_error_rate == 1e-4
    assert dashed.a_to_b.bits_per_char == 11


def test_one_setting_under_two_names_is_refused() -> None:
    with pytest.raises(ConfigError, match="gives byte_error_rate twice"):
        LinkConfig.from_toml("[both]\nber = 1e-4\nbyte_error_rate = 1e-3\n")


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ('[both]\nburst = "0.1"', "burst wants"),
        ('[both]\noutage = ["5"]', "T1:T2"),
        ('[both]\noutage = ["5:1"]', "outage.end must be > outage.start"),
        ("[both]\nrats = 1", "the keys are the command-line flag names"),
    ],
)
def test_bad_flag_style_values_are_config_errors(text: str, words: str) -> None:
    with pytest.raises(ConfigError, match=words):
        LinkConfig.from_toml(text)


def test_relay_write_config_writes_what_the_flags_describe(
    tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "line.toml"
    argv = ["relay", "--preset", "moon", "--ber", "1e-5", "--outage", "5:6", "--seed", "3"]
    assert main([*argv, "--write-config", str(path)]) == 0
    text = path.read_text()
    assert text.startswith("# telelink line configuration")
    expected = LinkConfig.symmetric(
        DirectionConfig(rate=9600, delay=1.3, byte_error_rate=1e-5, outages=(Outage(5, 6),)),
        seed=3,
    )
    assert LinkConfig.from_toml(path) == expected
    capsys.readouterr()
    # Never over a file that exists (it may be the user's edited copy).
    assert main([*argv, "--write-config", str(path)]) == 1
    assert "not overwriting" in capsys.readouterr().err
    assert path.read_text() == text


def test_write_config_dash_is_stdout_and_nothing_else(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["relay", "--preset", "noisy-moon", "--write-config", "-"]) == 0
    out, err = capsys.readouterr()
    assert LinkConfig.from_toml(out) == LinkConfig.preset("noisy-moon")
    assert err == ""


def test_arm_server_write_world_writes_the_world_it_would_run(
    tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "world.toml"
    assert main(["arm-server", "--write-world", str(path)]) == 0
    text = path.read_text()
    assert "# six joint angles at start, rad" in text
    assert WorldConfig.from_toml(path) == DEFAULT_WORLD
    # A --world file given is what is written back (edited, then round-tripped).
    edited = tmp_path / "edited.toml"
    edited.write_text(text.replace("weigh_time = 0.5", "weigh_time = 1.5"))
    assert main(["arm-server", "--world", str(edited), "--write-world", "-"]) == 0
    out = capsys.readouterr().out
    assert WorldConfig.from_toml(out).weigh_time == 1.5


def test_world_and_plot_read_stdin_as_dash(
    tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--world -`` and ``linksim plot -`` read stdin (a pipe from --write-world or a log)."""
    world = DEFAULT_WORLD.to_toml().replace("weigh_time = 0.5", "weigh_time = 0.75")
    monkeypatch.setattr("sys.stdin", io.StringIO(world))
    out = tmp_path / "w.toml"
    assert main(["arm-server", "--world", "-", "--write-world", str(out)]) == 0
    assert WorldConfig.from_toml(out).weigh_time == 0.75
    pytest.importorskip("matplotlib")
    log = tmp_path / "run.jsonl"
    assert main(["console", "--virtual", "--preset", "clean", "--plain", "--log", str(log)]) == 0
    monkeypatch.setattr("sys.stdin", io.StringIO(log.read_text()))
    png = tmp_path / "run.png"
    assert main(["plot", "-", "--out", str(png)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"
    capsys.readouterr()
