"""Number namespaces: the functions the formulas of :mod:`delta` call, for floats, numpy arrays (and, in
``fmus.native``, CasADi symbols). One formula, several number types (see :data:`SCALAR`)."""

from __future__ import annotations

import math
from types import ModuleType

import numpy as np

__all__ = ["SCALAR", "ARRAY", "namespace"]


def namespace(name: str, **functions: object) -> ModuleType:
    """A module object holding ``functions``: its attributes are looked up as fast as globals."""
    module = ModuleType(name)
    module.__dict__.update(functions)
    return module


def _check(ok, reason):  # noqa: ANN001, ANN202
    """``ok`` itself: on numbers the caller branches on it (see :data:`SCALAR`)."""
    return ok


def _where_scalar(cond, a, b):  # noqa: ANN001, ANN202
    return a if cond else b


SCALAR = namespace("delta.scalar_math", cos=math.cos, sin=math.sin, sqrt=math.sqrt, atan2=math.atan2,
                    acos=math.acos, maximum=max, minimum=min, both=lambda a, b: a and b,
                    where=_where_scalar, check=_check, isfinite=math.isfinite, symbolic=False)
"""Functions of ``math`` for one pose on plain floats.

Besides the functions, a number namespace gives the per-pose algorithms what a branch on a computed
value needs, so that the same code also runs on symbols (``fmus.native`` traces it to C):

* ``where(cond, a, b)``: ``a if cond else b`` (both are evaluated; neither may raise);
* ``check(ok, reason)``: a condition the algorithm needs to continue on its valid path, with its
  ``reason`` when it fails (a string, or a callable giving it). On numbers it returns ``ok`` and the
  caller branches on it (raises, or returns a fault); on symbols it records ``(ok, reason)`` for the
  generated code and returns True, so the trace follows the valid path;
* ``both(a, b)``: logical and of two conditions; ``isfinite``; ``symbolic`` (False here).
"""
ARRAY = namespace("delta.array_math", cos=np.cos, sin=np.sin, sqrt=np.sqrt, atan2=np.arctan2, acos=np.arccos,
                   maximum=np.maximum, minimum=np.minimum, both=np.logical_and, where=np.where,
                   check=_check, isfinite=np.isfinite, symbolic=False)
"""The same functions from numpy, for arrays of poses."""
