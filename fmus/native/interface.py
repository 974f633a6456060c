"""The interface of a native FMU, read from its python adapter, and its modelDescription.xml (FMI 2 and 3).

Each FMU's variables (names, units, start values, causality, variability, ModelStructure
dependencies) are declared once, in its adapter's ``__init__`` (:mod:`fmus.adapters`). The native
build instantiates that adapter (without running it: :func:`fmus.adapters.common.declared`) and reads its
declarations, so both builds have one interface; a model-exchange native model's continuous states are
those its model-exchange adapter declares (:attr:`~fmus.native.models.NativeModel.me_adapter`).
Value references: 0 is the time (FMI 3's independent variable; implicit in FMI 2), then
the adapter's variables in declaration order, then the derivatives of the model-exchange states.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING
from xml.etree.ElementTree import Element, SubElement, indent, tostring

from .._names import UNITS, initial_knowns
from ..adapters.common import declared
from .errors import NativeError
if TYPE_CHECKING:  # the models import CasADi: model_description, which a cached build's run reaches, does not need it
    from .models import NativeModel

__all__ = ["Variable", "Interface", "interface", "model_description"]


@dataclass(frozen=True)
class Variable:
    """One FMI variable of a native FMU; ``vr`` indexes the C model's values array."""

    vr: int
    name: str
    type: str  # "real" | "boolean" | "integer" | "string"
    causality: str  # "parameter" | "input" | "output" | "local" | "independent"
    variability: str  # "fixed" | "tunable" | "discrete" | "continuous"
    start: float | None
    unit: str | None
    description: str
    depends: tuple[str, ...] | None = None  # outputs and derivatives: the knowns they depend on directly
    derivative_of: str | None = None  # a derivative: the state it is the derivative of
    choices: tuple[str, ...] = ()  # a String: the values it may take (its start is their index)


@dataclass(frozen=True)
class Interface:
    name: str
    description: str
    variables: tuple[Variable, ...]
    experiment: tuple[float, float, float]
    states: tuple[tuple[str, str], ...]  # (continuous state, its derivative), model exchange
    me_advances: bool = False  # model exchange commits the internal state at completed integrator steps
    me_accepts: bool = False  # model exchange checks the state at completed integrator steps

    @property
    def needs_completed_step(self) -> bool:
        """Model exchange needs ``completedIntegratorStep`` (to commit its internal state, or check the state)."""
        return self.me_advances or self.me_accepts

    def by_name(self) -> dict[str, Variable]:
        return {v.name: v for v in self.variables}


def interface(name: str, model: NativeModel) -> Interface:
    """The interface of FMU ``name``: its adapter's variables, plus the model-exchange states' derivatives."""
    adapter = declared(model.adapter, model.kind, name)
    variables = [Variable(0, "time", "real", "independent", "continuous", None, "s", "simulation time")]
    state_deps: dict[str, tuple[str, ...]] = {}
    me, continuous = None, ()
    if model.me_adapter is not None:
        me = declared(model.me_adapter, model.kind, name)
        state_deps = dict(me._depends)
        continuous = tuple(zip(*me._state_order))  # (state, derivative), in ModelStructure order
    for spec in adapter.specs:
        depends = None
        if spec.causality == "output":
            extra = tuple(d for d in state_deps.get(spec.name, ()) if d not in spec.depends)
            depends = tuple(spec.depends) + extra
        choices: tuple[str, ...] = ()
        start = None if spec.causality == "output" else spec.start
        if spec.kind == "string":
            choices = tuple(model.choices.get(spec.name, ()))
            if spec.start not in choices:
                raise NativeError(f"FMU {name}: String variable {spec.name!r} has no closed set of values that "
                                  f"holds its start {spec.start!r}: it cannot be native")
            start = choices.index(spec.start)
        variables.append(Variable(len(variables), spec.name, spec.kind, spec.causality, spec.variability,
                                  None if start is None else float(start), spec.unit, spec.description, depends,
                                  choices=choices))
    units = {v.name: v.unit for v in variables}
    for state, der in continuous:
        der_var = next((v for v in me.vars.values() if v.name == der), None)
        variables.append(Variable(len(variables), der, "real", "local", "continuous", None,
                                  getattr(der_var, "unit", None) or units.get(state),
                                  f"time derivative of {state}", state_deps.get(der, ()), state))
    missing = [s for s, _ in continuous if s not in units]
    if missing:
        raise ValueError(f"FMU {name}: model-exchange states {missing} are not variables of "
                         f"{model.adapter.__qualname__}")
    return Interface(name, adapter.description, tuple(variables), tuple(adapter.EXPERIMENT), continuous,
                     model.me_advances, model.me_accepts)


# ----------------------------------------------------------------------------- modelDescription.xml

LOG_CATEGORIES = (("logAll", "information"),
                  ("logStatusWarning", "a check that failed without stopping the model (e.g. an unreachable "
                                       "reference held)"),
                  ("logStatusDiscard", "a step that could not be taken (the reason is given)"),
                  ("logStatusError", "a call that failed (the reason is given)"))
"""The categories of the C glue's log messages (``c/runtime.c``)."""


def _initial(v: Variable) -> str | None:
    if v.causality in ("output", "local"):
        return "calculated"
    if v.causality == "parameter":
        return "exact"
    return None


def _units(root: Element, variables) -> None:  # noqa: ANN001
    used = sorted({v.unit for v in variables if v.unit is not None})
    if not used:
        return
    defs = SubElement(root, "UnitDefinitions")
    for unit in used:
        SubElement(SubElement(defs, "Unit", name=unit), "BaseUnit", {k: str(e) for k, e in UNITS[unit].items() if e})


def _fmt(x: float) -> str:
    return repr(float(x))


def _common(root: Element, itf: Interface, variables) -> Element:  # noqa: ANN001
    """UnitDefinitions, LogCategories and DefaultExperiment (the same in FMI 2 and 3); returns ModelVariables."""
    _units(root, variables)
    categories = SubElement(root, "LogCategories")
    for name, text in LOG_CATEGORIES:
        SubElement(categories, "Category", name=name, description=text)
    SubElement(root, "DefaultExperiment", startTime=_fmt(itf.experiment[0]), stopTime=_fmt(itf.experiment[1]),
               stepSize=_fmt(itf.experiment[2]))
    return SubElement(root, "ModelVariables")


def _attributes(v: Variable) -> dict[str, str]:
    """The attributes of a variable's element common to FMI 2 and 3 (only Reals may be continuous: a
    boolean or integer that changes in time is discrete)."""
    variability = "discrete" if v.type != "real" and v.variability == "continuous" else v.variability
    attrs = {"name": v.name, "valueReference": str(v.vr), "description": v.description,
             "causality": v.causality, "variability": variability}
    initial = _initial(v)
    if initial:
        attrs["initial"] = initial
    return attrs


def _initial_knowns(itf: Interface, v: Variable) -> set[str]:
    """The knowns InitialUnknown ``v`` depends on: the rule of the python builds (:func:`fmus._names.initial_knowns`)."""
    return initial_knowns(v.depends or (), {u.name for u in itf.variables if u.causality == "input"},
                          [p.name for p in itf.variables if p.causality == "parameter"])


def model_description(itf: Interface, fmi: int, token: str, sources: list[str]) -> bytes:
    """modelDescription.xml of the native FMU for FMI ``fmi`` (2 or 3): co-simulation and model exchange."""
    if fmi == 2:
        return _fmi2(itf, token, sources)
    return _fmi3(itf, token)


def _fmi2(itf: Interface, token: str, sources: list[str]) -> bytes:
    variables = [v for v in itf.variables if v.causality != "independent"]
    index = {v.name: i + 1 for i, v in enumerate(variables)}
    root = Element("fmiModelDescription", fmiVersion="2.0", modelName=itf.name, guid=token,
                   description=itf.description, generationTool="delta-cosim fmus.native (CasADi)",
                   variableNamingConvention="structured", numberOfEventIndicators="0")
    for element in ("ModelExchange", "CoSimulation"):
        attrs = {"modelIdentifier": itf.name, "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true"}
        if element == "CoSimulation":
            attrs.update(canHandleVariableCommunicationStepSize="true")
        elif itf.needs_completed_step:
            attrs.update(completedIntegratorStepNotNeeded="false")
        node = SubElement(root, element, attrs)
        files = SubElement(node, "SourceFiles")
        for src in sources:
            SubElement(files, "File", name=src)
    mvars = _common(root, itf, variables)
    for v in variables:
        sv = SubElement(mvars, "ScalarVariable", _attributes(v))
        if v.type == "real":
            real = {"unit": v.unit} if v.unit else {}
            if v.start is not None:
                real["start"] = _fmt(v.start)
            if v.derivative_of is not None:
                real["derivative"] = str(index[v.derivative_of])
            SubElement(sv, "Real", real)
        elif v.type == "boolean":
            SubElement(sv, "Boolean", {} if v.start is None else {"start": "true" if v.start else "false"})
        elif v.type == "string":
            SubElement(sv, "String", {"start": v.choices[int(v.start)]})
        else:
            SubElement(sv, "Integer", {} if v.start is None else {"start": str(int(v.start))})
    structure = SubElement(root, "ModelStructure")
    outputs = [v for v in variables if v.causality == "output"]
    if outputs:
        node = SubElement(structure, "Outputs")
        for v in outputs:
            deps = " ".join(str(index[d]) for d in sorted(v.depends or (), key=index.get))
            SubElement(node, "Unknown", index=str(index[v.name]), dependencies=deps)
    derivatives = [v for v in variables if v.derivative_of is not None]
    if derivatives:
        node = SubElement(structure, "Derivatives")
        for v in derivatives:
            deps = " ".join(str(index[d]) for d in sorted(v.depends or (), key=index.get))
            SubElement(node, "Unknown", index=str(index[v.name]), dependencies=deps)
    unknowns = sorted({index[v.name] for v in outputs + derivatives}
                      | {index[s] for s, _ in itf.states})
    if unknowns:
        node = SubElement(structure, "InitialUnknowns")
        by_index = {index[v.name]: v for v in variables}
        for i in unknowns:
            known = _initial_knowns(itf, by_index[i])
            SubElement(node, "Unknown", index=str(i),
                       dependencies=" ".join(str(index[d]) for d in sorted(known, key=index.get)))
    indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="utf-8") + b"\n"


def _fmi3(itf: Interface, token: str) -> bytes:
    vr = {v.name: v.vr for v in itf.variables}
    root = Element("fmiModelDescription", fmiVersion="3.0", modelName=itf.name, instantiationToken=token,
                   description=itf.description, generationTool="delta-cosim fmus.native (CasADi)",
                   variableNamingConvention="structured")
    common = {"modelIdentifier": itf.name, "canGetAndSetFMUState": "true", "canSerializeFMUState": "true"}
    SubElement(root, "ModelExchange", dict(common, needsCompletedIntegratorStep="true" if itf.needs_completed_step else "false"))
    SubElement(root, "CoSimulation", dict(common, canHandleVariableCommunicationStepSize="true",
                                          providesIntermediateUpdate="false", hasEventMode="false"))
    mvars = _common(root, itf, itf.variables)
    for v in itf.variables:
        attrs = _attributes(v)
        if v.start is not None and v.type != "string":
            attrs["start"] = ("true" if v.start else "false") if v.type == "boolean" else (
                _fmt(v.start) if v.type == "real" else str(int(v.start)))
        if v.type == "real":
            if v.unit:
                attrs["unit"] = v.unit
            if v.derivative_of is not None:
                attrs["derivative"] = str(vr[v.derivative_of])
        element = SubElement(mvars, {"real": "Float64", "boolean": "Boolean", "integer": "Int32",
                                     "string": "String"}[v.type], attrs)
        if v.type == "string":
            SubElement(element, "Start", value=v.choices[int(v.start)])
    structure = SubElement(root, "ModelStructure")
    outputs = [v for v in itf.variables if v.causality == "output"]
    derivatives = [v for v in itf.variables if v.derivative_of is not None]
    for v in outputs:
        SubElement(structure, "Output", valueReference=str(v.vr),
                   dependencies=" ".join(str(vr[d]) for d in sorted(v.depends or (), key=vr.get)))
    for v in derivatives:
        SubElement(structure, "ContinuousStateDerivative", valueReference=str(v.vr),
                   dependencies=" ".join(str(vr[d]) for d in sorted(v.depends or (), key=vr.get)))
    by_vr = {v.vr: v for v in itf.variables}
    for i in sorted({v.vr for v in outputs + derivatives} | {vr[s] for s, _ in itf.states}):
        known = _initial_knowns(itf, by_vr[i])
        SubElement(structure, "InitialUnknown", valueReference=str(i),
                   dependencies=" ".join(str(vr[d]) for d in sorted(known, key=vr.get)))
    indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="utf-8") + b"\n"
