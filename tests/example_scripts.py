"""The worked examples under examples/ loaded as modules by the tests that check them."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]
TABLE8_SCRIPT = ROOT / "examples" / "prototype_table8" / "table8.py"


def table8() -> ModuleType:
    """examples/prototype_table8/table8.py, the prototype paper's Table 8 against the simulation."""
    spec = importlib.util.spec_from_file_location("prototype_table8", TABLE8_SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # its dataclass looks its module up
    spec.loader.exec_module(mod)
    return mod
