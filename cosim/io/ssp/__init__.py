"""SSP 1.0 export and import (moved into a package: see its modules)."""

from .read import *  # noqa: F403
from .read import MAX_FMU_BYTES, MAX_XML_BYTES, __all__  # noqa: F401
