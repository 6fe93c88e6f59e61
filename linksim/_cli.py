"""The ``linksim`` command: ``linksim bench codec`` (more subcommands join as they land)."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from . import _bench_codec

__all__ = ["main"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser; subcommands register here."""
    ap = argparse.ArgumentParser(prog="linksim", description="Impaired links and benchmarks.")
    sub = ap.add_subparsers(dest="command", required=True)
    bench = sub.add_parser("bench", help="benchmarks (measure speed; not tests)")
    bench_sub = bench.add_subparsers(dest="bench", required=True)
    codec = bench_sub.add_parser("codec", help="Kermit encode/decode speed")
    _bench_codec.add_arguments(codec)
    codec.set_defaults(func=_bench_codec.main)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    """Run the linksim command line; returns the exit status."""
    args = build_parser().parse_args(argv)
    status: int = args.func(args)
    return status
