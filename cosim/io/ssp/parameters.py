"""Parameter bindings of an SSP archive: parameter sets (``.ssv`` files or inline), each through its binding's
parameter mapping (``.ssm``: a mapped name goes to the entry's targets through its linear, boolean, integer or
enumeration transformation; an unmapped name stays as it is), for a component and for the system (its
``Component.parameter`` names, the longest component name that fits)."""

from __future__ import annotations

import zipfile
from dataclasses import replace
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

from ...errors import shown
from .archive import component_fmu, member_path, parse_xml, read_member
from .spec import NS, PARAMETER_MAPPING_TYPE, PARAMETER_SET_TYPE, SspError, qname, warn
from .units import Quantity, merged_units, unit_table

__all__ = ["component_bindings", "system_bindings"]


def _value(kind: str, text: str | None, ssp: Path, where: str) -> Any:
    if text is None:
        # Refused (correctness): no value to set: the FMU's own start would run silently
        raise SspError(ssp, f"{where}: ssv:{kind} has no value attribute")
    try:
        if kind == "Real":
            return float(text)
        if kind == "Integer":
            return int(text)
        if kind == "Boolean":
            if text.strip() in ("true", "1"):
                return True
            if text.strip() in ("false", "0"):
                return False
            # Refused (correctness): no Boolean of SSP's (caught below, named as not a valid value)
            raise ValueError(text)
        return text
    except ValueError:
        # Refused (correctness): the value the file means cannot be read
        raise SspError(ssp, f"{where}: {shown(repr(text))} is not a valid {kind} value") from None


def _parameter_set(pset: ET.Element, ssp: Path, where: str, prefix: str,
                   ssd_units: dict[str, tuple] | None = None) -> dict[str, Any]:
    if pset.tag != qname("ssv", "ParameterSet"):
        # Refused (correctness): not a parameter set: its values cannot be read
        raise SspError(ssp, f"{where}: expected an ssv:ParameterSet, found {pset.tag}")
    units = merged_units(ssd_units or {}, unit_table(pset, "ssv:Units/ssc:Unit", ssp, where), ssp, where)
    values: dict[str, Any] = {}
    for p in pset.iterfind("ssv:Parameters/ssv:Parameter", NS):
        pname = p.get("name")
        if not pname:
            # Refused (correctness): a value for nothing: where it belongs is a guess
            raise SspError(ssp, f"{where}: a parameter without a name")
        for kind in ("Real", "Integer", "Boolean", "String"):
            typed = p.find(f"ssv:{kind}", NS)
            if typed is not None:
                value = _value(kind, typed.get("value"), ssp, f"{where}: parameter {pname}")
                if kind == "Real" and typed.get("unit"):
                    value = Quantity(value, typed.get("unit"), units.get(typed.get("unit")),
                                      f"{where}: parameter {pname}")
                if prefix + pname in values:  # which one would be meant: refused, not the last one silently
                    # Refused (correctness): which value is meant is a guess (the last one won silently)
                    raise SspError(ssp, f"{where}: parameter {pname} is given twice")
                values[prefix + pname] = value
                break
        else:
            found = [child.tag.rsplit("}", 1)[-1] for child in p]
            # Refused (correctness): an Enumeration or Binary value would be dropped: the FMU's own start would run
            raise SspError(ssp, f"{where}: parameter {pname}: type {', '.join(found) or '(none)'} is not "
                                "supported (Real, Integer, Boolean, String)")
    return values


def _mapping(b: ET.Element, zf: zipfile.ZipFile, ssp: Path, where: str) -> tuple[str, dict[str, list]]:
    """The ``ssd:ParameterMapping`` of binding ``b``: (its file or "inline", parameter name -> [(target,
    transformation element or None)]); no mapping: ("", {})."""
    pm = b.find("ssd:ParameterMapping", NS)
    if pm is None:
        return "", {}
    mtype = pm.get("type", PARAMETER_MAPPING_TYPE)
    if mtype != PARAMETER_MAPPING_TYPE:
        # Refused (correctness): a mapping we cannot read: values would reach the wrong names
        raise SspError(ssp, f"{where}: parameter mapping of type {mtype!r} is not supported (only "
                            f"{PARAMETER_MAPPING_TYPE})")
    if pm.get("source") is not None:
        what = member_path("", pm.get("source"), ssp, f"{where}: parameter mapping")
        try:
            root = parse_xml(read_member(zf, what, ssp), ssp, what)
        except KeyError:
            # Refused (correctness): the mapping is missing: values would reach the wrong names
            raise SspError(ssp, f"{where}: parameter mapping source {what} is not in the archive") from None
    else:
        what, root = "inline parameter mapping", pm.find("ssm:ParameterMapping", NS)
        if root is None:
            # Refused (correctness): an empty mapping element: values would reach the wrong names
            raise SspError(ssp, f"{where}: ssd:ParameterMapping has neither a source nor an ssm:ParameterMapping")
    if root.tag != qname("ssm", "ParameterMapping"):
        # Refused (correctness): not a mapping: values would reach the wrong names
        raise SspError(ssp, f"{what}: expected an ssm:ParameterMapping, found {root.tag}")
    entries: dict[str, list] = {}
    skipped: list[str] = []
    for e in root.iterfind("ssm:MappingEntry", NS):
        src, dst = e.get("source"), e.get("target")
        if src is None or dst is None:  # required attributes missing: no tool could say what is meant (correctness)
            # Refused (correctness): required attributes missing: no tool could say what is meant
            raise SspError(ssp, f"{what}: a MappingEntry without source or target")
        if not src or not dst:  # OMSimulator's example writes source="": it maps nothing, as OMSimulator reads it
            skipped.append(f"{src!r} -> {dst!r}")
            continue
        transforms = [c for c in e if c.tag.startswith(f"{{{NS['ssc']}}}")]
        known = [c for c in transforms if c.tag.rsplit("}", 1)[1] in _TRANSFORMATIONS]
        if len(known) != len(transforms) or len(known) > 1:
            found = ", ".join(c.tag.rsplit("}", 1)[1] for c in transforms)
            # Refused (correctness): the value would be set untransformed
            raise SspError(ssp, f"{what}: mapping {src} -> {dst}: transformation {found} is not supported (one of "
                                f"{', '.join(_TRANSFORMATIONS)})")
        entries.setdefault(src, []).append((dst, known[0] if known else None))
    if skipped:
        warn(ssp, f"{what}: {len(skipped)} MappingEntry with an empty source or target ({', '.join(skipped[:3])}"
                  f"{', ...' if len(skipped) > 3 else ''}) map nothing, as OMSimulator reads them")
    return what, entries


_TRANSFORMATIONS = ("LinearTransformation", "BooleanMappingTransformation", "IntegerMappingTransformation",
                    "EnumerationMappingTransformation")


def _transform(value: Any, tr: ET.Element | None, ssp: Path, where: str) -> Any:
    """``value`` through an SSP 1.0 transformation (ssc:LinearTransformation: factor * value + offset; the
    mapping transformations: the ssc:MapEntry whose source is the value)."""
    if tr is None:
        return value
    kind = tr.tag.rsplit("}", 1)[1]
    if isinstance(value, Quantity):  # the transformation maps the number; the unit stays the set's
        if kind != "LinearTransformation":
            # Refused (correctness): the unit would no longer say what the mapped number is
            raise SspError(ssp, f"{where}: a {kind} cannot map a Real value with a unit ({value.unit})")
        return replace(value, value=_transform(value.value, tr, ssp, where))
    if kind == "LinearTransformation":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            # Refused (correctness): no linear transformation of that value exists
            raise SspError(ssp, f"{where}: a LinearTransformation needs a Real or Integer value, got {value!r}")
        try:
            factor, offset = float(tr.get("factor", "1")), float(tr.get("offset", "0"))
        except ValueError:
            # Refused (correctness): the transformed value would be a guess
            raise SspError(ssp, f"{where}: LinearTransformation factor/offset are not numbers") from None
        out = factor * value + offset
        return out if isinstance(value, float) or out != int(out) else int(out)
    text = ("true" if value else "false") if isinstance(value, bool) else str(value)
    for m in tr.iterfind("ssc:MapEntry", NS):
        source = m.get("source", "")
        if source == text or (kind == "BooleanMappingTransformation" and _bool_text(source) == value):
            target = m.get("target", "")
            return _bool_text(target) if kind == "BooleanMappingTransformation" else _int_text(target, ssp, where)
    # Refused (correctness): the value the mapping gives is unknown
    raise SspError(ssp, f"{where}: {kind} has no MapEntry for the value {shown(repr(text))}")


def _bool_text(text: str) -> bool | None:
    return {"true": True, "1": True, "false": False, "0": False}.get(text.strip())


def _int_text(text: str, ssp: Path, where: str) -> int:
    try:
        return int(text)
    except ValueError:
        # Refused (correctness): the mapped value cannot be read
        raise SspError(ssp, f"{where}: MapEntry target {shown(repr(text))} is not an integer") from None


def _binding_values(el: ET.Element, zf: zipfile.ZipFile, ssp: Path, where: str,
                    units: dict[str, tuple]) -> list[tuple[str, Any, str]]:
    """(name, value, file) of every parameter the ``ssd:ParameterBindings`` under ``el`` give, in order, each
    through its binding's parameter mapping (a mapped name takes the mapping's targets; an unmapped name stays)
    and prefix. ``units``: the SSD's unit definitions (a set's own ``ssv:Units`` come first)."""
    out: list[tuple[str, Any, str]] = []
    for b in el.iterfind("ssd:ParameterBindings/ssd:ParameterBinding", NS):
        btype = b.get("type", PARAMETER_SET_TYPE)
        if btype != PARAMETER_SET_TYPE:
            # Refused (correctness): a binding we cannot read: its values would be dropped
            raise SspError(ssp, f"{where}: parameter binding of type {btype!r} is not supported "
                                f"(only {PARAMETER_SET_TYPE})")
        mapping_file, mapping = _mapping(b, zf, ssp, where)
        prefix = b.get("prefix", "")
        source = b.get("source")
        sets: list[tuple[str, dict[str, Any]]] = []
        if source is not None:
            member = member_path("", source, ssp, f"{where}: parameter binding")
            try:
                data = read_member(zf, member, ssp)
            except KeyError:
                # Refused (correctness): the set is missing: its values would be dropped
                raise SspError(ssp, f"{where}: parameter binding source {member} is not in the archive") from None
            sets.append((member, _parameter_set(parse_xml(data, ssp, member), ssp, member, "", units)))
        for pset in b.iterfind("ssd:ParameterValues/ssv:ParameterSet", NS):
            label = f"{where}: inline parameter values"
            sets.append((label, _parameter_set(pset, ssp, label, "", units)))
        for file, values in sets:
            for name, value in values.items():
                for target, tr in mapping.get(name, [(name, None)]):
                    value_out = _transform(value, tr, ssp, f"{mapping_file}: parameter {name} of {file}")
                    out.append((prefix + target, value_out, file))
    return out


def component_bindings(el: ET.Element, zf: zipfile.ZipFile, ssp: Path, comp: str, units: dict[str, tuple]) -> dict[str, Any]:
    return {name: value for name, value, _ in _binding_values(el, zf, ssp, f"component {comp!r}", units)}


def system_bindings(system: ET.Element, zf: zipfile.ZipFile, ssp: Path, components: dict[str, dict[str, Any]],
                     units: dict[str, tuple]) -> None:
    """Apply the system's own parameter bindings to the components they name (SSP 1.0: a parameter of a
    system-level set is named ``Component.parameter``; the longest component name that fits is taken, so
    names with dots need no quoting here). They come after the components' own bindings and win over them.
    A parameter that names no component, or no variable of it, is one error naming the file and the parameter."""
    names = sorted(components, key=len, reverse=True)
    for name, value, file in _binding_values(system, zf, ssp, "the system", units):
        comp = next((c for c in names if name.startswith(c + ".")), None)
        if comp is None:
            # Refused (correctness): a value the file sets would be dropped silently
            raise SspError(ssp, f"{file}: parameter {name!r} of a system-level binding names no component "
                                f"(expected Component.parameter; components: {', '.join(components)})")
        var = name[len(comp) + 1:]
        if var not in component_fmu(comp, components, ssp).variables:
            # Refused (correctness): a value the file sets would be dropped silently
            raise SspError(ssp, f"{file}: parameter {name!r}: component {comp!r} has no variable {var!r}")
        components[comp].setdefault("parameters", {})[var] = value
