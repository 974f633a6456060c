"""Units of an SSP archive: the unit definitions an export writes (from the FMUs' own), and a parameter value given
with a unit, converted to the unit of the FMU variable it is bound to."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

from .archive import component_fmu
from .spec import NS, SspError, num_text

__all__ = ["Quantity", "convert_units", "merged_units", "unit_definitions", "unit_table"]


BASE_UNITS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


@dataclass(frozen=True)
class Quantity:
    """A Real parameter value with the unit its parameter set gives it (``ssv:Real unit``), converted to the unit
    of the FMU variable it is bound to once the components' FMUs are read (:func:`convert_units`). ``base``: the
    unit's definition (base-unit exponents, factor, offset: value in SI = factor * value + offset) from the set's
    ``ssv:Units`` or the SSD's ``ssd:Units``; None when neither defines it. ``where``: file and parameter."""

    value: float
    unit: str
    base: tuple[tuple[int, ...], float, float] | None
    where: str


def unit_table(parent: ET.Element | None, path: str, ssp: Path, where: str) -> dict[str, tuple]:
    """``ssc:Unit`` definitions under ``parent`` (``ssv:Units`` or ``ssd:Units``): name -> (exponents, factor,
    offset)."""
    out: dict[str, tuple] = {}
    for u in (parent.iterfind(path, NS) if parent is not None else ()):
        base = u.find("ssc:BaseUnit", NS)
        attrs = base.attrib if base is not None else {}
        name = u.get("name", "")
        try:
            factor, offset = float(attrs.get("factor", "1")), float(attrs.get("offset", "0"))
            unit = (tuple(int(attrs.get(k, "0")) for k in BASE_UNITS), factor, offset)
        except ValueError:
            # Refused (correctness): the conversion would be a guess
            raise SspError(ssp, f"{where}: unit {name!r}: its BaseUnit attributes are not numbers") from None
        if not conversion_ok(factor, offset):
            # Refused (correctness): no conversion through it exists (x 0, inf, nan)
            raise SspError(ssp, f"{where}: unit {name!r}: BaseUnit factor {factor!r}, offset {offset!r}: a "
                                "unit needs a finite factor other than 0 and a finite offset")
        _same_unit(out, name, unit, ssp, where)
        out[name] = unit
    return out


def _same_unit(known: dict[str, tuple], name: str, unit: tuple, ssp: Path, where: str) -> None:
    """Refuse a second definition of ``name`` that differs from the first (correctness: which one a value is
    converted with would be a guess; 1500 mm reached an FMU as 1 500 000 when the last one won)."""
    if name in known and known[name] != unit:
        (e1, f1, o1), (e2, f2, o2) = known[name], unit
        # Refused (correctness): which definition a value is converted with would be a guess
        raise SspError(ssp, f"{where}: unit {name!r} is defined twice, differently (factor {f1!r} then {f2!r}, offset "
                            f"{o1!r} then {o2!r}{', other base units' if e1 != e2 else ''}): give it one definition")


def merged_units(outer: dict[str, tuple], inner: dict[str, tuple], ssp: Path, where: str) -> dict[str, tuple]:
    """The unit definitions of a parameter set (``inner``) added to the system's (``outer``); a name both define
    differently is refused (:func:`_same_unit`)."""
    out = dict(outer)
    for name, unit in inner.items():
        _same_unit(out, name, unit, ssp, where)
        out[name] = unit
    return out


def conversion_ok(factor: float, offset: float) -> bool:
    return math.isfinite(factor) and factor != 0.0 and math.isfinite(offset)


def convert_units(components: dict[str, dict[str, Any]], ssp: Path) -> None:
    """Every parameter value given with a unit (:class:`Quantity`) in the unit of the FMU variable it is bound to
    (SSP 1.0: the value in SI is ``factor * value + offset`` of its unit's BaseUnit, then back through the
    variable's unit definition in the FMU). The same unit, or a variable without a unit: the number as given.
    Units of different dimensions, or a unit defined nowhere, are one error naming the parameter."""
    for comp, data in components.items():
        params = data.get("parameters") or {}
        for var, q in list(params.items()):
            if not isinstance(q, Quantity):
                continue
            info = component_fmu(comp, components, ssp)
            v = info.variables.get(var)
            unit = None if v is None else v.unit
            if not unit or unit == q.unit:  # no variable (named later) or nothing to convert
                params[var] = q.value
                continue
            target = next((u.baseUnit for u in info.md.unitDefinitions or [] if u.name == unit), None)
            if q.base is None:
                # Refused (correctness): the value's unit is unknown: it would be set as if in the variable's
                raise SspError(ssp, f"{q.where}: unit {q.unit!r} is defined in neither the parameter set's ssv:Units "
                                    f"nor the SSD's ssd:Units: cannot convert it to {comp}.{var}'s unit {unit!r}")
            if target is None:
                # Refused (correctness): the variable's unit is unknown: the conversion would be a guess
                raise SspError(ssp, f"{q.where}: {comp}.{var} is in {unit!r}, which its FMU does not define: cannot "
                                    f"convert {q.unit!r} to it")
            exps = tuple(int(getattr(target, k, 0) or 0) for k in BASE_UNITS)
            if exps != q.base[0]:
                # Refused (correctness): no conversion connects other dimensions: the value would mean another thing
                raise SspError(ssp, f"{q.where}: unit {q.unit!r} does not convert to {comp}.{var}'s unit {unit!r} "
                                    "(other base units)")
            factor = 1.0 if target.factor is None else float(target.factor)
            offset = 0.0 if target.offset is None else float(target.offset)
            if not conversion_ok(factor, offset):
                # Refused (correctness): no conversion through it exists (x 0, inf, nan)
                raise SspError(ssp, f"{q.where}: {comp}.{var}'s unit {unit!r} has factor {factor!r}, offset {offset!r} "
                                    "in its FMU: cannot convert to it")
            params[var] = (q.base[1] * q.value + q.base[2] - offset) / factor


def unit_definitions(infos) -> dict[str, dict[str, str]]:
    """Unit name -> BaseUnit attributes (non-default exponents, factor, offset), from the FMUs."""
    out: dict[str, dict[str, str]] = {}
    for info in infos:
        for u in getattr(info.md, "unitDefinitions", None) or []:
            b = u.baseUnit
            attrs: dict[str, str] = {}
            if b is not None:
                for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad"):
                    if int(getattr(b, k, 0) or 0):
                        attrs[k] = str(int(getattr(b, k)))
                if float(b.factor) != 1.0:
                    attrs["factor"] = num_text(b.factor)
                if float(b.offset) != 0.0:
                    attrs["offset"] = num_text(b.offset)
            out.setdefault(u.name, attrs)
    return out
