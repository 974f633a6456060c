"""Units of recorded signals: the common ones robot recordings use, and the one conversion between them.

A unit is (dimension, factor): the value in SI is ``factor * value``. Names are case-sensitive (``mm`` is not
``Mm``); a few spellings are accepted for the same unit (``N*m``, ``N.m``, ``Nm``, ``N·m``). No unit has an offset
(temperatures are not robot signals here), so a conversion is one factor.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import RecordingError

__all__ = ["UNITS", "unit_factor", "convert", "known_unit"]

_DEG = math.pi / 180.0

UNITS: dict[str, tuple[str, float]] = {
    "": ("1", 1.0), "1": ("1", 1.0), "-": ("1", 1.0),
    "m": ("m", 1.0), "mm": ("m", 1e-3), "cm": ("m", 1e-2), "um": ("m", 1e-6), "µm": ("m", 1e-6),
    "rad": ("rad", 1.0), "deg": ("rad", _DEG), "°": ("rad", _DEG), "mrad": ("rad", 1e-3),
    "s": ("s", 1.0), "ms": ("s", 1e-3), "us": ("s", 1e-6), "µs": ("s", 1e-6), "ns": ("s", 1e-9),
    "m/s": ("m/s", 1.0), "mm/s": ("m/s", 1e-3),
    "m/s2": ("m/s2", 1.0), "m/s^2": ("m/s2", 1.0), "mm/s2": ("m/s2", 1e-3), "mm/s^2": ("m/s2", 1e-3),
    "rad/s": ("rad/s", 1.0), "deg/s": ("rad/s", _DEG), "rpm": ("rad/s", 2 * math.pi / 60.0),
    "rad/s2": ("rad/s2", 1.0), "rad/s^2": ("rad/s2", 1.0), "deg/s2": ("rad/s2", _DEG), "deg/s^2": ("rad/s2", _DEG),
    "N": ("N", 1.0), "kN": ("N", 1e3), "mN": ("N", 1e-3),
    "N*m": ("N*m", 1.0), "N.m": ("N*m", 1.0), "Nm": ("N*m", 1.0), "N·m": ("N*m", 1.0), "mN*m": ("N*m", 1e-3),
    "mNm": ("N*m", 1e-3), "kg": ("kg", 1.0), "g": ("kg", 1e-3),
}
"""Unit name -> (dimension, factor to that dimension's SI unit)."""


def known_unit(unit: str) -> bool:
    return unit.strip() in UNITS


def unit_factor(unit_from: str, unit_to: str, where: str = "") -> float:
    """The factor taking a value in ``unit_from`` to ``unit_to``; one line naming ``where`` when they do not
    convert (an unknown unit or another dimension)."""
    a, b = unit_from.strip(), unit_to.strip()
    if a == b:
        return 1.0
    prefix = f"{where}: " if where else ""
    for u in (a, b):
        if u not in UNITS:
            known = ", ".join(k for k in UNITS if k not in ("", "1", "-"))
            # Refused (correctness): a unit we do not know: the conversion would be a guess
            raise RecordingError(f"{prefix}unknown unit {u!r}; known: {known}")
    (dim_a, f_a), (dim_b, f_b) = UNITS[a], UNITS[b]
    if dim_a != dim_b:
        # Refused (correctness): no conversion connects other dimensions: the value would mean another thing
        raise RecordingError(f"{prefix}unit {a!r} does not convert to {b!r} ({dim_a} is not {dim_b})")
    return f_a / f_b


def convert(values: np.ndarray, unit_from: str, unit_to: str, where: str = "") -> np.ndarray:
    """``values`` in ``unit_from`` expressed in ``unit_to`` (a new array; the same one when the units agree)."""
    f = unit_factor(unit_from, unit_to, where)
    return values if f == 1.0 else np.asarray(values, dtype=float) * f
