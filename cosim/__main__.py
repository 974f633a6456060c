"""``python -m cosim``: see :mod:`cosim.cli`."""

import sys

from .cli import main

if __name__ == "__main__":  # also imported by multiprocessing's spawned workers
    sys.exit(main())
