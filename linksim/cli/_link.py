"""The line options every ``linksim`` command that builds a link shares, and the
:class:`~linksim.link.LinkConfig` they describe."""

from __future__ import annotations

import argparse
import dataclasses
import pathlib
from typing import Any

from linksim._errors import ConfigError
from linksim.link import PRESETS, DirectionConfig, GilbertElliott, LinkConfig, Outage

from ._args import BIT_RATE, BITS_PER_CHAR, DELAY, PROBABILITY, SEED

__all__ = ["add_link_arguments", "config_from_args"]


def _outage(text: str) -> Outage:
    try:
        return Outage.parse(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _burst(text: str) -> GilbertElliott:
    try:
        return GilbertElliott.parse(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_link_arguments(ap: argparse.ArgumentParser, *, default_preset: str = "clean") -> None:
    """Options that describe the line (shared by relay and benchmarks).

    ``default_preset`` only names, in the help, the preset the command uses
    when neither ``--preset`` nor ``--config`` is given."""
    g = ap.add_argument_group("line (applied to both directions, over --preset or --config)")
    g.add_argument("--preset", choices=PRESETS, help=f"named preset (default: {default_preset})")
    g.add_argument("--config", type=pathlib.Path, help="TOML file (see LinkConfig.from_toml)")
    g.add_argument("--seed", type=SEED, help="RNG seed (default 0)")
    g.add_argument("--rate", type=BIT_RATE, help="line rate, bit/s")
    g.add_argument(
        "--bits", type=BITS_PER_CHAR, dest="bits_per_char", help="bits per character (8N1 = 10)"
    )
    g.add_argument("--delay", type=DELAY, help="one-way delay, s")
    g.add_argument("--jitter", type=DELAY, help="order-preserving jitter, s (uniform 0..J)")
    g.add_argument("--loss", type=PROBABILITY, help="byte loss probability")
    g.add_argument(
        "--ber",
        "--byte-error-rate",
        type=PROBABILITY,
        dest="byte_error_rate",
        help="byte error rate",
    )
    g.add_argument("--noise", type=PROBABILITY, help="probability of a noise byte after each byte")
    g.add_argument("--burst", type=_burst, help="Gilbert-Elliott P_GB:P_BG[:E_BAD[:E_GOOD]]")
    g.add_argument(
        "--outage", type=_outage, action="append", dest="outages", help="T1:T2 (repeatable)"
    )


def config_from_args(args: argparse.Namespace) -> LinkConfig:
    """The LinkConfig the options describe (raises ConfigError on bad values)."""
    if args.config is not None:
        if args.preset is not None:
            raise ConfigError("give --preset or --config, not both (a TOML file can name a preset)")
        config = LinkConfig.from_toml(args.config)
    else:
        config = LinkConfig.preset(args.preset or "clean")
    names = [f.name for f in dataclasses.fields(DirectionConfig)]
    overrides: dict[str, Any] = {
        n: getattr(args, n) for n in names if getattr(args, n, None) is not None
    }
    if "outages" in overrides:
        overrides["outages"] = tuple(overrides["outages"])
    return LinkConfig(
        a_to_b=dataclasses.replace(config.a_to_b, **overrides),
        b_to_a=dataclasses.replace(config.b_to_a, **overrides),
        seed=config.seed if args.seed is None else args.seed,
    )
