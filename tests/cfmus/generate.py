"""Turn a ``models.Model`` into modelDescription.xml and the C variable table.

The two outputs come from one description, so the value references, types,
causalities and array sizes the binary knows are the ones the XML declares.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from .models import UNITS, Model, Var

__all__ = ["model_description", "variables_header", "CS_FIXED_STEP"]

GENERATOR = "delta-cosim tests/cfmus"
CS_FIXED_STEP = 1e-3  # s, the CS_FIXED_STEP of c/core.h
LOG_CATEGORIES = (
    ("logEvents", "Events and time steps (when debug logging is on)"),
    ("logStatusWarning", "Warnings"),
    ("logStatusDiscard", "Rejected or shortened steps"),
    ("logStatusError", "Errors"),
)
_FMI2_TYPES = {"Float64": "Real", "Int32": "Integer", "Boolean": "Boolean", "String": "String",
               "Enumeration": "Enumeration"}
_DEFAULT_INITIAL = {  # (variability, causality) -> initial, FMI 2 table 3 / FMI 3 table 22
    ("constant", "output"): "exact",
    ("constant", "local"): "exact",
    ("fixed", "parameter"): "exact",
    ("fixed", "structuralParameter"): "exact",
    ("tunable", "parameter"): "exact",
    ("fixed", "calculatedParameter"): "calculated",
    ("discrete", "input"): "exact",
    ("continuous", "input"): "exact",
    ("discrete", "output"): "calculated",
    ("continuous", "output"): "calculated",
    ("discrete", "local"): "calculated",
    ("continuous", "local"): "calculated",
}


def _effective_initial(v: Var) -> str | None:
    if v.causality == "independent":
        return None
    return v.initial or _DEFAULT_INITIAL[(v.variability, v.causality)]


def _fmt(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, bytes):
        return value.hex()
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return " ".join(_fmt(x) for x in value)
    return str(value)


def _initial_unknowns(model: Model) -> list[Var]:
    """The set FMI 2 section 3.3.3 / FMI 3 section 2.4.8 prescribe."""
    by_name = {v.name: v for v in model.variables}
    chosen = []
    for v in model.variables:
        init = _effective_initial(v)
        if v.causality == "output" and init in ("approx", "calculated") and not dict(v.attributes).get("clocks"):
            chosen.append(v)
        elif v.causality == "calculatedParameter":
            chosen.append(v)
        elif v.derivative and init in ("approx", "calculated"):
            chosen.append(v)
    for v in model.variables:
        if v.derivative:
            state = by_name[v.derivative]
            if _effective_initial(state) in ("approx", "calculated") and state not in chosen:
                chosen.append(state)
    return sorted(chosen, key=lambda v: model.variables.index(v))


def _common_root(model: Model, token: str) -> ET.Element:
    root = ET.Element("fmiModelDescription")
    root.set("fmiVersion", "2.0" if model.fmi == 2 else "3.0")
    root.set("modelName", model.name)
    root.set("guid" if model.fmi == 2 else "instantiationToken", token)
    root.set("description", model.description)
    root.set("generationTool", GENERATOR)
    root.set("variableNamingConvention", "structured")
    if model.fmi == 2:
        root.set("numberOfEventIndicators", str(len(model.event_indicators)))
    return root


def _interfaces(root: ET.Element, model: Model) -> None:
    state = "true" if model.fmu_state else "false"  # get/set and serialize come together, as in the Reference FMUs
    if model.fmi == 2:
        ET.SubElement(root, "ModelExchange", modelIdentifier=model.name,
                      completedIntegratorStepNotNeeded="false" if model.step_events else "true",
                      canNotUseMemoryManagementFunctions="true", canGetAndSetFMUstate=state,
                      canSerializeFMUstate=state)
        ET.SubElement(root, "CoSimulation", modelIdentifier=model.name, canHandleVariableCommunicationStepSize="true",
                      canNotUseMemoryManagementFunctions="true", canGetAndSetFMUstate=state,
                      canSerializeFMUstate=state)
    else:
        ET.SubElement(root, "ModelExchange", modelIdentifier=model.name,
                      needsCompletedIntegratorStep="true" if model.step_events else "false",
                      canGetAndSetFMUState=state, canSerializeFMUState=state)
        cs = ET.SubElement(root, "CoSimulation", modelIdentifier=model.name,
                           canHandleVariableCommunicationStepSize="true", fixedInternalStepSize=repr(CS_FIXED_STEP),
                           canGetAndSetFMUState=state, canSerializeFMUState=state)
        if model.might_return_early:
            cs.set("mightReturnEarlyFromDoStep", "true")


def _definitions(root: ET.Element, model: Model) -> None:
    if model.units:
        units = ET.SubElement(root, "UnitDefinitions")
        for name in model.units:
            ET.SubElement(ET.SubElement(units, "Unit", name=name), "BaseUnit",
                          {k: str(e) for k, e in UNITS[name].items()})
    if model.enumerations:
        types = ET.SubElement(root, "TypeDefinitions")
        for name, items in model.enumerations.items():
            if model.fmi == 2:
                parent = ET.SubElement(ET.SubElement(types, "SimpleType", name=name), "Enumeration")
            else:
                parent = ET.SubElement(types, "EnumerationType", name=name)
            for item, value in items:
                ET.SubElement(parent, "Item", name=item, value=str(value))
    cats = ET.SubElement(root, "LogCategories")
    for name, text in LOG_CATEGORIES:
        ET.SubElement(cats, "Category", name=name, description=text)
    ET.SubElement(root, "DefaultExperiment", {k: repr(float(x)) for k, x in model.experiment.items()})


def _variable_attributes(v: Var) -> dict[str, str]:
    a = {"name": v.name, "valueReference": str(v.vr), "description": v.description, "causality": v.causality}
    if v.variability:
        a["variability"] = v.variability
    if v.initial and v.type != "Clock":
        a["initial"] = v.initial
    return a


def _type_attributes(model: Model, v: Var, index: dict[str, int]) -> dict[str, str]:
    a = {}
    if v.declared_type:
        a["declaredType"] = v.declared_type
    if v.unit:
        a["unit"] = v.unit
    if v.nominal is not None:
        a["nominal"] = repr(float(v.nominal))
    if v.derivative:
        a["derivative"] = str(index[v.derivative])
    if v.start is not None and v.type not in ("String", "Binary") or (model.fmi == 2 and v.start is not None):
        a["start"] = _fmt(v.start)
    a.update(dict(v.attributes))
    return a


def _variables_fmi2(root: ET.Element, model: Model) -> dict[str, int]:
    index = {v.name: i for i, v in enumerate(model.variables, start=1)}
    mv = ET.SubElement(root, "ModelVariables")
    for v in model.variables:
        sv = ET.SubElement(mv, "ScalarVariable", _variable_attributes(v))
        ET.SubElement(sv, _FMI2_TYPES[v.type], _type_attributes(model, v, index))
    return index


def _variables_fmi3(root: ET.Element, model: Model) -> dict[str, int]:
    vrs = {v.name: v.vr for v in model.variables}
    mv = ET.SubElement(root, "ModelVariables")
    for v in model.variables:
        el = ET.SubElement(mv, v.type, {**_variable_attributes(v), **_type_attributes(model, v, vrs)})
        if v.type in ("String", "Binary") and v.start is not None:
            ET.SubElement(el, "Start", value=_fmt(v.start))
        for d in v.dims:
            if isinstance(d, int):
                ET.SubElement(el, "Dimension", start=str(d))
            else:
                ET.SubElement(el, "Dimension", valueReference=str(vrs[d]))
    return vrs


def _structure(root: ET.Element, model: Model, ref: dict[str, int]) -> None:
    ms = ET.SubElement(root, "ModelStructure")
    key = "index" if model.fmi == 2 else "valueReference"

    def unknown(parent: ET.Element, tag: str, name: str, deps: list[str] | None) -> None:
        a = {key: str(ref[name])}
        if deps is not None:
            a["dependencies"] = " ".join(str(ref[d]) for d in sorted(deps, key=lambda d: ref[d]))
        ET.SubElement(parent, tag, a)

    order = {v.name: i for i, v in enumerate(model.variables)}
    initial = _initial_unknowns(model)
    if model.fmi == 2:
        for tag, items in (("Outputs", model.outputs), ("Derivatives", model.derivatives)):
            if items:
                parent = ET.SubElement(ms, tag)
                for name in sorted(items, key=order.get):
                    unknown(parent, "Unknown", name, items[name])
        if initial:
            parent = ET.SubElement(ms, "InitialUnknowns")
            for v in initial:
                unknown(parent, "Unknown", v.name, None)
    else:
        for tag, items in (("Output", model.outputs), ("ContinuousStateDerivative", model.derivatives)):
            for name in sorted(items, key=order.get):
                unknown(ms, tag, name, items[name])
        for v in initial:
            unknown(ms, "InitialUnknown", v.name, None)
        for name, deps in model.event_indicators.items():
            unknown(ms, "EventIndicator", name, deps)


_FMI1_VARIABILITY = {"fixed": "parameter", "tunable": "parameter"}  # FMI 1.0 has no tunable parameters
_FMI1_CAUSALITY = {"parameter": "internal", "local": "internal", "calculatedParameter": "internal"}


def _model_description_fmi1(model: Model, token: str, interface: str) -> ET.Element:
    """FMI 1.0: one interface per file (co-simulation announced by ``<Implementation>``), function names
    prefixed with the model identifier, each output's ``DirectDependency`` (the inputs of its FMI 2 / 3
    ModelStructure entry), the states counted on the root element, no independent variable."""
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "1.0", "modelName": model.name, "modelIdentifier": model.name, "guid": token,
        "description": model.description, "generationTool": GENERATOR, "variableNamingConvention": "structured",
        "numberOfContinuousStates": str(len(model.derivatives)),
        "numberOfEventIndicators": str(len(model.event_indicators))})
    if model.units:
        units = ET.SubElement(root, "UnitDefinitions")
        for name in model.units:
            ET.SubElement(units, "BaseUnit", unit=name)
    if model.enumerations:
        types = ET.SubElement(root, "TypeDefinitions")
        for name, items in model.enumerations.items():
            enum = ET.SubElement(ET.SubElement(types, "Type", name=name), "EnumerationType")
            for item, value in items:  # FMI 1.0 numbers the items 1, 2, ... in order
                assert value == len(enum) + 1, f"{name}.{item}: FMI 1.0 enumeration values are 1, 2, ..."
                ET.SubElement(enum, "Item", name=item, description=item)
    ET.SubElement(root, "DefaultExperiment", {k: repr(float(model.experiment[k])) for k in ("startTime", "stopTime")})
    mv = ET.SubElement(root, "ModelVariables")
    inputs = {v.name for v in model.variables if v.causality == "input"}
    for v in model.variables:
        if v.causality == "independent":
            continue
        sv = ET.SubElement(mv, "ScalarVariable", {
            "name": v.name, "valueReference": str(v.vr), "description": v.description,
            "variability": _FMI1_VARIABILITY.get(v.variability, v.variability),
            "causality": _FMI1_CAUSALITY.get(v.causality, v.causality)})
        a = {}
        if v.declared_type:
            a["declaredType"] = v.declared_type
        if v.unit:
            a["unit"] = v.unit
        if v.nominal is not None:
            a["nominal"] = repr(float(v.nominal))
        if v.start is not None and _effective_initial(v) != "calculated":
            a["start"] = _fmt(v.start)
        ET.SubElement(sv, _FMI2_TYPES[v.type], a)
        if v.causality == "output" and model.outputs.get(v.name) is not None:  # FMI 1.0's ModelStructure
            dep = ET.SubElement(sv, "DirectDependency")
            for name in model.outputs[v.name]:
                if name in inputs:
                    ET.SubElement(dep, "Name").text = name
    if interface == "cs":
        cs = ET.SubElement(ET.SubElement(root, "Implementation"), "CoSimulation_StandAlone")
        ET.SubElement(cs, "Capabilities", canHandleVariableCommunicationStepSize="true", canHandleEvents="true",
                      canRejectSteps="false", canInterpolateInputs="false", maxOutputDerivativeOrder="0",
                      canRunAsynchronuously="false", canSignalEvents="false",
                      canBeInstantiatedOnlyOncePerProcess="false", canNotUseMemoryManagementFunctions="true")
    return root


def model_description(model: Model, token: str, interface: str | None = None) -> bytes:
    """modelDescription.xml of ``model`` with the GUID / instantiationToken ``token``; FMI 1.0 needs the
    ``interface`` ("cs" or "me") of the file."""
    if model.fmi == 1:
        root = _model_description_fmi1(model, token, interface)
        ET.indent(root)
        return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8") + b"\n"
    root = _common_root(model, token)
    _interfaces(root, model)
    _definitions(root, model)
    ref = _variables_fmi2(root, model) if model.fmi == 2 else _variables_fmi3(root, model)
    _structure(root, model, ref)
    ET.indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8") + b"\n"


# --------------------------------------------------------------------------- C table

_C_TYPES = {
    "Float32": "T_FLOAT32", "Float64": "T_FLOAT64", "Int8": "T_INT8", "UInt8": "T_UINT8", "Int16": "T_INT16",
    "UInt16": "T_UINT16", "Int32": "T_INT32", "UInt32": "T_UINT32", "Int64": "T_INT64", "UInt64": "T_UINT64",
    "Boolean": "T_BOOL", "String": "T_STRING", "Binary": "T_BINARY", "Enumeration": "T_ENUM", "Clock": "T_CLOCK",
}
_C_CAUSALITY = {
    "parameter": "CAUS_PARAMETER", "structuralParameter": "CAUS_STRUCTURAL", "calculatedParameter": "CAUS_CALCULATED",
    "input": "CAUS_INPUT", "output": "CAUS_OUTPUT", "local": "CAUS_LOCAL", "independent": "CAUS_INDEPENDENT",
}
_C_VARIABILITY = {"constant": "VAR_CONSTANT", "fixed": "VAR_FIXED", "tunable": "VAR_TUNABLE",
                  "discrete": "VAR_DISCRETE", "continuous": "VAR_CONTINUOUS"}
_C_INITIAL = {None: "INIT_NONE", "exact": "INIT_EXACT", "approx": "INIT_APPROX", "calculated": "INIT_CALCULATED"}


def variables_header(model: Model) -> str:
    """``variables.h``: MODEL_VARS for the ModelData struct of the model's C file."""
    vrs = {v.name: v.vr for v in model.variables}
    rows = []
    for v in model.variables:
        dims = []
        for d in v.dims:
            dims.append(f"{{{d}, -1}}" if isinstance(d, int) else f"{{0, {vrs[d]}}}")
        dims += ["{0, -1}"] * (2 - len(dims))
        offset = "0" if v.causality == "independent" else f"offsetof(ModelData, {v.field or v.name})"
        indirect = "true" if any(isinstance(d, str) for d in v.dims) else "false"
        rows.append(
            f'    {{{v.vr}, "{v.name}", {_C_TYPES[v.type]}, {_C_CAUSALITY[v.causality]}, '
            f"{_C_VARIABILITY[v.variability]}, {_C_INITIAL[_effective_initial(v)]}, {offset}, {indirect}, "
            f"{len(v.dims)}, {{{', '.join(dims)}}}}},"
        )
    return (
        f"/* Generated by tests/cfmus/generate.py for {model.name} (FMI {model.fmi}): do not edit. */\n"
        "const VarInfo MODEL_VARS[] = {\n" + "\n".join(rows) + "\n};\n"
        "const size_t MODEL_N_VARS = sizeof MODEL_VARS / sizeof MODEL_VARS[0];\n"
    )
