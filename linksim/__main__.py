"""``python -m linksim``: see :mod:`linksim.cli`."""

import sys

from .cli import main

sys.exit(main())
