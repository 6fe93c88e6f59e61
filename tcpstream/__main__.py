"""``python -m tcpstream``: see :mod:`tcpstream._cli`."""

import sys

from ._cli import main

sys.exit(main())
