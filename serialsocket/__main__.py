"""``python -m serialsocket``: see :mod:`serialsocket._cli`."""

import sys

from ._cli import main

sys.exit(main())
