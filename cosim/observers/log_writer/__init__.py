"""The run log's writer (moved into a package: see its modules)."""

from .process import *  # noqa: F403
from .process import __all__, _ForkedWriter, _SAMPLES_HELPER, _serve, os_reason  # noqa: F401
