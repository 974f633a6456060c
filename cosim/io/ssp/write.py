"""Export: a system structure (from a scenario, or made in code) written as an SSP 1.0 archive that any SSP tool
can run (see :mod:`cosim.io.ssp`).

The writer emits prefixed names itself (``ssd:``, ``ssc:``, ``ssv:``, ``osp:``: OSP libcosim matches element names
by their prefixes literally) instead of relying on ElementTree's namespace registry (a process-wide setting).
"""

from __future__ import annotations

import json
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any
from xml.etree import ElementTree as ET

from ...engine.names import safe_stem
from ...engine.prepare import input_files, prepare
from ...engine.structure import ComponentStructure, SystemStructure
from ...engine.wiring import index_text
from ...errors import written_by_rename
from ..output import check_output
from .spec import (COMPONENT_OPTIONS, EXTRAS, FMU_TYPE, IMPLEMENTATION, NS, OMS_ANNOTATION, OSP_ANNOTATION,
                   OUR_ANNOTATION, PARAMETER_SET_TYPE, SSD_NAME, SSP_TYPE, SspError, num_text)
from .units import unit_definitions

if TYPE_CHECKING:
    from ...engine.schema import Scenario

__all__ = ["ExportReport", "export_ssp", "write_ssp"]


@dataclass(frozen=True)
class ExportReport:
    """What :func:`write_ssp` wrote."""

    path: Path
    components: list[str]
    connections: int
    parameters: dict[str, int]  # component -> number of start values in its .ssv
    step: float
    stop: float
    events: int = 0  # the system's events, carried in our annotation only

    def as_dict(self) -> dict[str, Any]:
        return {"ssp": str(self.path), "components": self.components, "connections": self.connections,
                "parameters": self.parameters, "step_s": self.step, "stop_s": self.stop, "events": self.events}

    def text(self) -> str:
        n = sum(self.parameters.values())
        text = (f"{self.path}: {len(self.components)} components ({', '.join(self.components)}), "
                f"{self.connections} connections, {n} start values, step {self.step:g} s, stop {self.stop:g} s")
        if self.events:
            text += (f"\n  {self.events} event(s) kept in the delta-cosim annotation: SSP 1.0 cannot express values "
                     "set during a run, so other SSP tools run the system without them")
        return text


def export_ssp(system: "SystemStructure | Scenario", out: str | Path) -> ExportReport:
    """Write ``system`` (a system structure, or a scenario: its structure) as an SSP 1.0 archive at ``out`` (see
    :mod:`cosim.io.ssp`), through :func:`write_ssp`, with the sections SSP has no place for in our annotation.

    Builds our FMUs if needed and runs the pre-flight (:func:`cosim.engine.prepare.prepare`); raises
    :class:`cosim.errors.CosimError` subclasses for a bad scenario, :class:`SspError` for what SSP
    1.0 cannot express.
    """
    if not isinstance(system, SystemStructure):
        system = system.structure()
    replayed = [n for n, c in system.components.items() if c.replay is not None]
    if replayed:  # said at the scenario's line; write_ssp says it for a structure made in code
        line = system.where().line(("components", replayed[0], "recording"))
        raise SspError(f"{system.source}:{line}" if line else system.source or "<scenario>", _replaying(
            replayed[0], system.components[replayed[0]].replay.file))
    plan, _ = prepare(system)
    return write_ssp(system, plan, out, extras=_extras(system), inputs=input_files(system))


def write_ssp(structure: SystemStructure, plan, out: str | Path, *, extras: dict[str, Any] | None = None,
              inputs: tuple = ()) -> ExportReport:
    """Write the system ``structure`` (with its ``plan``: :func:`cosim.engine.system.build_plan`) as an SSP 1.0
    archive at ``out``: every component's FMU, connectors and start values, the connections, the time grid and the
    algorithm; ``extras``: our annotation's sections SSP has no place for (default: what the structure holds of
    them: its name, algorithm, what is logged, each component's options and its events); ``inputs``: files the
    archive must not replace. A structure made in code exports as one read from a scenario."""
    out = Path(out)
    for name, comp in structure.components.items():
        if comp.replay is not None:  # SSP 1.0 components are FMUs (or SSPs): a recording has no component to become
            # Refused (correctness): the archive would hold a system without that component
            raise SspError(out, _replaying(name, comp.replay.file))
    names, infos = plan.names, plan.infos
    arc_names = _archive_names(names, infos)
    start, stop, step = (structure.start_ns / 1e9, structure.stop_ns / 1e9, structure.step_ns / 1e9)
    extras = dict(extras) if extras is not None else _structure_extras(structure)
    system_name = _identifier(structure.name)  # our annotation keeps the system's name
    root = _el(None, "ssd:SystemStructureDescription", {
        "xmlns:ssd": NS["ssd"], "xmlns:ssc": NS["ssc"], "xmlns:ssv": NS["ssv"], "xmlns:osp": NS["osp"],
        "xmlns:dcs": NS["dcs"], "xmlns:oms": NS["oms"], "name": system_name, "version": "1.0",
        "description": extras.get("description") or None, "generationTool": "delta-cosim"})
    system = _el(root, "ssd:System", {"name": system_name})
    elements = _el(system, "ssd:Elements")
    # OMSimulator 3.0 types a system by its own annotation (SystemWC, its fixed-step master): without
    # it the import fails ("[NewSystem] internal error"). It reads only the first ssc:Annotation here.
    # (appended after the connections: the SSD's order)
    system_annotations = _el(None, "ssd:Annotations")
    oms = _el(_el(_el(system_annotations, "ssc:Annotation", {"type": OMS_ANNOTATION}), "oms:Annotations"),
              "oms:SimulationInformation")
    _el(oms, "oms:FixedStepMaster", {"description": "oms-ma", "stepSize": num_text(step)})
    connected = _connected(plan, out)
    ssv_files: dict[str, bytes] = {}
    n_params: dict[str, int] = {}
    stems = _member_stems(names)
    for c, name in enumerate(names):
        ssv = _component(elements, structure, plan, c, (arc_names[c], stems[c]), connected, out)
        if ssv is not None:
            ssv_files[f"resources/{stems[c]}.ssv"] = ssv
        n_params[name] = len(_start_values(plan, c))
    _connections(system, plan, arc_names)
    system.append(system_annotations)
    _units(root, infos)
    exp = _el(root, "ssd:DefaultExperiment", {"startTime": num_text(start), "stopTime": num_text(stop)})
    ann = _el(_el(exp, "ssd:Annotations"), "ssc:Annotation", {"type": OSP_ANNOTATION})
    _el(_el(ann, "osp:Algorithm"), "osp:FixedStepAlgorithm", {"baseStepSize": num_text(step)})
    # ours on the system, after OMSimulator's: OMSimulator 3.0 refuses any ssd:Annotations at the top
    # ("wrong xml schema detected"), though SSP 1.0 allows them there
    ours = _el(system_annotations, "ssc:Annotation", {"type": OUR_ANNOTATION})
    renamed = {a: n for a, n in zip(arc_names, names) if a != n}
    if renamed:
        extras["component_names"] = renamed
    _el(ours, "dcs:Scenario").text = json.dumps(extras, indent=1)
    check_output(out, (*inputs, *(info.path for info in infos)))
    with written_by_rename(out) as partial, zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr(SSD_NAME, _xml(root))
        for arc, data in ssv_files.items():
            z.writestr(arc, data)
        for stem, info in zip(stems, infos):
            z.write(info.path, f"resources/{stem}.fmu", compress_type=zipfile.ZIP_STORED)  # already deflated
    return ExportReport(out, list(names), len(plan.links), n_params, step, stop, len(structure.events))


def _replaying(name: str, file: str) -> str:
    return (f"components.{name}: replays a recording ({file}); SSP 1.0 has no such component: export a system whose "
            "components are all FMUs")


def _structure_extras(structure: SystemStructure) -> dict[str, Any]:
    """Our annotation's sections for a structure made in code: what it holds of them."""
    events = [{k: v for k, v in (("at", e.at), ("when", e.when), ("set", dict(e.set)), ("repeat", e.repeat),
                                  ("tolerance", e.tolerance)) if v is not None} for e in structure.events]
    return {"name": structure.name, "algorithm": structure.algorithm, "logging": {"signals": structure.log_signals},
            "events": events, "component_options": _component_options(structure)}


def _component_options(structure: SystemStructure) -> dict[str, dict[str, Any]]:
    """Each component's options that differ from their defaults (how the master drives it), by name."""
    defaults = ComponentStructure(None, None, {})
    options = {}
    for name, comp in structure.components.items():
        changed = {k: getattr(comp, k) for k in COMPONENT_OPTIONS if getattr(comp, k) != getattr(defaults, k)}
        if changed:
            options[name] = changed
    return options


def _connected(plan, out: Path) -> set[tuple[str, str]]:
    """(component, variable name) of every port a connection uses (prefixes expanded: ``plan.links``); a connection
    of an FMI 3 array is refused."""
    names = plan.names
    connected = {(names[port.comp], port.var.name) for link in plan.links for port in (link.src, link.dst)}
    for link in plan.links:
        for port in (link.src, link.dst):
            if port.var.is_array:
                raise SspError(out, f"connection of {port.label(names)}: FMI 3 arrays have no SSP 1.0 connector")
    return connected


def _start_values(plan, c: int) -> dict[str, Any]:
    """The start values of component ``c`` its .ssv holds (a String at the FMU's own start left out)."""
    info = plan.infos[c]
    return {k: v for k, v in plan.start_values[c].items() if not _string_at_start(info.variables[k], v)}


def _component(elements: ET.Element, structure: SystemStructure, plan, c: int, arc: tuple[str, str],
               connected: set[tuple[str, str]], out: Path) -> bytes | None:
    """Component ``c``'s ``ssd:Component`` (its connectors, its parameter binding, its step size hint) under
    ``elements``, named ``arc`` (its name in the archive, its file stem); its .ssv (None without start values)."""
    name, info = plan.names[c], plan.infos[c]
    arc_name, stem = arc
    comp = structure.components[name]
    el = _el(elements, "ssd:Component", {"name": arc_name, "type": FMU_TYPE, "source": f"resources/{stem}.fmu",
                                         "implementation": _implementation(comp.interface, info)})
    connectors = _el(el, "ssd:Connectors")
    for var in info.variables.values():
        if var.causality not in ("input", "output"):
            continue
        if var.is_array or var.fmi_type not in SSP_TYPE:
            if (name, var.name) in connected:
                raise SspError(out, f"{name}.{var.name} is {var.fmi_type}"
                                    f"{' array' if var.is_array else ''}: no SSP 1.0 connector type")
            continue
        conn = _el(connectors, "ssd:Connector", {"name": var.name, "kind": var.causality,
                                                 "description": var.description or None})
        _typed(conn, "ssc", var)
    values = _start_values(plan, c)
    # every parameter the .ssv sets is also declared, as OMSimulator's own export declares them: its
    # Python API (OMSimulator.SSP) finds a declared name as it is, and guesses an undeclared one by
    # dropping each part that is in its own path ("model.root.ctl"), so "model.w_inertia" became the
    # unknown "model.root.ctl.w_inertia" and instantiate() failed
    for vname in values:
        var = info.variables[vname]
        if var.causality == "parameter" and SSP_TYPE.get(var.fmi_type) and not var.is_array:
            _typed(_el(connectors, "ssd:Connector", {"name": vname, "kind": "parameter",
                                                     "description": var.description or None}), "ssc", var)
    if not len(connectors):
        el.remove(connectors)
    ssv = _parameter_set(name, info, values, out)
    if ssv is not None:
        bindings = _el(el, "ssd:ParameterBindings")
        _el(bindings, "ssd:ParameterBinding", {"type": PARAMETER_SET_TYPE, "source": f"resources/{stem}.ssv"})
    if comp.step_multiple != 1:
        ann = _el(_el(el, "ssd:Annotations"), "ssc:Annotation", {"type": OSP_ANNOTATION})
        _el(ann, "osp:StepSizeHint", {"value": num_text(structure.step_ns * comp.step_multiple / 1e9)})
    return ssv


def _implementation(interface: str, info) -> str | None:
    """The ``implementation`` attribute of a component run through ``interface``: none (any: the tool chooses)
    for model exchange when its FMU also offers co-simulation, our annotation keeping the choice for our master.
    OMSimulator runs every FMU of its fixed-step system through co-simulation whatever the attribute says (its
    C++ import, ``System::importFromSnapshot``); its Python API puts a model-exchange component in a system of its
    own (CVODE) and drops every connection between that system and the others (``System.processElements``
    files them under no solver), so the plant ran open loop there. Without the attribute both run the FMU's
    co-simulation interface, closed loop."""
    if interface == "me" and "cs" in info.interfaces:
        return None
    return IMPLEMENTATION.get(interface)


def _parameter_set(name: str, info, values: dict[str, Any], out: Path) -> bytes | None:
    """The .ssv of a component's start values (None without any)."""
    if not values:
        return None
    pset = _el(None, "ssv:ParameterSet", {"xmlns:ssv": NS["ssv"], "version": "1.0", "name": f"{name}_start_values"})
    params = _el(pset, "ssv:Parameters")
    for vname, value in values.items():
        var = info.variables[vname]
        if isinstance(value, list):
            raise SspError(out, f"{name}.{vname}: array start values have no SSP 1.0 parameter type")
        try:
            _typed(_el(params, "ssv:Parameter", {"name": vname}), "ssv", var, value, f"{name}.")
        except ValueError as exc:
            raise SspError(out, str(exc)) from None
    return _xml(pset)


def _connections(system: ET.Element, plan, names: list[str]) -> None:
    """One ``ssd:Connection`` per link of the plan, element-wise as written, between the components ``names``."""
    if not plan.links:
        return
    conns = _el(system, "ssd:Connections")
    for link in plan.links:
        attrs = {"startElement": names[link.src.comp], "startConnector": _connector(link.src),
                 "endElement": names[link.dst.comp], "endConnector": _connector(link.dst)}
        if link.src.var.unit and link.dst.var.unit and link.src.var.unit != link.dst.var.unit:
            attrs["suppressUnitConversion"] = "true"  # a connection with `units: as_is` (else refused)
        _el(conns, "ssd:Connection", attrs)


def _units(root: ET.Element, infos) -> None:
    """``ssd:Units``: the definitions (from the FMUs) of the units the components' variables use."""
    units = unit_definitions(infos)
    used = {v.unit for info in infos for v in info.variables.values() if v.unit}
    if used & set(units):
        uel = _el(root, "ssd:Units")
        for uname in sorted(used & set(units)):
            _el(_el(uel, "ssc:Unit", {"name": uname}), "ssc:BaseUnit", units[uname])


def _el(parent: ET.Element | None, tag: str, attrib: dict[str, str] | None = None) -> ET.Element:
    attrib = {k: v for k, v in (attrib or {}).items() if v is not None}
    return ET.Element(tag, attrib) if parent is None else ET.SubElement(parent, tag, attrib)


def _xml(root: ET.Element) -> bytes:
    ET.indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8") + b"\n"


def _typed(parent: ET.Element, prefix: str, var, value: Any = None, where: str = "") -> None:
    """``<prefix:Real unit=.../>`` (connector) or ``<prefix:Real value=.../>`` (parameter) for ``var``."""
    kind = SSP_TYPE.get(var.fmi_type)
    if kind is None or var.is_array:
        raise ValueError(f"{where}{var.name} is {var.fmi_type}{' array' if var.is_array else ''}, which SSP 1.0 "
                         "connectors and parameter values do not carry")
    attrib: dict[str, str | None] = {}
    if value is not None:
        if kind == "Real":
            attrib["value"] = num_text(value)
        elif kind == "Integer":
            attrib["value"] = str(int(value))
        elif kind == "Boolean":
            attrib["value"] = "true" if (value.lower() == "true" if isinstance(value, str) else bool(value)) \
                else "false"
        else:
            attrib["value"] = str(value)
    if kind == "Real" and var.unit and value is None:  # a connector's unit (defined in ssd:Units)
        attrib["unit"] = var.unit
    _el(parent, f"{prefix}:{kind}", attrib)


def _string_at_start(var, value: Any) -> bool:
    """Whether ``value`` is a String variable's own start value, which the export leaves out of the
    .ssv: the FMU starts from it anyway (SSP 1.0 binds what it changes; an unbound parameter keeps its
    start), and OMSimulator 3.0 refuses every ``ssv:String`` ("Unknown ParameterBinding-type"), so a
    scenario that writes a String parameter at its default (``model.fidelity: full``) still runs
    there. A String that differs from the start is written as ``ssv:String``, as the standard says."""
    return SSP_TYPE.get(var.fmi_type) == "String" and isinstance(value, str) and value == var.start


def _extras(system: SystemStructure) -> dict[str, Any]:
    """The sections SSP has no place for, as JSON-ready data: the scenario's as it runs (its document), or what a
    structure made in code holds of them."""
    document = system.document
    if document is None:
        return _structure_extras(system)
    data = {k: document[k] for k in EXTRAS if k in document}
    data["name"] = system.name
    logging = dict(data.get("logging") or {})
    logging.pop("out", None)  # relative to the YAML file; the archive's runs log to runs/<name>.mcap
    data["logging"] = logging
    if data.get("initial_state"):
        data["initial_state"] = {**data["initial_state"], "from_trajectory": False}  # values are in the .ssv
    data["component_options"] = _component_options(system)
    return data


def _archive_names(names: list[str], infos) -> list[str]:
    """The components' names in the archive: names every SSP tool can address, each the scenario's name where it
    is one (our annotation's ``component_names`` maps the others back on import). OMSimulator takes a component's
    name as an identifier (``ComRef::isValidIdent``: a letter, then letters, digits, ``_`` and ``-``; ``DP
    Controller`` or ``Ship.Engine`` cannot be added), and its C++ import and its Python API read a parameter whose
    first part is the component's name (``model`` and its ``model.w_inertia``) as a path that repeats the component,
    and drop that part.
    So: any other character becomes ``_``, ``c`` goes before a name that does not start with a letter, and ``_``
    is appended while the name is the first part of one of its FMU's variables, or another component's name."""
    out: list[str] = []
    for name, info in zip(names, infos):
        firsts = {re.split(r"[.\[]", v, maxsplit=1)[0] for v in info.variables}
        arc = _identifier(name)
        while arc in firsts or arc.lower() in {o.lower() for o in out}:
            arc += "_"
        out.append(arc)
    return out


def _identifier(name: str) -> str:
    """``name`` as an OMSimulator identifier (``^[a-zA-Z][a-zA-Z0-9_-]*$``): other characters ``_``, and ``c``
    before a name that does not start with a letter."""
    ident = re.sub(r"[^A-Za-z0-9_-]", "_", name)
    return ident if re.match(r"[A-Za-z]", ident) else "c" + ident


def _member_stems(names: list[str]) -> list[str]:
    """File names in ``resources/`` for the components: the name made safe (:func:`cosim.engine.names.safe_stem`;
    ``DP Controller`` -> ``DP_Controller``), numbered when two would clash."""
    out: list[str] = []
    for name in names:
        stem, n = safe_stem(name, "component"), 2
        while stem.lower() in {o.lower() for o in out}:
            stem = f"{safe_stem(name, 'component')}_{n}"
            n += 1
        out.append(stem)
    return out


def _connector(port) -> str:
    """A port's connector name (the variable, with its FMI 3 element index)."""
    return f"{port.var.name}{index_text(port.var, port.element)}"
