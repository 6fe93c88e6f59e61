"""The ``linksim`` command line: argparse and exit codes only.

The one sub-package that may import every other; nothing imports it but
``linksim.__main__`` and the ``linksim`` console script.
"""

from __future__ import annotations

from ._main import build_parser, main

__all__ = [
    "build_parser",
    "main",
]
