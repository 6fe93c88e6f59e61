"""Link configuration: presets, TOML, validation messages, CLI options."""

from __future__ import annotations

import dataclasses
import pathlib

import pytest

from linksim import PRESETS, ConfigError, DirectionConfig, LinkConfig, Outage
from linksim.cli import build_parser
from linksim.cli._main import config_from_args
from linksim.link import FaultAction, GilbertElliott, ScriptedFault


def test_presets_are_exactly_the_issues_list() -> None:
    assert PRESETS == ("clean", "phone-2400", "moon", "noisy-moon", "geo", "mars")
    assert LinkConfig.preset("clean") == LinkConfig()
    phone = LinkConfig.preset("phone-2400").a_to_b
    assert (phone.rate, phone.byte_error_rate, phone.delay) == (2400, 1e-5, 0.05)
    moon = LinkConfig.preset("moon", seed=4)
    assert (moon.a_to_b.delay, moon.a_to_b.rate, moon.seed) == (1.3, 9600, 4)
    noisy = LinkConfig.preset("noisy-moon").b_to_a
    assert (noisy.delay, noisy.rate, noisy.byte_error_rate) == (1.3, 2400, 1e-4)
    assert noisy.burst == GilbertElliott(5e-5, 0.05, error_bad=0.3)
    assert LinkConfig.preset("geo").a_to_b == DirectionConfig(delay=0.27)
    mars = LinkConfig.preset("mars").a_to_b
    assert (mars.delay, mars.rate, mars.byte_error_rate) == (1200.0, 2400, 1e-4)
    with pytest.raises(ConfigError, match="preset must be one of clean, phone-2400"):
        LinkConfig.preset("jupiter")


def test_configs_are_frozen_and_slotted() -> None:
    config = DirectionConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.delay = 1.0  # type: ignore[misc]
    assert not hasattr(config, "__dict__")
    assert config.char_time == 0.0
    assert DirectionConfig(rate=2400).char_time == 10 / 2400


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"loss": 1.5}, r"loss must be a probability in \[0, 1\], got 1.5"),
        ({"byte_error_rate": -0.1}, "byte_error_rate must be a probability"),
        ({"rate": 0}, "rate must be a finite number of bit/s > 0"),
        ({"bits_per_char": 0}, r"bits_per_char must be an integer in \[1, 64\]"),
        ({"delay": -1}, "delay must be a finite number >= 0"),
        ({"jitter": float("nan")}, "jitter must be a finite number >= 0"),
    ],
)
def test_validation_names_field_and_range(kwargs: dict[str, float], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        DirectionConfig(**kwargs)  # type: ignore[arg-type]


def test_nested_validation() -> None:
    with pytest.raises(ConfigError, match=r"burst.p_bad_to_good must be in \(0, 1\]"):
        GilbertElliott(0.1, 0.0)
    with pytest.raises(ConfigError, match=r"outage\.end must be > outage\.start"):
        Outage(3.0, 2.0)
    with pytest.raises(ConfigError, match="exactly one target"):
        ScriptedFault(FaultAction.DROP)
    with pytest.raises(ConfigError, match="begin with a literal byte"):
        ScriptedFault(FaultAction.DROP, packet=1, starts_with=b"?Y", wildcard=ord("?"))
    with pytest.raises(ConfigError, match="seed must be an integer >= 0"):
        LinkConfig(seed=-1)
    assert issubclass(ConfigError, ValueError)


TOML = """
preset = "moon"
seed = 42

[both]
loss = 0.001

[a_to_b]
jitter = 0.05
outages = [[10, 12.5]]
burst = { p_good_to_bad = 0.001, p_bad_to_good = 0.2, error_bad = 0.4 }

[[a_to_b.faults]]
action = "drop"
packet = 3
starts_with = "\\u0001"

[[a_to_b.faults]]
action = "insert"
byte = 1000
data = "noise"

[b_to_a]
delay = 2.0
"""


def test_from_toml_text_and_file(tmp_path: pathlib.Path) -> None:
    config = LinkConfig.from_toml(TOML)
    assert config.seed == 42
    ab, ba = config.a_to_b, config.b_to_a
    assert (ab.rate, ab.delay, ab.loss, ab.jitter) == (9600, 1.3, 0.001, 0.05)
    assert ab.outages == (Outage(10.0, 12.5),)
    assert ab.burst == GilbertElliott(0.001, 0.2, error_bad=0.4)
    assert ab.faults == (
        ScriptedFault(FaultAction.DROP, packet=3, starts_with=b"\x01"),
        ScriptedFault(FaultAction.INSERT, byte=1000, data=b"noise"),
    )
    assert (ba.rate, ba.delay, ba.loss, ba.faults) == (9600, 2.0, 0.001, ())
    path = tmp_path / "link.toml"
    path.write_text(TOML)
    assert LinkConfig.from_toml(path) == config


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("colour = 1", "unknown top-level key"),
        ("[both]\nspeed = 1", r"unknown key 'speed' in \[both\]"),
        ("[both]\nloss = 2", "loss must be a probability"),
        ("[[both.faults]]\naction = 'explode'\nbyte = 1", "action must be drop, corrupt or insert"),
        ("[both]\noutages = [[1]]", "outages must be a list of"),
        ("not toml [", "invalid TOML"),
    ],
)
def test_toml_errors(text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        LinkConfig.from_toml(text)


def test_cli_options_override_preset() -> None:
    args = build_parser().parse_args(
        [
            *("relay", "--preset", "noisy-moon", "--delay", "0.5", "--outage", "1:2"),
            *("--seed", "9", "--ber", "0.01", "--burst", "0.01:0.1:1"),
        ]
    )
    config = config_from_args(args)
    assert config.seed == 9
    assert config.a_to_b == config.b_to_a
    d = config.a_to_b
    assert (d.rate, d.delay, d.byte_error_rate) == (2400, 0.5, 0.01)
    assert d.outages == (Outage(1.0, 2.0),)
    assert d.burst == GilbertElliott(0.01, 0.1, error_bad=1.0)
