"""``python -m linksim``: see :mod:`linksim._cli`."""

import sys

from ._cli import main

sys.exit(main())
