"""The components of an SSP archive's system: each ``ssd:Component`` an FMU unpacked from the archive, with its
interface, its own parameter bindings and its step size hint, and its connectors checked against its FMU."""

from __future__ import annotations

import math
import posixpath
import shutil
import zipfile
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

from ...engine.names import safe_stem
from ...fmi.extract import MAX_FMU_BYTES
from .archive import component_fmu, member_path
from .parameters import component_bindings
from .spec import FMU_TYPE, INTERFACE, NS, OSP_ANNOTATION, SSD_NAME, SSP_TYPE, SspError, warn

__all__ = ["read_components"]


def read_components(elements: list[ET.Element], zf: zipfile.ZipFile, ssp: Path, workdir: Path, members: set[str],
                    options: dict[str, dict[str, Any]], units: dict[str, tuple]) -> tuple[dict, dict, dict]:
    """The system's components as scenario data (name -> its FMU unpacked into ``workdir``, its interface, its options
    from our annotation, the parameters of its own bindings), their connectors (name -> connector -> (kind, unit)),
    checked against their FMUs, and their step size hints (``osp:StepSizeHint``, s). ``units``: the SSD's unit
    definitions."""
    components: dict[str, dict[str, Any]] = {}
    connectors: dict[str, dict[str, tuple]] = {}  # component -> connector name -> (kind, unit or None)
    hints: dict[str, float] = {}
    for el in elements:
        name, comp = _component(el, zf, ssp, workdir, members, components)
        comp.update(options.get(name, {}))
        params = component_bindings(el, zf, ssp, name, units)
        if params:
            comp["parameters"] = params
        hint = step_hint(el, ssp, name)
        if hint is not None:
            hints[name] = hint
        connectors[name] = {c.get("name", ""): (c.get("kind", ""), _connector_unit(c))
                            for c in el.iterfind("ssd:Connectors/ssd:Connector", NS)}
        components[name] = comp
    if not components:
        # Refused (correctness): nothing to run
        raise SspError(ssp, f"{SSD_NAME}: the system has no components")
    for el in elements:
        check_connectors(el, components, ssp)
    return components, connectors, hints


def _connector_unit(connector: ET.Element) -> str | None:
    """The unit an ``ssd:Connector`` declares for its Real (``ssc:Real unit``), None if none."""
    real = connector.find("ssc:Real", NS)
    return (real.get("unit") or None) if real is not None else None


def _component(el: ET.Element, zf: zipfile.ZipFile, ssp: Path, workdir: Path, members: set[str],
               components: dict[str, dict[str, Any]]) -> tuple[str, dict[str, Any]]:
    """One ``ssd:Component`` after ``components``: its name, and its FMU unpacked (its path) with its interface."""
    tag = el.tag.rsplit("}", 1)[-1]
    if tag != "Component":
        # Refused (correctness): the elements inside would be left out of the run
        raise SspError(ssp, f"{SSD_NAME}: ssd:{tag} {el.get('name', '')!r}: nested systems and signal "
                            "dictionaries are not supported (only FMU components)")
    name = el.get("name")
    if not name:
        # Refused (correctness): nothing could name its signals
        raise SspError(ssp, f"{SSD_NAME}: a component without a name")
    if name in components:
        # Refused (correctness): which one a connection or a binding means is a guess
        raise SspError(ssp, f"{SSD_NAME}: two components named {name!r}")
    ctype = el.get("type", FMU_TYPE)
    if ctype != FMU_TYPE:
        # Refused (correctness): only an FMU can run here: the component would be missing
        raise SspError(ssp, f"component {name!r}: type {ctype!r} is not supported (only FMUs, {FMU_TYPE})")
    source = el.get("source")
    if not source:
        # Refused (correctness): no FMU to run: the component would be missing
        raise SspError(ssp, f"component {name!r}: no source attribute")
    member = member_path("", source, ssp, f"component {name!r}")
    if member not in members:
        # Refused (correctness): no FMU to run: the component would be missing
        raise SspError(ssp, f"component {name!r}: its FMU {member} is not in the archive")
    impl = el.get("implementation", "any")
    if impl not in INTERFACE:
        # Refused (correctness): not an SSP value: which interface is meant is a guess
        raise SspError(ssp, f"component {name!r}: implementation {impl!r} is not supported "
                            f"({', '.join(INTERFACE)})")
    # the component's name is the SSD's to choose and never a path here: each FMU goes to a folder
    # numbered by its place in the system (a name such as "../../x" wrote outside the work folder)
    stem = posixpath.splitext(posixpath.basename(member))[0]
    target = workdir / "fmus" / f"{len(components):04d}" / f"{safe_stem(stem, 'component')}.fmu"
    if zf.getinfo(member).file_size > MAX_FMU_BYTES:  # read no further than declared: this bounds it
        # Refused (security): a zip bomb: bounded before it is unpacked
        raise SspError(ssp, f"component {name!r}: its FMU {member} unpacks to more than "
                            f"{MAX_FMU_BYTES:,} bytes: refused")
    target.parent.mkdir(parents=True, exist_ok=True)
    with zf.open(member) as src, open(target, "wb") as dst:
        shutil.copyfileobj(src, dst)
    comp: dict[str, Any] = {"path": str(target)}
    if impl != "any":
        comp["interface"] = INTERFACE[impl]
    return name, comp


_CONNECTOR_KINDS = ("input", "output", "inout", "parameter", "calculatedParameter")


def check_connectors(el: ET.Element, components: dict[str, dict[str, Any]], ssp: Path) -> None:
    """A component's connectors as its FMU declares them: an input or an output where the FMU variable is one, and
    its type (a connector declared Boolean on a Real variable, or an output on an input, was taken as the FMU's).
    A kind SSP does not know is one warning per component and kind (the FMU's variable decides, as in libcosim)."""
    name = el.get("name")
    info = None
    odd: dict[str, list[str]] = {}  # a kind SSP does not know -> its connectors
    for c in el.iterfind("ssd:Connectors/ssd:Connector", NS):
        cname, kind = c.get("name", ""), c.get("kind", "")
        label = f"component {name!r}: connector {cname!r}"
        if kind not in _CONNECTOR_KINDS:  # libcosim stores the kind unchecked; the FMU's causality decides here too
            odd.setdefault(kind, []).append(cname)
        info = info or component_fmu(name, components, ssp)
        var = info.variables.get(cname)
        if var is None:  # named in a connection later, or never used
            continue
        if kind in ("input", "output") and var.causality in ("input", "output") and kind != var.causality:
            # Refused (correctness): the file says two things of one signal: it may have been written for another FMU
            raise SspError(ssp, f"{label}: declared an {kind}, but its FMU's variable {cname} is an {var.causality}")
        declared = next((child.tag.rsplit("}", 1)[-1] for child in c if child.tag.startswith("{" + NS["ssc"] + "}")),
                        None)
        want = SSP_TYPE.get(var.fmi_type)
        if declared in ("Real", "Integer", "Boolean", "String") and want is not None and declared != want:
            # Refused (correctness): the file says two things of one signal: it may have been written for another FMU
            raise SspError(ssp, f"{label}: declared {declared}, but its FMU's variable {cname} is {var.fmi_type}")
    for kind, names in odd.items():
        listed = ", ".join(map(repr, names[:3])) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
        warn(ssp, f"component {name!r}: connector{'s' if len(names) > 1 else ''} {listed}: kind {kind!r} is not an "
                  f"SSP connector kind ({', '.join(_CONNECTOR_KINDS)}): its FMU's variable decides")


def step_hint(el: ET.Element, ssp: Path, comp: str) -> float | None:
    for ann in el.iterfind("ssd:Annotations/ssc:Annotation", NS):
        if ann.get("type") == OSP_ANNOTATION:
            hint = ann.find("osp:StepSizeHint", NS)
            if hint is not None:
                try:
                    value = float(hint.get("value", ""))
                except ValueError:
                    # Refused (correctness): no step multiple follows from it
                    raise SspError(ssp, f"component {comp!r}: osp:StepSizeHint value {hint.get('value')!r} is "
                                        "not a number") from None
                if not math.isfinite(value):
                    # Refused (correctness): no step multiple follows from it
                    raise SspError(ssp, f"component {comp!r}: osp:StepSizeHint value {value} is not finite")
                return value
    return None
