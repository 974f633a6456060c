"""Import: an SSP 1.0 archive read into scenario data (see :mod:`cosim.io.ssp`): its .ssd checked (SSP 1.0, FMU
components only), the FMUs unpacked, parameter bindings applied, connections, time grid and algorithm from the
default experiment and the annotations (OSP's, OMSimulator's, ours)."""

from __future__ import annotations

import json
import math
import zipfile
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

from ...engine.grid import MAX_TIME_S
from ...engine.names import ref
from ...errors import CosimError, file_problem, shown
from ...fmi.description import load_fmu
from .archive import parse_xml, read_member
from .components import read_components
from .parameters import system_bindings
from .spec import (EXTRAS, NS, OMS_ANNOTATION, OSP_ANNOTATION, OUR_ANNOTATION, SSD_NAME, SspError, local_name, qname,
                   warn)
from .units import convert_units, unit_table

__all__ = ["read_ssp"]


def read_ssp(ssp: str | Path, workdir: str | Path) -> dict[str, Any]:
    """Read ``ssp`` into scenario data (the mapping :func:`cosim.engine.scenario.scenario_from_data` takes).

    The FMUs are unpacked into ``workdir`` (component ``path`` entries point there). The time
    grid may lack ``step`` or ``stop`` when neither the SSD nor the FMUs give one (the caller's
    ``--step`` / ``--stop-time`` overrides fill them in).
    """
    ssp, workdir = Path(ssp), Path(workdir)
    with _open_archive(ssp) as zf:
        members, root = _structure(zf, ssp)
        system = _system(root, ssp)
        extras = _our_annotation(root, system, ssp)
        options = extras.pop("component_options", {}) or {}
        _scenario_names(system, extras.pop("component_names", {}), ssp)
        ssd_units = unit_table(root, "ssd:Units/ssc:Unit", ssp, SSD_NAME)
        elements = system.find("ssd:Elements", NS)
        elements = list(elements) if elements is not None else []
        components, connectors, hints = read_components(elements, zf, ssp, workdir, members, options, ssd_units)
        system_bindings(system, zf, ssp, components, ssd_units)
        convert_units(components, ssp)
        connections = _connections(system, components, connectors, ssd_units, ssp)
        exp = root.find("ssd:DefaultExperiment", NS)
        time = _time_grid(exp, system, components, hints, ssp)
    data: dict[str, Any] = {"name": extras.pop("name", None) or root.get("name") or ssp.stem,
                            "components": components, "connections": connections, "time": time}
    if _osp_step(exp, ssp) is not None:  # libcosim's fixed_step_algorithm: every FMU from the last step's values
        data["algorithm"] = "jacobi"
    if root.get("description") and "description" not in extras:
        data["description"] = root.get("description")
    data.update({k: v for k, v in extras.items() if k in EXTRAS})
    return data


def _open_archive(ssp: Path) -> zipfile.ZipFile:
    problem = file_problem(ssp)  # a FIFO or /dev/zero named .ssp: zipfile would read it for ever
    if problem is not None:
        # Refused (security): a FIFO or a device named .ssp would be read for ever
        raise SspError(ssp, problem)
    try:
        return zipfile.ZipFile(ssp)
    except FileNotFoundError:
        # Refused (correctness): no archive, nothing to run
        raise SspError(ssp, "no such file") from None
    except (zipfile.BadZipFile, OSError) as exc:
        # Refused (correctness): not a zip: no member can be read
        raise SspError(ssp, f"not an SSP archive (a zip file): {exc}") from None


def _structure(zf: zipfile.ZipFile, ssp: Path) -> tuple[set[str], ET.Element]:
    """The archive's member names and its SystemStructure.ssd (SSP 1.0), each member once."""
    names = zf.namelist()
    members = set(names)
    if len(members) != len(names):  # zip readers differ on which copy they take: the archive means two things
        twice = sorted({n for n in names if names.count(n) > 1})
        # Refused (correctness): zip readers differ on which copy they take: the archive means two things
        raise SspError(ssp, f"the archive holds two members named {twice[0]!r}"
                            + (f" (and {len(twice) - 1} more)" if len(twice) > 1 else "") + ": refused")
    if SSD_NAME not in members:
        found = ", ".join(sorted(m for m in members if m.endswith(".ssd"))) or "none"
        # Refused (correctness): no system structure, nothing to run
        raise SspError(ssp, f"no {SSD_NAME} at the top of the archive (.ssd files found: {found})")
    root = parse_xml(read_member(zf, SSD_NAME, ssp), ssp, SSD_NAME)
    if root.tag.startswith("{http://ssp-standard.org/SSP2/"):
        # Refused (correctness): SSP 2.0's namespaces: nothing of it would be read, the run would be empty
        raise SspError(ssp, f"{SSD_NAME}: SSP 2.0 is not supported (SSP 1.0 only)")
    if root.tag != qname("ssd", "SystemStructureDescription"):
        # Refused (correctness): not a system structure: nothing of it would be read
        raise SspError(ssp, f"{SSD_NAME}: the root element is {root.tag}, expected ssd:SystemStructureDescription "
                            f"in namespace {NS['ssd']}")
    if not (root.get("version") or "").startswith("1."):  # OMSimulator 2 wrote "Draft20171219"; libcosim reads any
        warn(ssp, f"{SSD_NAME}: SSP version {root.get('version')!r} read as SSP 1.0 (its namespaces are SSP 1.0's)")
    return members, root


def _system(root: ET.Element, ssp: Path) -> ET.Element:
    """The SSD's system. Its own connectors and its signal dictionaries are left out with one warning each, as
    libcosim leaves them out: a connection to a system connector, or an element referring to a dictionary, is
    refused where it is read (:func:`_connections`, :func:`~cosim.io.ssp.components.read_components`)."""
    system = root.find("ssd:System", NS)
    if system is None:
        # Refused (correctness): no system, nothing to run
        raise SspError(ssp, f"{SSD_NAME}: no ssd:System element")
    connected = all(cn.get("startElement") and cn.get("endElement")
                    for cn in system.iterfind("ssd:Connections/ssd:Connection", NS))
    if system.find("ssd:Connectors", NS) is not None and connected:  # else the connection to one is refused
        warn(ssp, f"{SSD_NAME}: the system's own connectors are left out (no connection uses them)")
    referred = system.find("ssd:Elements/ssd:SignalDictionaryReference", NS) is not None  # refused as an element
    if system.find("ssd:SignalDictionaries", NS) is not None and not referred:
        warn(ssp, f"{SSD_NAME}: the system's signal dictionaries are left out (no component refers to them)")
    return system


def _our_annotation(root: ET.Element, system: ET.Element, ssp: Path) -> dict[str, Any]:
    """What our annotation carries (:func:`_annotation`), {} without one; it never chooses where the log goes."""
    extras: dict[str, Any] = {}
    for ann in [*system.iterfind("ssd:Annotations/ssc:Annotation", NS),  # ours, since OMSimulator's check
                *root.iterfind("ssd:Annotations/ssc:Annotation", NS)]:  # archives written before
        if ann.get("type") == OUR_ANNOTATION:
            node = ann.find("dcs:Scenario", NS)
            extras = _annotation(node.text or "{}", ssp) if node is not None else {}
    if isinstance(extras.get("logging"), dict) and extras["logging"].get("out") is not None:
        # Refused (security): an archive must not choose which file of the user's is written
        raise SspError(ssp, f"{SSD_NAME}: annotation {OUR_ANNOTATION} sets logging.out "
                            f"({extras['logging']['out']!r}): an archive cannot choose where the log is written; "
                            "give --out")
    return extras


def _scenario_names(system: ET.Element, renamed: dict[str, str], ssp: Path) -> None:
    """Give the system's components and connections the scenario's names where our export wrote others (names
    every SSP tool can address: :func:`cosim.io.ssp.write._archive_names`), from our annotation's
    ``component_names`` (archive name -> scenario name)."""
    if not renamed:
        return
    elements = system.findall("ssd:Elements/*", NS)
    present = {el.get("name") for el in elements}
    missing = sorted(set(renamed) - present)
    if missing:
        # Refused (correctness): a name mapped back onto no component would leave the scenario's name unbound
        raise SspError(ssp, f"{SSD_NAME}: annotation {OUR_ANNOTATION}: component_names names {missing[0]!r}, which "
                            f"is no component of the system ({', '.join(sorted(n for n in present if n))})")
    final = [renamed.get(n, n) for n in present]
    twice = next((n for n in final if final.count(n) > 1), None)
    if twice is not None:
        # Refused (correctness): two components of one name would be ambiguous wherever the scenario names one
        raise SspError(ssp, f"{SSD_NAME}: annotation {OUR_ANNOTATION}: component_names gives two components the "
                            f"name {twice!r}")
    for el in elements:
        el.set("name", renamed.get(el.get("name"), el.get("name")))
    for cn in system.iterfind("ssd:Connections/ssd:Connection", NS):
        for side in ("startElement", "endElement"):
            if cn.get(side) in renamed:
                cn.set(side, renamed[cn.get(side)])


def _same_units(cn: ET.Element, connectors: dict[str, dict[str, tuple]], units: dict[str, tuple], ssp: Path,
                label: str) -> None:
    """Refuse a connection whose connectors declare different units (correctness: SSP converts between them, which
    this reader does not; m to s cannot be converted at all, and was passed on silently). The same unit, or a side
    without one, passes; ``suppressUnitConversion`` passes the numbers as they are (not checked here)."""
    a = connectors[cn.get("startElement")][cn.get("startConnector")][1]
    b = connectors[cn.get("endElement")][cn.get("endConnector")][1]
    if a is None or b is None or a == b:
        return
    da, db = units.get(a), units.get(b)
    if da is not None and db is not None and da[0] != db[0]:
        # Refused (correctness): no conversion connects m to s: the value would be passed on meaning another thing
        raise SspError(ssp, f"{label}: the connectors' units {a!r} and {b!r} are of different dimensions: no "
                            "conversion connects them (suppressUnitConversion=\"true\" passes the numbers as they are)")
    # Refused (correctness): SSP converts between the two units, which this reader does not: the value would be off
    raise SspError(ssp, f"{label}: the connectors' units differ ({a!r} -> {b!r}) and unit conversion on "
                        "connections is not supported: declare one unit, or set suppressUnitConversion=\"true\" "
                        "to pass the numbers as they are")


def _connections(system: ET.Element, components: dict[str, dict[str, Any]], connectors: dict[str, dict[str, tuple]],
                 units: dict[str, tuple], ssp: Path) -> list[dict[str, str]]:
    """The system's connections as scenario data, each end a component's connector (no transformation; connector
    units checked by :func:`_same_units` against the SSD's ``units``)."""
    connections = []
    for cn in system.iterfind("ssd:Connections/ssd:Connection", NS):
        ends = []
        for side, role in (("start", "output"), ("end", "input")):
            elem, conn = cn.get(f"{side}Element"), cn.get(f"{side}Connector")
            label = f"connection {cn.get('startElement')}.{cn.get('startConnector')} -> " \
                    f"{cn.get('endElement')}.{cn.get('endConnector')}"
            if elem is None:
                # Refused (correctness): the system's connectors are left out: the input would get no value
                raise SspError(ssp, f"{label}: connections to the system's own connectors are not supported")
            if elem not in components:
                # Refused (correctness): a connection to nothing: the input would get no value
                raise SspError(ssp, f"{label}: no component named {elem!r} (components: "
                                    f"{', '.join(components)})")
            if conn not in connectors[elem]:
                known = ", ".join(sorted(connectors[elem])[:12]) or "none"
                # Refused (correctness): a connection to nothing: the input would get no value
                raise SspError(ssp, f"{label}: component {elem!r} has no connector {conn!r} (connectors: {known})")
            ends.append(ref(elem, conn))
        if cn.find("ssc:LinearTransformation", NS) is not None or any(
                child.tag.endswith("MappingTransformation") for child in cn):
            # Refused (correctness): the value would reach the input untransformed
            raise SspError(ssp, f"connection {ends[0]} -> {ends[1]}: transformations are not supported")
        connection = {"from": ends[0], "to": ends[1]}
        if cn.get("suppressUnitConversion", "false").strip() in ("true", "1"):
            connection["units"] = "as_is"  # the numbers pass as they are, whatever the connectors' units
        else:
            _same_units(cn, connectors, units, ssp, f"connection {ends[0]} -> {ends[1]}")
        connections.append(connection)
    return connections


def _time_grid(exp: ET.Element | None, system: ET.Element, components: dict[str, dict[str, Any]],
               hints: dict[str, float], ssp: Path) -> dict[str, float]:
    """The time grid (start, stop, base step: the default experiment, the annotations, else the FMUs'), and each
    component's step multiple from its step size hint."""
    time: dict[str, float] = {}
    for key, attr in (("start", "startTime"), ("stop", "stopTime")):
        if exp is not None and exp.get(attr) is not None:
            try:
                time[key] = _time(float(exp.get(attr)))
            except ValueError:
                # Refused (correctness): the run's time grid would be a guess
                raise SspError(ssp, f"ssd:DefaultExperiment {attr} {exp.get(attr)!r} is not a number") from None
    step = _osp_step(exp, ssp)
    oms_step = _oms_step(system, ssp)
    if step is not None and oms_step is not None and step != oms_step:
        # Refused (correctness): two base steps: which one the file means is a guess
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
            multiple = round(m)
            if abs(m - multiple) > 1e-9 * abs(m) or multiple < 1:  # libcosim takes the same multiple, with a warning
                multiple = max(1, math.floor(m))
                warn(ssp, f"component {name!r}: osp:StepSizeHint {hint:g} s is not a whole multiple of the base step "
                          f"{step:g} s: it steps every {multiple * step:g} s, as libcosim does")
            if multiple > 1:
                components[name]["step_multiple"] = multiple
    return time


def _annotation(text: str, ssp: Path) -> dict[str, Any]:
    """Our annotation's JSON: an object, each key once, with keys of the scenario's sections only; nesting, numbers
    and everything else JSON allows but no scenario holds are one error naming the annotation."""
    where = f"{SSD_NAME}: annotation {OUR_ANNOTATION}"

    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        keys = [k for k, _ in items]
        twice = next((k for k in keys if keys.count(k) > 1), None)
        if twice is not None:
            # Refused (correctness): which value is meant is a guess (JSON readers differ)
            raise SspError(ssp, f"{where}: the key {twice!r} is given twice")
        return dict(items)

    try:
        data = json.loads(text, object_pairs_hook=pairs)
    except json.JSONDecodeError as exc:
        # Refused (correctness): our annotation's options cannot be read: the run would lack them
        raise SspError(ssp, f"{where}: not valid JSON ({exc})") from None
    except SspError:  # a key given twice
        raise
    except (RecursionError, ValueError) as exc:  # nested too deep, an integer of thousands of digits
        # Refused (security): nesting or integers past what a scenario holds cost memory and time
        raise SspError(ssp, f"{where}: not a scenario's JSON ({str(exc)[:120]})") from None
    if not isinstance(data, dict):
        # Refused (correctness): our annotation's options cannot be read: the run would lack them
        raise SspError(ssp, f"{where}: expected a JSON object, got {type(data).__name__}")
    unknown = sorted(set(data) - {*EXTRAS, "name", "component_options", "component_names"})
    if unknown:
        # Refused (correctness): a section we do not know would be dropped silently
        raise SspError(ssp, f"{where}: unknown key {unknown[0]!r} (an archive's annotation carries "
                            f"{', '.join(EXTRAS)}, name, component_options and component_names)")
    renamed = data.get("component_names", {})
    if not isinstance(renamed, dict) or not all(isinstance(v, str) and v for v in renamed.values()):
        # Refused (correctness): a mapping of another shape names no component the run could be placed by
        raise SspError(ssp, f"{where}: component_names must map the archive's component names to the scenario's "
                            f"(strings), got {_shape(renamed)}")
    options = data.get("component_options", {})
    if not isinstance(options, dict) or not all(isinstance(v, dict) for v in options.values()):
        # Refused (correctness): options of the wrong shape cannot be applied
        raise SspError(ssp, f"{where}: component_options must map component names to objects of their options, "
                            f"got {_shape(options)}")
    if not isinstance(data.get("name", ""), str):
        # Refused (correctness): a name of the wrong shape cannot name the run
        raise SspError(ssp, f"{where}: name must be a string, got {_shape(data['name'])}")
    return data


def _shape(value: Any) -> str:
    """What a JSON value is, for a message (not the value: it may be large)."""
    if isinstance(value, dict):
        inner = {type(v).__name__ for v in value.values()}
        return f"an object of {', '.join(sorted(inner)) or 'nothing'}"
    return {list: "a list", str: "a string", bool: "a boolean", type(None): "null"}.get(type(value), "a number")


def _fmu_defaults(ssp: Path, paths: list[Path]) -> tuple[float | None, float | None]:
    """(smallest default step, largest default stop time) over the FMUs' DefaultExperiment (read as the run reads
    them, once: :func:`cosim.fmi.load_fmu`)."""
    steps, stops = [], []
    for path in paths:
        try:
            de = load_fmu(path).md.defaultExperiment
        except CosimError as exc:
            # Refused (correctness): an FMU the run cannot read (the error of load_fmu, named by component)
            raise SspError(ssp, f"{path.parent.name}: {exc}") from None
        if de is None:
            continue
        if de.stepSize is not None:
            steps.append(float(de.stepSize))
        if de.stopTime is not None:
            stops.append(float(de.stopTime))
    return (min(steps) if steps else None), (max(stops) if stops else None)


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
        # Refused (correctness): the base step would be a guess
        raise SspError(ssp, f"{what} {shown(repr(text))} is not a number") from None
    if not step > 0 or not math.isfinite(step):
        # Refused (correctness): no grid steps forward by a step <= 0 or not finite
        raise SspError(ssp, f"{what} must be > 0, got {step}")
    return step


def _oms_step(system: ET.Element, ssp: Path) -> float | None:
    """The base step of OMSimulator's annotation on the system (its ``SystemWC``: ``<ssc:Annotation
    type="org.openmodelica"><oms:Annotations><oms:SimulationInformation><oms:FixedStepMaster
    stepSize=.../>``; ``oms:VariableStepMaster``: its ``maximumStepSize``), if any. Tags are matched by
    local name, as OMSimulator matches them by its own prefix without resolving namespaces."""
    for ann in system.iterfind("ssd:Annotations/ssc:Annotation", NS):
        if ann.get("type") != OMS_ANNOTATION:
            continue
        for info in ann.iter():
            if local_name(info) != "SimulationInformation":
                continue
            for master in info:
                attr = {"FixedStepMaster": "stepSize", "VariableStepMaster": "maximumStepSize"}.get(local_name(master))
                if attr is None:
                    continue
                return _positive_step(master.get(attr), f"{SSD_NAME}: OMSimulator's {local_name(master)} {attr}", ssp)
    return None


def _time(x: float) -> float:
    """A time read as a double, rounded to whole nanoseconds (the master's resolution); one no grid can hold (nan,
    an infinity, past :data:`~cosim.engine.grid.MAX_TIME_S`) as it is, for the scenario's check to name."""
    return round(x * 1e9) / 1e9 if abs(x) <= MAX_TIME_S else x
