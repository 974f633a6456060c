"""``python -m cosim``: see :mod:`cosim.cli`."""

import sys

from .cli import main

sys.exit(main())
