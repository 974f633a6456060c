"""``python -m cosim.observers.log_writer``: the log's writer process as a new interpreter."""

import sys

from .process import main

sys.exit(main())
