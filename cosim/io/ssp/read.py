"""SSP 1.0 (System Structure and Parameterization, ssp-standard.org) export and import.

Export (:func:`export_ssp`, ``python -m cosim ssp export SCENARIO -o SYSTEM.ssp``) writes a
scenario as an SSP archive that any SSP tool can run:

- ``SystemStructure.ssd``: one ``ssd:Component`` per FMU (``source="resources/<name>.fmu"``,
  ``implementation`` when the scenario fixes the interface), its scalar inputs and outputs as
  connectors with kind, type and unit (``ssd:Units`` defines the units from the FMUs' own
  UnitDefinitions), one ``ssd:Connection`` per scenario connection (element-wise, as written),
  the default experiment (``startTime``, ``stopTime``) with the base step in the OSP annotation
  libcosim reads (``osp:FixedStepAlgorithm baseStepSize``) and a component's step multiple as
  ``osp:StepSizeHint``;
- ``resources/<name>.ssv``: per component, every start value our master sets (the plan of
  :func:`cosim.engine.prepare.prepare`: explicit parameters, our trajectory FMUs' parameters from the
  ``trajectory:`` section and the plant's initial state), bound through ``ssd:ParameterBinding``,
  except a String equal to the FMU's own start value (OMSimulator 3.0 reads no ``ssv:String``);
- ``resources/<name>.fmu``: the FMUs;
- a root annotation of type ``org.delta-cosim.engine.scenario`` holding what SSP has no place for
  (algorithm, robot, trajectory for the pre-flight, comparison, checks, logging, per-component
  solver options) as JSON, so our master runs the archive exactly as the YAML. Other tools ignore
  it. ``initial_state.from_trajectory`` is written false: its values are in the plant's .ssv.

Import (:func:`open_ssp`, ``python -m cosim run|check SYSTEM.ssp``) reads any SSP 1.0 archive with
FMU components (ours or another tool's): the .ssd, its parameter bindings (.ssv files or inline
parameter sets), the FMUs from the archive, and builds the same :class:`cosim.engine.scenario.Scenario`
the YAML loader builds, run by the normal :func:`cosim.run.run_scenario`. The base step comes from
the OSP annotation (``osp:FixedStepAlgorithm baseStepSize``, which also makes the algorithm Jacobi:
libcosim's fixed_step_algorithm steps every FMU from the previous step's values) or OMSimulator's
(``oms:FixedStepMaster stepSize`` on the system; two annotations that disagree are an error), else
from the FMUs' default experiments (the smallest), else ``--step``; the stop time from the default
experiment, else the FMUs', else ``--stop-time``. Our own annotation, when present, sets the algorithm.
Parameter bindings of a component and of the system (``Component.parameter`` names, the longest
component name that fits) are applied, each through its ``.ssm`` parameter mapping (SSP 1.0: a mapped
name goes to the entry's targets through its linear, boolean, integer or enumeration transformation;
an unmapped name stays as it is); the system's come last and win. Component names are SSP's: any text
(``DP Controller``); in dotted names a name with a dot is quoted (:mod:`cosim.engine.names`), and a file
made from a name is made safe first. The archive is
unpacked into a temporary directory that :func:`open_ssp` removes when its block ends (also on
error and Ctrl-C); the scenario names the archive and its SHA-256, which a run's log records, so that
``run --from-log`` unpacks the same archive again (:func:`reopen_ssp`). Bad input raises :class:`SspError`: one line naming the file and the problem.
Not supported (a clear error, never a silent change): SSP 2.0, nested systems, signal dictionaries,
system-level connectors, connection transformations, components that are not FMUs, FMI 3 arrays.

Library choice: the standard library's ``xml.etree.ElementTree``, written against the SSP 1.0 XSDs
(those shipped with fmpy in ``fmpy/ssp/schema``; the tests validate every exported file against
them). fmpy's ``fmpy.ssp`` reads but cannot write, rejects any file that fails the schema with a
bare ``Exception`` and reads transformations in the wrong namespace; ``pyssp-standard`` would be a
new dependency with few users. OSP libcosim matches element names by their prefixes literally
(``ssd:``, ``ssc:``, ``ssv:``, ``osp:``), so the writer emits prefixed names itself instead of
relying on ElementTree's namespace registry (a process-wide setting); the reader resolves
namespaces properly, so files of other tools with other prefixes read too.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import posixpath
import re
import shutil
import tempfile
import zipfile
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator
from urllib.parse import unquote, urlparse
from xml.etree import ElementTree as ET

from ...engine.grid import MAX_TIME_S
from ...engine.names import ref, safe_stem
from ...engine.prepare import input_files, prepare
from ...engine.overrides import apply_overrides
from ...engine.scenario import load_scenario, scenario_from_data
from ...engine.schema import Component
from ...engine.wiring import index_text
from ...errors import CosimError, Issue, ScenarioError, file_problem, number_option, written_by_rename
from ...fmi.description import FMUInfo, load_fmu
from ...fmi.extract import MAX_FMU_BYTES, SSP_PREFIX, sweep_orphans
from ..output import check_output

if TYPE_CHECKING:  # the CLI imports this module to register its command: keep pydantic out of that
    from ...engine.schema import Scenario

__all__ = ["SspError", "ExportReport", "export_ssp", "read_ssp", "open_ssp", "reopen_ssp", "is_ssp", "NS", "SSD_NAME", "register"]

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "ssm": "http://ssp-standard.org/SSP1/SystemStructureParameterMapping",
    "ssb": "http://ssp-standard.org/SSP1/SystemStructureSignalDictionary",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
    "dcs": "https://github.com/delta-cosim/ssp",
    "oms": "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd",
}
SSD_NAME = "SystemStructure.ssd"
OSP_ANNOTATION = "com.opensimulationplatform"
OMS_ANNOTATION = "org.openmodelica"
OUR_ANNOTATION = "org.delta-cosim.engine.scenario"
FMU_TYPE = "application/x-fmu-sharedlibrary"
PARAMETER_SET_TYPE = "application/x-ssp-parameter-set"
_IMPLEMENTATION = {"cs": "CoSimulation", "me": "ModelExchange"}
_INTERFACE = {"CoSimulation": "cs", "ModelExchange": "me", "any": "auto"}
# FMI 2.0 / 3.0 declared types -> SSP 1.0 connector / parameter types
_SSP_TYPE = {"Real": "Real", "Float64": "Real", "Float32": "Real", "Integer": "Integer",
             "Int8": "Integer", "Int16": "Integer", "Int32": "Integer", "Int64": "Integer", "UInt8": "Integer",
             "UInt16": "Integer", "UInt32": "Integer", "UInt64": "Integer", "Boolean": "Boolean",
             "String": "String"}
# scenario sections carried in our annotation (SSP has no place for them)
_EXTRAS = ("description", "robot", "algorithm", "parallel", "trajectory", "initial_state", "logging", "compare",
           "checks", "regression", "events")
_COMPONENT_OPTIONS = ("interface", "feedthrough", "rtol", "solver", "max_step")


class SspError(ScenarioError):
    """An SSP archive cannot be read or written: one line naming the file and the problem."""

    def __init__(self, file: str | Path, message: str):
        super().__init__(Issue("", message, str(file)))


def _num(x: float) -> str:
    """A float as the shortest text that reads back to the same double (C strtod included)."""
    return repr(float(x))


# --------------------------------------------------------------------------- export


@dataclass(frozen=True)
class ExportReport:
    """What :func:`export_ssp` wrote."""

    path: Path
    components: list[str]
    connections: int
    parameters: dict[str, int]  # component -> number of start values in its .ssv
    step: float
    stop: float
    events: int = 0  # the scenario's events, carried in our annotation only

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


def _el(parent: ET.Element | None, tag: str, attrib: dict[str, str] | None = None) -> ET.Element:
    attrib = {k: v for k, v in (attrib or {}).items() if v is not None}
    return ET.Element(tag, attrib) if parent is None else ET.SubElement(parent, tag, attrib)


def _xml(root: ET.Element) -> bytes:
    ET.indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8") + b"\n"


def _typed(parent: ET.Element, prefix: str, var, value: Any = None, where: str = "") -> None:
    """``<prefix:Real unit=.../>`` (connector) or ``<prefix:Real value=.../>`` (parameter) for ``var``."""
    kind = _SSP_TYPE.get(var.fmi_type)
    if kind is None or var.is_array:
        raise ValueError(f"{where}{var.name} is {var.fmi_type}{' array' if var.is_array else ''}, which SSP 1.0 "
                         "connectors and parameter values do not carry")
    attrib: dict[str, str | None] = {}
    if value is not None:
        if kind == "Real":
            attrib["value"] = _num(value)
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
    return _SSP_TYPE.get(var.fmi_type) == "String" and isinstance(value, str) and value == var.start


def _unit_definitions(infos) -> dict[str, dict[str, str]]:
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
                    attrs["factor"] = _num(b.factor)
                if float(b.offset) != 0.0:
                    attrs["offset"] = _num(b.offset)
            out.setdefault(u.name, attrs)
    return out


def _extras(scenario: Scenario) -> dict[str, Any]:
    """The scenario sections SSP has no place for, as JSON-ready data."""
    data = scenario.model_dump(mode="json", by_alias=True, include=set(_EXTRAS), exclude_defaults=False)
    data["name"] = scenario.name
    logging = dict(data.get("logging") or {})
    logging.pop("out", None)  # relative to the YAML file; the archive's runs log to runs/<name>.mcap
    data["logging"] = logging
    if data.get("initial_state"):
        data["initial_state"] = {**data["initial_state"], "from_trajectory": False}  # values are in the .ssv

    defaults = {k: Component.model_fields[k].default for k in _COMPONENT_OPTIONS}
    options = {}
    for name, comp in scenario.components.items():
        changed = {k: getattr(comp, k) for k in _COMPONENT_OPTIONS if getattr(comp, k) != defaults[k]}
        if changed:
            options[name] = changed
    data["component_options"] = options
    return data


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


def export_ssp(scenario: Scenario, out: str | Path) -> ExportReport:
    """Write ``scenario`` as an SSP 1.0 archive at ``out`` (see the module docstring).

    Builds our FMUs if needed and runs the pre-flight (:func:`cosim.engine.prepare.prepare`); raises
    :class:`cosim.errors.CosimError` subclasses for a bad scenario, :class:`SspError` for what SSP
    1.0 cannot express.
    """

    out = Path(out)
    plan, _ = prepare(scenario)
    names, infos = plan.names, plan.infos
    t = scenario.time
    root = _el(None, "ssd:SystemStructureDescription", {
        "xmlns:ssd": NS["ssd"], "xmlns:ssc": NS["ssc"], "xmlns:ssv": NS["ssv"], "xmlns:osp": NS["osp"],
        "xmlns:dcs": NS["dcs"], "xmlns:oms": NS["oms"], "name": scenario.name, "version": "1.0",
        "description": scenario.description or None, "generationTool": "delta-cosim"})
    system = _el(root, "ssd:System", {"name": scenario.name})
    elements = _el(system, "ssd:Elements")
    # OMSimulator 3.0 types a system by its own annotation (SystemWC, its fixed-step master): without
    # it the import fails ("[NewSystem] internal error"). It reads only the first ssc:Annotation here.
    # (appended after the connections: the SSD's order)
    system_annotations = _el(None, "ssd:Annotations")
    oms = _el(_el(_el(system_annotations, "ssc:Annotation", {"type": OMS_ANNOTATION}), "oms:Annotations"),
              "oms:SimulationInformation")
    _el(oms, "oms:FixedStepMaster", {"description": "oms-ma", "stepSize": _num(t.step)})
    connected = {}  # (component, variable name) that a connection uses (prefixes expanded: plan.links)
    for link in plan.links:
        for port in (link.src, link.dst):
            connected[(names[port.comp], port.var.name)] = port.label(names)
    for link in plan.links:
        for port in (link.src, link.dst):
            if port.var.is_array:
                raise SspError(out, f"connection of {port.label(names)}: FMI 3 arrays have no SSP 1.0 connector")
    ssv_files: dict[str, bytes] = {}
    n_params: dict[str, int] = {}
    stems = _member_stems(names)
    for c, name in enumerate(names):
        comp, info = scenario.components[name], infos[c]
        el = _el(elements, "ssd:Component", {"name": name, "type": FMU_TYPE, "source": f"resources/{stems[c]}.fmu",
                                             "implementation": _IMPLEMENTATION.get(comp.interface)})
        connectors = _el(el, "ssd:Connectors")
        for var in info.variables.values():
            if var.causality not in ("input", "output"):
                continue
            if var.is_array or var.fmi_type not in _SSP_TYPE:
                if (name, var.name) in connected:
                    raise SspError(out, f"{name}.{var.name} is {var.fmi_type}"
                                        f"{' array' if var.is_array else ''}: no SSP 1.0 connector type")
                continue
            conn = _el(connectors, "ssd:Connector", {"name": var.name, "kind": var.causality,
                                                     "description": var.description or None})
            _typed(conn, "ssc", var)
        if not len(connectors):
            el.remove(connectors)
        values = {k: v for k, v in plan.start_values[c].items() if not _string_at_start(info.variables[k], v)}
        if values:
            pset = _el(None, "ssv:ParameterSet", {"xmlns:ssv": NS["ssv"], "version": "1.0",
                                                  "name": f"{name}_start_values"})
            params = _el(pset, "ssv:Parameters")
            for vname, value in values.items():
                var = info.variables[vname]
                if isinstance(value, list):
                    raise SspError(out, f"{name}.{vname}: array start values have no SSP 1.0 parameter type")
                try:
                    _typed(_el(params, "ssv:Parameter", {"name": vname}), "ssv", var, value, f"{name}.")
                except ValueError as exc:
                    raise SspError(out, str(exc)) from None
            ssv_files[f"resources/{stems[c]}.ssv"] = _xml(pset)
            n_params[name] = len(values)
            bindings = _el(el, "ssd:ParameterBindings")
            _el(bindings, "ssd:ParameterBinding", {"type": PARAMETER_SET_TYPE, "source": f"resources/{stems[c]}.ssv"})
        else:
            n_params[name] = 0
        if comp.step_multiple != 1:
            ann = _el(_el(el, "ssd:Annotations"), "ssc:Annotation", {"type": OSP_ANNOTATION})
            _el(ann, "osp:StepSizeHint", {"value": _num(t.step * comp.step_multiple)})
    if plan.links:
        conns = _el(system, "ssd:Connections")
        for link in plan.links:
            attrs = {"startElement": names[link.src.comp], "startConnector": _connector(link.src),
                     "endElement": names[link.dst.comp], "endConnector": _connector(link.dst)}
            if link.src.var.unit and link.dst.var.unit and link.src.var.unit != link.dst.var.unit:
                attrs["suppressUnitConversion"] = "true"  # a connection with `units: as_is` (else refused)
            _el(conns, "ssd:Connection", attrs)
    system.append(system_annotations)
    units = _unit_definitions(infos)
    used = {v.unit for info in infos for v in info.variables.values() if v.unit}
    if used & set(units):
        uel = _el(root, "ssd:Units")
        for uname in sorted(used & set(units)):
            _el(_el(uel, "ssc:Unit", {"name": uname}), "ssc:BaseUnit", units[uname])
    exp = _el(root, "ssd:DefaultExperiment", {"startTime": _num(t.start), "stopTime": _num(t.stop)})
    ann = _el(_el(exp, "ssd:Annotations"), "ssc:Annotation", {"type": OSP_ANNOTATION})
    _el(_el(ann, "osp:Algorithm"), "osp:FixedStepAlgorithm", {"baseStepSize": _num(t.step)})
    # ours on the system, after OMSimulator's: OMSimulator 3.0 refuses any ssd:Annotations at the top
    # ("wrong xml schema detected"), though SSP 1.0 allows them there
    ours = _el(system_annotations, "ssc:Annotation", {"type": OUR_ANNOTATION})
    _el(ours, "dcs:Scenario").text = json.dumps(_extras(scenario), indent=1)
    check_output(out, (*input_files(scenario), *(info.path for info in infos)))
    with written_by_rename(out) as partial, zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr(SSD_NAME, _xml(root))
        for arc, data in ssv_files.items():
            z.writestr(arc, data)
        for stem, info in zip(stems, infos):
            z.write(info.path, f"resources/{stem}.fmu", compress_type=zipfile.ZIP_STORED)  # already deflated
    return ExportReport(out, list(names), len(plan.links), n_params, t.step, t.stop, len(scenario.events))


# --------------------------------------------------------------------------- import


def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


_ROOT_TAG = re.compile(rb"<[A-Za-z_][\w.:-]*")  # the first start tag (not <?xml, <!-- or <!DOCTYPE)


def _parse_xml(data: bytes, ssp: Path, member: str) -> ET.Element:
    """A member's XML. One repair, as libcosim makes it: published OSP files use the ``osp:`` prefix of their
    annotations without declaring it (an unbound prefix, not well-formed XML); it gets OSP's namespace."""
    try:
        return ET.fromstring(data)
    except ET.ParseError as exc:
        if "unbound prefix" in str(exc) and b"<osp:" in data and b"xmlns:osp" not in data:
            declared = _ROOT_TAG.sub(lambda m: m.group(0) + f' xmlns:osp="{NS["osp"]}"'.encode(), data, count=1)
            try:
                return ET.fromstring(declared)
            except ET.ParseError:
                pass
        raise SspError(ssp, f"{member}: not well-formed XML ({exc})") from None


MAX_XML_BYTES = 64 * 1024 * 1024
"""Largest .ssd or .ssv an archive may unpack to (ours are a few kB; a zip bomb inflated one to 2.5 GiB)."""


def _read_member(zf: zipfile.ZipFile, member: str, ssp: Path) -> bytes:
    """An XML member of the archive, read no further than :data:`MAX_XML_BYTES` (whatever its header claims)."""
    with zf.open(member) as f:
        data = f.read(MAX_XML_BYTES + 1)
    if len(data) > MAX_XML_BYTES:
        raise SspError(ssp, f"{member} unpacks to more than {MAX_XML_BYTES:,} bytes: refused")
    return data


def _member(base: str, uri: str, ssp: Path, what: str) -> str:
    """The archive member a relative URI in ``base`` (a member's directory) points at."""
    parsed = urlparse(uri)
    if parsed.scheme or parsed.netloc or uri.startswith("/"):
        raise SspError(ssp, f"{what}: source {uri!r} is not a relative reference into the archive "
                            "(only those are supported)")
    path = posixpath.normpath(posixpath.join(base, unquote(parsed.path)))
    if path.startswith("../") or path == "..":
        raise SspError(ssp, f"{what}: source {uri!r} points outside the archive")
    return path


def _value(kind: str, text: str | None, ssp: Path, where: str) -> Any:
    if text is None:
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
            raise ValueError(text)
        return text
    except ValueError:
        raise SspError(ssp, f"{where}: {text!r} is not a valid {kind} value") from None


_BASE_UNITS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


@dataclass(frozen=True)
class _Quantity:
    """A Real parameter value with the unit its parameter set gives it (``ssv:Real unit``), converted to the unit
    of the FMU variable it is bound to once the components' FMUs are read (:func:`_convert_units`). ``base``: the
    unit's definition (base-unit exponents, factor, offset: value in SI = factor * value + offset) from the set's
    ``ssv:Units`` or the SSD's ``ssd:Units``; None when neither defines it. ``where``: file and parameter."""

    value: float
    unit: str
    base: tuple[tuple[int, ...], float, float] | None
    where: str


def _unit_table(parent: ET.Element | None, path: str, ssp: Path, where: str) -> dict[str, tuple]:
    """``ssc:Unit`` definitions under ``parent`` (``ssv:Units`` or ``ssd:Units``): name -> (exponents, factor,
    offset)."""
    out: dict[str, tuple] = {}
    for u in (parent.iterfind(path, NS) if parent is not None else ()):
        base = u.find("ssc:BaseUnit", NS)
        attrs = base.attrib if base is not None else {}
        try:
            factor, offset = float(attrs.get("factor", "1")), float(attrs.get("offset", "0"))
            out[u.get("name", "")] = (tuple(int(attrs.get(k, "0")) for k in _BASE_UNITS), factor, offset)
        except ValueError:
            raise SspError(ssp, f"{where}: unit {u.get('name')!r}: its BaseUnit attributes are not numbers") from None
        if not _conversion_ok(factor, offset):
            raise SspError(ssp, f"{where}: unit {u.get('name')!r}: BaseUnit factor {factor!r}, offset {offset!r}: a "
                                "unit needs a finite factor other than 0 and a finite offset")
    return out


def _conversion_ok(factor: float, offset: float) -> bool:
    return math.isfinite(factor) and factor != 0.0 and math.isfinite(offset)


def _parameter_set(pset: ET.Element, ssp: Path, where: str, prefix: str,
                   ssd_units: dict[str, tuple] | None = None) -> dict[str, Any]:
    if pset.tag != _q("ssv", "ParameterSet"):
        raise SspError(ssp, f"{where}: expected an ssv:ParameterSet, found {pset.tag}")
    units = {**(ssd_units or {}), **_unit_table(pset, "ssv:Units/ssc:Unit", ssp, where)}
    values: dict[str, Any] = {}
    for p in pset.iterfind("ssv:Parameters/ssv:Parameter", NS):
        pname = p.get("name")
        if not pname:
            raise SspError(ssp, f"{where}: a parameter without a name")
        for kind in ("Real", "Integer", "Boolean", "String"):
            typed = p.find(f"ssv:{kind}", NS)
            if typed is not None:
                value = _value(kind, typed.get("value"), ssp, f"{where}: parameter {pname}")
                if kind == "Real" and typed.get("unit"):
                    value = _Quantity(value, typed.get("unit"), units.get(typed.get("unit")),
                                      f"{where}: parameter {pname}")
                if prefix + pname in values:  # which one would be meant: refused, not the last one silently
                    raise SspError(ssp, f"{where}: parameter {pname} is given twice")
                values[prefix + pname] = value
                break
        else:
            found = [child.tag.rsplit("}", 1)[-1] for child in p]
            raise SspError(ssp, f"{where}: parameter {pname}: type {', '.join(found) or '(none)'} is not "
                                "supported (Real, Integer, Boolean, String)")
    return values


PARAMETER_MAPPING_TYPE = "application/x-ssp-parameter-mapping"


def _mapping(b: ET.Element, zf: zipfile.ZipFile, ssp: Path, where: str) -> tuple[str, dict[str, list]]:
    """The ``ssd:ParameterMapping`` of binding ``b``: (its file or "inline", parameter name -> [(target,
    transformation element or None)]); no mapping: ("", {})."""
    pm = b.find("ssd:ParameterMapping", NS)
    if pm is None:
        return "", {}
    mtype = pm.get("type", PARAMETER_MAPPING_TYPE)
    if mtype != PARAMETER_MAPPING_TYPE:
        raise SspError(ssp, f"{where}: parameter mapping of type {mtype!r} is not supported (only "
                            f"{PARAMETER_MAPPING_TYPE})")
    if pm.get("source") is not None:
        what = _member("", pm.get("source"), ssp, f"{where}: parameter mapping")
        try:
            root = _parse_xml(_read_member(zf, what, ssp), ssp, what)
        except KeyError:
            raise SspError(ssp, f"{where}: parameter mapping source {what} is not in the archive") from None
    else:
        what, root = "inline parameter mapping", pm.find("ssm:ParameterMapping", NS)
        if root is None:
            raise SspError(ssp, f"{where}: ssd:ParameterMapping has neither a source nor an ssm:ParameterMapping")
    if root.tag != _q("ssm", "ParameterMapping"):
        raise SspError(ssp, f"{what}: expected an ssm:ParameterMapping, found {root.tag}")
    entries: dict[str, list] = {}
    for e in root.iterfind("ssm:MappingEntry", NS):
        src, dst = e.get("source"), e.get("target")
        if not src or not dst:
            raise SspError(ssp, f"{what}: a MappingEntry without source or target")
        transforms = [c for c in e if c.tag.startswith(f"{{{NS['ssc']}}}")]
        known = [c for c in transforms if c.tag.rsplit("}", 1)[1] in _TRANSFORMATIONS]
        if len(known) != len(transforms) or len(known) > 1:
            found = ", ".join(c.tag.rsplit("}", 1)[1] for c in transforms)
            raise SspError(ssp, f"{what}: mapping {src} -> {dst}: transformation {found} is not supported (one of "
                                f"{', '.join(_TRANSFORMATIONS)})")
        entries.setdefault(src, []).append((dst, known[0] if known else None))
    return what, entries


_TRANSFORMATIONS = ("LinearTransformation", "BooleanMappingTransformation", "IntegerMappingTransformation",
                    "EnumerationMappingTransformation")


def _transform(value: Any, tr: ET.Element | None, ssp: Path, where: str) -> Any:
    """``value`` through an SSP 1.0 transformation (ssc:LinearTransformation: factor * value + offset; the
    mapping transformations: the ssc:MapEntry whose source is the value)."""
    if tr is None:
        return value
    kind = tr.tag.rsplit("}", 1)[1]
    if isinstance(value, _Quantity):  # the transformation maps the number; the unit stays the set's
        if kind != "LinearTransformation":
            raise SspError(ssp, f"{where}: a {kind} cannot map a Real value with a unit ({value.unit})")
        return replace(value, value=_transform(value.value, tr, ssp, where))
    if kind == "LinearTransformation":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SspError(ssp, f"{where}: a LinearTransformation needs a Real or Integer value, got {value!r}")
        try:
            factor, offset = float(tr.get("factor", "1")), float(tr.get("offset", "0"))
        except ValueError:
            raise SspError(ssp, f"{where}: LinearTransformation factor/offset are not numbers") from None
        out = factor * value + offset
        return out if isinstance(value, float) or out != int(out) else int(out)
    text = ("true" if value else "false") if isinstance(value, bool) else str(value)
    for m in tr.iterfind("ssc:MapEntry", NS):
        source = m.get("source", "")
        if source == text or (kind == "BooleanMappingTransformation" and _bool_text(source) == value):
            target = m.get("target", "")
            return _bool_text(target) if kind == "BooleanMappingTransformation" else _int_text(target, ssp, where)
    raise SspError(ssp, f"{where}: {kind} has no MapEntry for the value {text!r}")


def _bool_text(text: str) -> bool | None:
    return {"true": True, "1": True, "false": False, "0": False}.get(text.strip())


def _int_text(text: str, ssp: Path, where: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise SspError(ssp, f"{where}: MapEntry target {text!r} is not an integer") from None


def _binding_values(el: ET.Element, zf: zipfile.ZipFile, ssp: Path, where: str,
                    units: dict[str, tuple]) -> list[tuple[str, Any, str]]:
    """(name, value, file) of every parameter the ``ssd:ParameterBindings`` under ``el`` give, in order, each
    through its binding's parameter mapping (a mapped name takes the mapping's targets; an unmapped name stays)
    and prefix. ``units``: the SSD's unit definitions (a set's own ``ssv:Units`` come first)."""
    out: list[tuple[str, Any, str]] = []
    for b in el.iterfind("ssd:ParameterBindings/ssd:ParameterBinding", NS):
        btype = b.get("type", PARAMETER_SET_TYPE)
        if btype != PARAMETER_SET_TYPE:
            raise SspError(ssp, f"{where}: parameter binding of type {btype!r} is not supported "
                                f"(only {PARAMETER_SET_TYPE})")
        mapping_file, mapping = _mapping(b, zf, ssp, where)
        prefix = b.get("prefix", "")
        source = b.get("source")
        sets: list[tuple[str, dict[str, Any]]] = []
        if source is not None:
            member = _member("", source, ssp, f"{where}: parameter binding")
            try:
                data = _read_member(zf, member, ssp)
            except KeyError:
                raise SspError(ssp, f"{where}: parameter binding source {member} is not in the archive") from None
            sets.append((member, _parameter_set(_parse_xml(data, ssp, member), ssp, member, "", units)))
        for pset in b.iterfind("ssd:ParameterValues/ssv:ParameterSet", NS):
            label = f"{where}: inline parameter values"
            sets.append((label, _parameter_set(pset, ssp, label, "", units)))
        for file, values in sets:
            for name, value in values.items():
                for target, tr in mapping.get(name, [(name, None)]):
                    value_out = _transform(value, tr, ssp, f"{mapping_file}: parameter {name} of {file}")
                    out.append((prefix + target, value_out, file))
    return out


def _bindings(el: ET.Element, zf: zipfile.ZipFile, ssp: Path, comp: str, units: dict[str, tuple]) -> dict[str, Any]:
    return {name: value for name, value, _ in _binding_values(el, zf, ssp, f"component {comp!r}", units)}


def _system_bindings(system: ET.Element, zf: zipfile.ZipFile, ssp: Path, components: dict[str, dict[str, Any]],
                     units: dict[str, tuple]) -> None:
    """Apply the system's own parameter bindings to the components they name (SSP 1.0: a parameter of a
    system-level set is named ``Component.parameter``; the longest component name that fits is taken, so
    names with dots need no quoting here). They come after the components' own bindings and win over them.
    A parameter that names no component, or no variable of it, is one error naming the file and the parameter."""
    names = sorted(components, key=len, reverse=True)
    for name, value, file in _binding_values(system, zf, ssp, "the system", units):
        comp = next((c for c in names if name.startswith(c + ".")), None)
        if comp is None:
            raise SspError(ssp, f"{file}: parameter {name!r} of a system-level binding names no component "
                                f"(expected Component.parameter; components: {', '.join(components)})")
        var = name[len(comp) + 1:]
        if var not in _description(comp, components, ssp).variables:
            raise SspError(ssp, f"{file}: parameter {name!r}: component {comp!r} has no variable {var!r}")
        components[comp].setdefault("parameters", {})[var] = value


def _description(comp: str, components: dict[str, dict[str, Any]], ssp: Path) -> FMUInfo:
    """A component's FMU as the run will read it (:func:`cosim.fmi.load_fmu`: checked, read once per file and
    process, so the run's own preparation reuses it)."""
    try:
        return load_fmu(components[comp]["path"])
    except CosimError as exc:
        raise SspError(ssp, f"component {comp!r}: {exc}") from None


def _convert_units(components: dict[str, dict[str, Any]], ssp: Path) -> None:
    """Every parameter value given with a unit (:class:`_Quantity`) in the unit of the FMU variable it is bound to
    (SSP 1.0: the value in SI is ``factor * value + offset`` of its unit's BaseUnit, then back through the
    variable's unit definition in the FMU). The same unit, or a variable without a unit: the number as given.
    Units of different dimensions, or a unit defined nowhere, are one error naming the parameter."""
    for comp, data in components.items():
        params = data.get("parameters") or {}
        for var, q in list(params.items()):
            if not isinstance(q, _Quantity):
                continue
            info = _description(comp, components, ssp)
            v = info.variables.get(var)
            unit = None if v is None else v.unit
            if not unit or unit == q.unit:  # no variable (named later) or nothing to convert
                params[var] = q.value
                continue
            target = next((u.baseUnit for u in info.md.unitDefinitions or [] if u.name == unit), None)
            if q.base is None:
                raise SspError(ssp, f"{q.where}: unit {q.unit!r} is defined in neither the parameter set's ssv:Units "
                                    f"nor the SSD's ssd:Units: cannot convert it to {comp}.{var}'s unit {unit!r}")
            if target is None:
                raise SspError(ssp, f"{q.where}: {comp}.{var} is in {unit!r}, which its FMU does not define: cannot "
                                    f"convert {q.unit!r} to it")
            exps = tuple(int(getattr(target, k, 0) or 0) for k in _BASE_UNITS)
            if exps != q.base[0]:
                raise SspError(ssp, f"{q.where}: unit {q.unit!r} does not convert to {comp}.{var}'s unit {unit!r} "
                                    "(other base units)")
            factor = 1.0 if target.factor is None else float(target.factor)
            offset = 0.0 if target.offset is None else float(target.offset)
            if not _conversion_ok(factor, offset):
                raise SspError(ssp, f"{q.where}: {comp}.{var}'s unit {unit!r} has factor {factor!r}, offset {offset!r} "
                                    "in its FMU: cannot convert to it")
            params[var] = (q.base[1] * q.value + q.base[2] - offset) / factor


def _osp_step(node: ET.Element | None, ssp: Path) -> float | None:
    """``baseStepSize`` of the OSP FixedStepAlgorithm annotation under ``node``, if any."""
    if node is None:
        return None
    for ann in node.iterfind("ssd:Annotations/ssc:Annotation", NS):
        if ann.get("type") != OSP_ANNOTATION:
            continue
        algo = ann.find("osp:Algorithm/osp:FixedStepAlgorithm", NS)
        if algo is not None:
            return _positive_step(algo.get("baseStepSize"), "osp:FixedStepAlgorithm baseStepSize", ssp)
    return None


def _positive_step(text: str | None, what: str, ssp: Path) -> float:
    """A step size given by an annotation: a number > 0 s, else one error naming ``what``."""
    try:
        step = float(text or "")
    except ValueError:
        raise SspError(ssp, f"{what} {text!r} is not a number") from None
    if not step > 0 or not math.isfinite(step):
        raise SspError(ssp, f"{what} must be > 0, got {step}")
    return step


def _local(el: ET.Element) -> str:
    return el.tag.rsplit("}", 1)[-1]


def _oms_step(system: ET.Element, ssp: Path) -> float | None:
    """The base step of OMSimulator's annotation on the system (its ``SystemWC``: ``<ssc:Annotation
    type="org.openmodelica"><oms:Annotations><oms:SimulationInformation><oms:FixedStepMaster
    stepSize=.../>``; ``oms:VariableStepMaster``: its ``maximumStepSize``), if any. Tags are matched by
    local name, as OMSimulator matches them by its own prefix without resolving namespaces."""
    for ann in system.iterfind("ssd:Annotations/ssc:Annotation", NS):
        if ann.get("type") != OMS_ANNOTATION:
            continue
        for info in ann.iter():
            if _local(info) != "SimulationInformation":
                continue
            for master in info:
                attr = {"FixedStepMaster": "stepSize", "VariableStepMaster": "maximumStepSize"}.get(_local(master))
                if attr is None:
                    continue
                return _positive_step(master.get(attr), f"{SSD_NAME}: OMSimulator's {_local(master)} {attr}", ssp)
    return None


def _step_hint(el: ET.Element, ssp: Path, comp: str) -> float | None:
    for ann in el.iterfind("ssd:Annotations/ssc:Annotation", NS):
        if ann.get("type") == OSP_ANNOTATION:
            hint = ann.find("osp:StepSizeHint", NS)
            if hint is not None:
                try:
                    return float(hint.get("value", ""))
                except ValueError:
                    raise SspError(ssp, f"component {comp!r}: osp:StepSizeHint value {hint.get('value')!r} is "
                                        "not a number") from None
    return None


def _time(x: float) -> float:
    """A time read as a double, rounded to whole nanoseconds (the master's resolution); one no grid can hold (nan,
    an infinity, past :data:`~cosim.engine.grid.MAX_TIME_S`) as it is, for the scenario's check to name."""
    return round(x * 1e9) / 1e9 if abs(x) <= MAX_TIME_S else x


def read_ssp(ssp: str | Path, workdir: str | Path) -> dict[str, Any]:
    """Read ``ssp`` into scenario data (the mapping :func:`cosim.engine.scenario.scenario_from_data` takes).

    The FMUs are unpacked into ``workdir`` (component ``path`` entries point there). The time
    grid may lack ``step`` or ``stop`` when neither the SSD nor the FMUs give one (the caller's
    ``--step`` / ``--stop-time`` overrides fill them in).
    """
    ssp, workdir = Path(ssp), Path(workdir)
    problem = file_problem(ssp)  # a FIFO or /dev/zero named .ssp: zipfile would read it for ever
    if problem is not None:
        raise SspError(ssp, problem)
    try:
        zf = zipfile.ZipFile(ssp)
    except FileNotFoundError:
        raise SspError(ssp, "no such file") from None
    except (zipfile.BadZipFile, OSError) as exc:
        raise SspError(ssp, f"not an SSP archive (a zip file): {exc}") from None
    with zf:
        names = zf.namelist()
        members = set(names)
        if len(members) != len(names):  # zip readers differ on which copy they take: the archive means two things
            twice = sorted({n for n in names if names.count(n) > 1})
            raise SspError(ssp, f"the archive holds two members named {twice[0]!r}"
                                + (f" (and {len(twice) - 1} more)" if len(twice) > 1 else "") + ": refused")
        if SSD_NAME not in members:
            found = ", ".join(sorted(m for m in members if m.endswith(".ssd"))) or "none"
            raise SspError(ssp, f"no {SSD_NAME} at the top of the archive (.ssd files found: {found})")
        root = _parse_xml(_read_member(zf, SSD_NAME, ssp), ssp, SSD_NAME)
        if root.tag.startswith("{http://ssp-standard.org/SSP2/"):
            raise SspError(ssp, f"{SSD_NAME}: SSP 2.0 is not supported (SSP 1.0 only)")
        if root.tag != _q("ssd", "SystemStructureDescription"):
            raise SspError(ssp, f"{SSD_NAME}: the root element is {root.tag}, expected ssd:SystemStructureDescription "
                                f"in namespace {NS['ssd']}")
        if not (root.get("version") or "").startswith("1."):
            raise SspError(ssp, f"{SSD_NAME}: SSP version {root.get('version')!r} is not supported (1.0)")
        system = root.find("ssd:System", NS)
        if system is None:
            raise SspError(ssp, f"{SSD_NAME}: no ssd:System element")
        if system.find("ssd:Connectors", NS) is not None:
            raise SspError(ssp, f"{SSD_NAME}: connectors of the system itself are not supported (only components')")
        if system.find("ssd:SignalDictionaries", NS) is not None:
            raise SspError(ssp, f"{SSD_NAME}: signal dictionaries are not supported")
        extras: dict[str, Any] = {}
        for ann in [*system.iterfind("ssd:Annotations/ssc:Annotation", NS),  # ours, since OMSimulator's check
                    *root.iterfind("ssd:Annotations/ssc:Annotation", NS)]:  # archives written before
            if ann.get("type") == OUR_ANNOTATION:
                node = ann.find("dcs:Scenario", NS)
                extras = _annotation(node.text or "{}", ssp) if node is not None else {}
        options = extras.pop("component_options", {}) or {}
        if isinstance(extras.get("logging"), dict) and extras["logging"].get("out") is not None:
            raise SspError(ssp, f"{SSD_NAME}: annotation {OUR_ANNOTATION} sets logging.out "
                                f"({extras['logging']['out']!r}): an archive cannot choose where the log is written; "
                                "give --out")

        components: dict[str, dict[str, Any]] = {}
        ssd_units = _unit_table(root, "ssd:Units/ssc:Unit", ssp, SSD_NAME)
        connectors: dict[str, dict[str, str]] = {}  # component -> connector name -> kind
        hints: dict[str, float] = {}
        elements = system.find("ssd:Elements", NS)
        for el in (list(elements) if elements is not None else []):
            tag = el.tag.rsplit("}", 1)[-1]
            if tag != "Component":
                raise SspError(ssp, f"{SSD_NAME}: ssd:{tag} {el.get('name', '')!r}: nested systems and signal "
                                    "dictionaries are not supported (only FMU components)")
            name = el.get("name")
            if not name:
                raise SspError(ssp, f"{SSD_NAME}: a component without a name")
            if name in components:
                raise SspError(ssp, f"{SSD_NAME}: two components named {name!r}")
            ctype = el.get("type", FMU_TYPE)
            if ctype != FMU_TYPE:
                raise SspError(ssp, f"component {name!r}: type {ctype!r} is not supported (only FMUs, {FMU_TYPE})")
            source = el.get("source")
            if not source:
                raise SspError(ssp, f"component {name!r}: no source attribute")
            member = _member("", source, ssp, f"component {name!r}")
            if member not in members:
                raise SspError(ssp, f"component {name!r}: its FMU {member} is not in the archive")
            impl = el.get("implementation", "any")
            if impl not in _INTERFACE:
                raise SspError(ssp, f"component {name!r}: implementation {impl!r} is not supported "
                                    f"({', '.join(_INTERFACE)})")
            # the component's name is the SSD's to choose and never a path here: each FMU goes to a folder
            # numbered by its place in the system (a name such as "../../x" wrote outside the work folder)
            stem = posixpath.splitext(posixpath.basename(member))[0]
            target = workdir / "fmus" / f"{len(components):04d}" / f"{safe_stem(stem, 'component')}.fmu"
            if zf.getinfo(member).file_size > MAX_FMU_BYTES:  # read no further than declared: this bounds it
                raise SspError(ssp, f"component {name!r}: its FMU {member} unpacks to more than "
                                    f"{MAX_FMU_BYTES:,} bytes: refused")
            target.parent.mkdir(parents=True, exist_ok=True)
            with zf.open(member) as src, open(target, "wb") as dst:
                shutil.copyfileobj(src, dst)
            comp: dict[str, Any] = {"path": str(target)}
            if impl != "any":
                comp["interface"] = _INTERFACE[impl]
            comp.update(options.get(name, {}))
            params = _bindings(el, zf, ssp, name, ssd_units)
            if params:
                comp["parameters"] = params
            hint = _step_hint(el, ssp, name)
            if hint is not None:
                hints[name] = hint
            connectors[name] = {c.get("name", ""): c.get("kind", "")
                                for c in el.iterfind("ssd:Connectors/ssd:Connector", NS)}
            components[name] = comp
        if not components:
            raise SspError(ssp, f"{SSD_NAME}: the system has no components")
        for el in (list(elements) if elements is not None else []):
            _check_connectors(el, components, ssp)
        _system_bindings(system, zf, ssp, components, ssd_units)
        _convert_units(components, ssp)

        connections = []
        for cn in system.iterfind("ssd:Connections/ssd:Connection", NS):
            ends = []
            for side, role in (("start", "output"), ("end", "input")):
                elem, conn = cn.get(f"{side}Element"), cn.get(f"{side}Connector")
                label = f"connection {cn.get('startElement')}.{cn.get('startConnector')} -> " \
                        f"{cn.get('endElement')}.{cn.get('endConnector')}"
                if elem is None:
                    raise SspError(ssp, f"{label}: connections to the system's own connectors are not supported")
                if elem not in components:
                    raise SspError(ssp, f"{label}: no component named {elem!r} (components: "
                                        f"{', '.join(components)})")
                if conn not in connectors[elem]:
                    known = ", ".join(sorted(connectors[elem])[:12]) or "none"
                    raise SspError(ssp, f"{label}: component {elem!r} has no connector {conn!r} (connectors: {known})")
                ends.append(ref(elem, conn))
            if cn.find("ssc:LinearTransformation", NS) is not None or any(
                    child.tag.endswith("MappingTransformation") for child in cn):
                raise SspError(ssp, f"connection {ends[0]} -> {ends[1]}: transformations are not supported")
            connection = {"from": ends[0], "to": ends[1]}
            if cn.get("suppressUnitConversion", "false").strip() in ("true", "1"):
                connection["units"] = "as_is"  # the numbers pass as they are, whatever the connectors' units
            connections.append(connection)

        exp = root.find("ssd:DefaultExperiment", NS)
        time: dict[str, float] = {}
        for key, attr in (("start", "startTime"), ("stop", "stopTime")):
            if exp is not None and exp.get(attr) is not None:
                try:
                    time[key] = _time(float(exp.get(attr)))
                except ValueError:
                    raise SspError(ssp, f"ssd:DefaultExperiment {attr} {exp.get(attr)!r} is not a number") from None
        step = _osp_step(exp, ssp)
        oms_step = _oms_step(system, ssp)
        if step is not None and oms_step is not None and step != oms_step:
            raise SspError(ssp, f"{SSD_NAME}: the OSP annotation gives the base step {step:g} s, OMSimulator's "
                                f"{oms_step:g} s: give one (or --step)")
        step = step if step is not None else oms_step
        if step is None or "stop" not in time:
            fmu_step, fmu_stop = _fmu_defaults(ssp, [Path(c["path"]) for c in components.values()])
            step = step if step is not None else fmu_step
            if "stop" not in time and fmu_stop is not None:
                time["stop"] = fmu_stop
        if step is not None:
            time["step"] = _time(step)
            for name, hint in hints.items():
                m = hint / step
                if abs(m - round(m)) > 1e-9 * m or round(m) < 1:
                    raise SspError(ssp, f"component {name!r}: osp:StepSizeHint {hint:g} s is not a whole multiple "
                                        f"of the base step {step:g} s")
                if round(m) > 1:
                    components[name]["step_multiple"] = round(m)
    data: dict[str, Any] = {"name": extras.pop("name", None) or root.get("name") or ssp.stem,
                            "components": components, "connections": connections, "time": time}
    if _osp_step(exp, ssp) is not None:  # libcosim's fixed_step_algorithm: every FMU from the last step's values
        data["algorithm"] = "jacobi"
    if root.get("description") and "description" not in extras:
        data["description"] = root.get("description")
    data.update({k: v for k, v in extras.items() if k in _EXTRAS})
    return data


def _annotation(text: str, ssp: Path) -> dict[str, Any]:
    """Our annotation's JSON: an object, each key once, with keys of the scenario's sections only; nesting, numbers
    and everything else JSON allows but no scenario holds are one error naming the annotation."""
    where = f"{SSD_NAME}: annotation {OUR_ANNOTATION}"

    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        keys = [k for k, _ in items]
        twice = next((k for k in keys if keys.count(k) > 1), None)
        if twice is not None:
            raise SspError(ssp, f"{where}: the key {twice!r} is given twice")
        return dict(items)

    try:
        data = json.loads(text, object_pairs_hook=pairs)
    except json.JSONDecodeError as exc:
        raise SspError(ssp, f"{where}: not valid JSON ({exc})") from None
    except SspError:  # a key given twice
        raise
    except (RecursionError, ValueError) as exc:  # nested too deep, an integer of thousands of digits
        raise SspError(ssp, f"{where}: not a scenario's JSON ({str(exc)[:120]})") from None
    if not isinstance(data, dict):
        raise SspError(ssp, f"{where}: expected a JSON object, got {type(data).__name__}")
    unknown = sorted(set(data) - {*_EXTRAS, "name", "component_options"})
    if unknown:
        raise SspError(ssp, f"{where}: unknown key {unknown[0]!r} (an archive's annotation carries "
                            f"{', '.join(_EXTRAS)}, name and component_options)")
    return data


_CONNECTOR_KINDS = ("input", "output", "inout", "parameter", "calculatedParameter")


def _check_connectors(el: ET.Element, components: dict[str, dict[str, Any]], ssp: Path) -> None:
    """A component's connectors as its FMU declares them: a kind SSP knows, an input or an output where the FMU
    variable is one, and its type (a connector declared Boolean on a Real variable, or an output on an input, was
    taken as the FMU's)."""
    name = el.get("name")
    info = None
    for c in el.iterfind("ssd:Connectors/ssd:Connector", NS):
        cname, kind = c.get("name", ""), c.get("kind", "")
        label = f"component {name!r}: connector {cname!r}"
        if kind not in _CONNECTOR_KINDS:
            raise SspError(ssp, f"{label}: kind {kind!r} is not an SSP connector kind ({', '.join(_CONNECTOR_KINDS)})")
        info = info or _description(name, components, ssp)
        var = info.variables.get(cname)
        if var is None:  # named in a connection later, or never used
            continue
        if kind in ("input", "output") and var.causality in ("input", "output") and kind != var.causality:
            raise SspError(ssp, f"{label}: declared an {kind}, but its FMU's variable {cname} is an {var.causality}")
        declared = next((child.tag.rsplit("}", 1)[-1] for child in c if child.tag.startswith("{" + NS["ssc"] + "}")),
                        None)
        want = _SSP_TYPE.get(var.fmi_type)
        if declared in ("Real", "Integer", "Boolean", "String") and want is not None and declared != want:
            raise SspError(ssp, f"{label}: declared {declared}, but its FMU's variable {cname} is {var.fmi_type}")


def _fmu_defaults(ssp: Path, paths: list[Path]) -> tuple[float | None, float | None]:
    """(smallest default step, largest default stop time) over the FMUs' DefaultExperiment (read as the run reads
    them, once: :func:`cosim.fmi.load_fmu`)."""
    steps, stops = [], []
    for path in paths:
        try:
            de = load_fmu(path).md.defaultExperiment
        except CosimError as exc:
            raise SspError(ssp, f"{path.parent.name}: {exc}") from None
        if de is None:
            continue
        if de.stepSize is not None:
            steps.append(float(de.stepSize))
        if de.stopTime is not None:
            stops.append(float(de.stopTime))
    return (min(steps) if steps else None), (max(stops) if stops else None)


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


@contextmanager
def _unpacking(ssp: Path) -> Iterator[Path]:
    """A temporary folder for ``ssp``'s FMUs, removed when the block ends (also on error)."""
    sweep_orphans()  # archives unpacked by runs that were killed (SIGKILL) go now
    tmp = Path(tempfile.mkdtemp(prefix=f"{SSP_PREFIX}{os.getpid()}-{ssp.stem}-"))
    try:
        yield tmp
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _archive(ssp: Path, tmp: Path, sha256: str) -> dict[str, str]:
    """:attr:`cosim.engine.scenario.Scenario.archive` of a scenario read from ``ssp`` unpacked into ``tmp``."""
    return {"file": os.path.normpath(ssp.absolute()), "sha256": sha256, "unpacked": str(tmp)}


@contextmanager
def open_ssp(ssp: str | Path, overrides: dict[tuple, Any] | None = None) -> Iterator[Scenario]:
    """The scenario of an SSP archive, valid inside the ``with`` block (its FMUs are unpacked into a
    temporary directory removed when the block ends, also on error).

    ``overrides`` as for :func:`cosim.engine.scenario.load_scenario` (``--set``, ``--stop-time``, and
    ``("time", "step")`` for ``--step``). The scenario's :attr:`~cosim.engine.scenario.Scenario.archive` names the
    archive and its SHA-256, which a run's log records for :func:`reopen_ssp`.
    """
    ssp = Path(ssp)
    with _unpacking(ssp) as tmp:
        data = read_ssp(ssp, tmp)  # reads the file (an archive that is not one is named by it) before it is hashed
        sha256 = _sha256(ssp)
        overrides = dict(overrides or {})
        missing = [(key, flag) for key, flag in (("step", "--step"), ("stop", "--stop-time"))
                   if key not in data["time"] and ("time", key) not in overrides]
        if missing:
            what = " and ".join(f"the {'base step' if k == 'step' else 'stop time'}" for k, _ in missing)
            raise SspError(ssp, f"{what}: neither the SSD's default experiment nor the FMUs give it; "
                                f"pass {' and '.join(f for _, f in missing)}")
        scenario = scenario_from_data(data, str(ssp), overrides)
        scenario._archive = _archive(ssp, tmp, sha256)
        yield scenario


@contextmanager
def reopen_ssp(archive: dict[str, str], data: dict[str, Any], source: str,
               overrides: dict[tuple, Any] | None = None) -> Iterator[Scenario]:
    """The scenario ``data`` of a run made from an SSP archive (as its log records it: ``archive`` is the run's
    :attr:`~cosim.engine.scenario.Scenario.archive`), with its FMUs unpacked again from that archive for the
    ``with`` block; ``source`` names the log in messages.

    Raises :class:`SspError` naming ``source`` and the archive when the archive is gone, or is not the file the
    run was made from (its SHA-256 differs): the recorded scenario's values would not be the archive's.
    """
    try:
        ssp, sha256, unpacked = Path(archive["file"]), archive["sha256"], archive["unpacked"]
    except (KeyError, TypeError):
        raise SspError(source, f"the log's ssp metadata is incomplete ({archive!r}): expected file, sha256 and "
                               "unpacked") from None
    head = f"the run was made from the SSP archive {ssp}, which"
    problem = file_problem(ssp)  # the log names it: a FIFO or a device would be hashed for ever
    if problem not in (None, "no such file"):
        raise SspError(source, f"{head} cannot be read: {problem}")
    try:
        now = _sha256(ssp)
    except FileNotFoundError:
        raise SspError(source, f"{head} is gone: its FMUs were unpacked from it for the run only; put the archive "
                               "back to run the log again") from None
    except OSError as exc:
        raise SspError(source, f"{head} cannot be read: {exc.strerror or exc}") from None
    if now != sha256:
        raise SspError(source, f"{head} has changed since (SHA-256 {sha256[:16]}... then, {now[:16]}... now): the "
                               f"log's FMUs and values may no longer be the archive's; run the archive itself "
                               f"(`python -m cosim run {ssp}`)")
    with _unpacking(ssp) as tmp:
        read_ssp(ssp, tmp)  # the FMUs go where they went for the run, relative to the folder (numbered by place)
        for comp in (data.get("components") or {}).values():
            path = comp.get("path") if isinstance(comp, dict) else None
            if isinstance(path, str) and Path(path).is_relative_to(unpacked):
                comp["path"] = str(tmp / Path(path).relative_to(unpacked))
        scenario = scenario_from_data(data, source, overrides)
        scenario._archive = _archive(ssp, tmp, sha256)
        yield scenario


def is_ssp(path: str | Path) -> bool:
    return Path(path).suffix.lower() == ".ssp"


# --------------------------------------------------------------------------- CLI


def register(sub) -> None:
    """``python -m cosim ssp export SCENARIO -o SYSTEM.ssp``."""
    p = sub.add_parser("ssp", help="export a scenario as an SSP 1.0 archive (run one with `cosim run X.ssp`)")
    ssub = p.add_subparsers(dest="ssp_command", required=True, metavar="COMMAND")
    e = ssub.add_parser("export", help="write SystemStructure.ssd, one .ssv per component and the FMUs",
                        description="Writes the scenario as an SSP 1.0 archive (SystemStructure.ssd, a parameter "
                                    "set per component with every start value the master sets, the FMUs in "
                                    "resources/) that OSP libcosim and other SSP tools run.")
    e.add_argument("scenario", help="scenario file (YAML)")
    e.add_argument("-o", "--out", required=True, help="the .ssp file to write")
    e.add_argument("--stop-time", type=number_option(), help="override time.stop, s")
    e.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override by dotted name (repeatable): a component parameter (ctl.gain.kp[1]=4e4), the trajectory (trajectory.params.rx=0.05), the time grid (time.stop=0.5), any scenario key")
    e.add_argument("--json", action="store_true")
    e.set_defaults(handler=_cmd_export)


def _cmd_export(args) -> int:

    rep = export_ssp(load_scenario(args.scenario, apply_overrides(args.set, args.stop_time)), args.out)
    if args.json:
        print(json.dumps(rep.as_dict(), indent=2))
    else:
        print(rep.text())
    return 0
