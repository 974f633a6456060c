"""Declarative layer shared by every adapter: variables with unit, description,
causality, variability and initial, stored by name, plus the FMI 2.0 slave base.

An adapter declares its interface in ``__init__`` with :meth:`Adapter.input`,
:meth:`Adapter.output`, :meth:`Adapter.parameter` (or the vector forms) and
implements :meth:`Adapter.start` (called once the parameters are fixed) and
:meth:`Adapter.advance` (one communication step). Outputs are refreshed through
:meth:`Adapter.refresh`, called lazily when an output is read after an input or
tunable parameter changed, so algebraic blocks (IK, FK) have direct feedthrough.
"""

from __future__ import annotations

from dataclasses import dataclass
from operator import itemgetter
from typing import Any, Iterable
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.variables import Boolean, Integer, Real, String

from ._names import UNITS, XYZ, ValueAccess, axis_names, compensate_exporter_refcount, joint_names, writer

__all__ = ["Adapter", "UNITS", "XYZ", "joint_names", "axis_names", "DefaultExperiment", "writer"]


@dataclass(frozen=True)
class Spec:
    """One FMI variable: what every importing tool sees in modelDescription.xml."""

    name: str
    kind: str  # "real" | "integer" | "boolean" | "string"
    causality: str  # "input" | "output" | "parameter" | "local"
    variability: str  # "fixed" | "tunable" | "discrete" | "continuous"
    start: Any
    unit: str | None
    description: str


class _UnitReal(Real):
    """pythonfmu 0.7's Real has no ``unit`` attribute; add it to the <Real> element."""

    def __init__(self, name: str, unit: str | None, **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self.unit = unit

    def to_xml(self) -> Element:
        node = super().to_xml()
        if self.unit is not None:
            node.find("Real").set("unit", self.unit)
        return node


_CAUSALITY = {c.name: c for c in Fmi2Causality}
_VARIABILITY = {v.name: v for v in Fmi2Variability}
_TYPES = {"real": float, "integer": int, "boolean": bool, "string": str}


class Adapter(ValueAccess, Fmi2Slave):
    """FMI 2.0 co-simulation slave declared from :class:`Spec` records.

    Subclasses set the class attributes ``KIND`` (robot kind, or None) and
    ``EXPERIMENT`` (start, stop, step) and call the ``input``/``output``/``parameter``
    helpers in ``__init__``.
    """

    KIND: str | None = None
    EXPERIMENT: tuple[float, float, float] = (0.0, 1.0, 1e-3)

    def __init__(self, **kwargs: Any) -> None:
        compensate_exporter_refcount(type(self))
        super().__init__(**kwargs)
        self.author = "delta-cosim"
        start, stop, step = self.EXPERIMENT
        self.default_experiment = DefaultExperiment(start_time=start, stop_time=stop, step_size=step)
        self.values: dict[str, Any] = {}
        self.specs: list[Spec] = []
        # Fast paths for fmi2GetReal / fmi2SetReal (see get_real): value reference -> name, and
        # one access plan per distinct list of references (an importer asks for the same lists
        # every step, so the per-call work is a tuple hash and one dict lookup).
        self._real_get: dict[int, str] = {}
        self._real_set: dict[int, str] = {}
        self._output_vrs: set[int] = set()
        self._get_plans: dict[tuple[int, ...], tuple[bool, Any] | None] = {}
        self._set_plans: dict[tuple[int, ...], Any] = {}
        self._dirty = True
        self._started = False
        self.time = 0.0

    # ------------------------------------------------------------------ declaration
    def _declare(self, spec: Spec) -> None:
        self.specs.append(spec)
        self.values[spec.name] = _TYPES[spec.kind](spec.start)
        name = spec.name
        settable = spec.causality in ("input", "parameter")
        kwargs: dict[str, Any] = dict(
            causality=_CAUSALITY[spec.causality],
            variability=_VARIABILITY[spec.variability],
            description=spec.description,
            getter=self._getter(name, spec.causality == "output"),
            setter=self._setter(name, spec.kind) if settable else None,
        )
        # pythonfmu 0.7 + fmpy validation: outputs need initial="exact" and a start value.
        if spec.causality == "output":
            kwargs["initial"] = Fmi2Initial.exact
        if spec.kind == "real":
            var = _UnitReal(name, spec.unit, start=float(spec.start), **kwargs)
        else:
            var = {"integer": Integer, "boolean": Boolean, "string": String}[spec.kind](
                name, start=spec.start, **kwargs
            )
        self.register_variable(var, nested=False)
        vr = var.value_reference
        if spec.causality == "output":
            self._output_vrs.add(vr)
        if spec.kind == "real":
            self._real_get[vr] = name
            if settable:
                self._real_set[vr] = name

    def _getter(self, name: str, is_output: bool):
        if is_output:
            def get() -> Any:
                if self._started and self._dirty:
                    self._dirty = False
                    self.refresh()
                return self.values[name]
            return get
        return lambda: self.values[name]

    def _setter(self, name: str, kind: str):
        cast = _TYPES[kind]

        def set_(value: Any) -> None:
            self.values[name] = cast(value)
            self._dirty = True
        return set_

    def input(self, name: str, unit: str | None, description: str, start: Any = 0.0, kind: str = "real") -> None:
        self._declare(Spec(name, kind, "input", "continuous" if kind == "real" else "discrete",
                           start, unit, description))

    def output(self, name: str, unit: str | None, description: str, start: Any = 0.0, kind: str = "real") -> None:
        self._declare(Spec(name, kind, "output", "continuous" if kind == "real" else "discrete",
                           start, unit, description))

    def parameter(self, name: str, start: Any, unit: str | None, description: str, *,
                  tunable: bool = False, kind: str | None = None) -> None:
        if kind is None:
            kind = {bool: "boolean", int: "integer", str: "string"}.get(type(start), "real")
        self._declare(Spec(name, kind, "parameter", "tunable" if tunable else "fixed", start, unit, description))

    def inputs3(self, names: Iterable[str], unit: str, description: str, start: Iterable[float] = (0.0, 0.0, 0.0)) -> None:
        for i, (n, s) in enumerate(zip(names, start)):
            self.input(n, unit, f"{description} ({_component(n, i)})", s)

    def outputs3(self, names: Iterable[str], unit: str, description: str, start: Iterable[float] = (0.0, 0.0, 0.0)) -> None:
        for i, (n, s) in enumerate(zip(names, start)):
            self.output(n, unit, f"{description} ({_component(n, i)})", s)

    def parameters3(self, names: Iterable[str], start: Iterable[float], unit: str, description: str,
                    *, tunable: bool = False) -> None:
        for i, (n, s) in enumerate(zip(names, start)):
            self.parameter(n, float(s), unit, f"{description} ({_component(n, i)})", tunable=tunable)

    # ------------------------------------------------------------------ behaviour
    def start(self) -> None:
        """Build the core objects from the (now fixed) parameters."""

    def refresh(self) -> None:
        """Recompute outputs from the current inputs (direct feedthrough)."""

    def advance(self, t: float, h: float) -> None:
        """Advance internal state from ``t`` to ``t + h``."""

    # ------------------------------------------------------------------ FMI
    def get_real(self, vrs):
        """fmi2GetReal: pythonfmu's version calls a getter closure and an isinstance per variable;
        this one reads ``values`` through a cached plan for this list of references, refreshing
        the outputs once if any of them is requested."""
        key = tuple(vrs)
        try:
            plan = self._get_plans[key]
        except KeyError:
            plan = self._get_plans[key] = self._get_plan(key)
        if plan is None:  # not all Reals: pythonfmu raises the TypeError naming the reference
            return super().get_real(vrs)
        reads_outputs, read = plan
        if reads_outputs and self._dirty and self._started:
            self._dirty = False
            self.refresh()
        return read(self.values)

    def _get_plan(self, vrs: tuple[int, ...]) -> tuple[bool, Any] | None:
        """(whether an output is read, values -> list of the values of ``vrs``), None if one is not a Real."""
        if not all(vr in self._real_get for vr in vrs):
            return None
        names = [self._real_get[vr] for vr in vrs]
        if len(names) == 1:
            name = names[0]
            read = lambda values: [values[name]]  # noqa: E731
        else:
            pick = itemgetter(*names)
            read = lambda values: list(pick(values))  # noqa: E731
        return not self._output_vrs.isdisjoint(vrs), read

    def set_real(self, vrs, values):
        """fmi2SetReal without per-variable setter closures (same effect: store, mark outputs stale)."""
        key = tuple(vrs)
        try:
            write = self._set_plans[key]
        except KeyError:
            write = self._set_plans[key] = self._set_plan(key)
        if write is None:  # not all settable Reals: pythonfmu's error, before anything is stored
            return super().set_real(vrs, values)
        write(self.values, values)  # fmi2SetReal hands over Python floats
        self._dirty = True

    def _set_plan(self, vrs: tuple[int, ...]) -> Any:
        """(values, new values) -> None storing under the names of ``vrs``; None if one is not a settable Real."""
        if not vrs or not all(vr in self._real_set for vr in vrs):
            return None
        return writer([self._real_set[vr] for vr in vrs])

    def setup_experiment(self, start_time: float, stop_time: float | None = None, tolerance: float | None = None):
        self.time = float(start_time)

    def exit_initialization_mode(self) -> None:
        self.start()
        self._started = True
        self._dirty = False
        self.refresh()

    def do_step(self, current_time: float, step_size: float) -> bool:
        self.advance(current_time, step_size)
        self.time = current_time + step_size
        self._dirty = True  # outputs are recomputed once, when next read
        return True

    def to_xml(self, model_options: dict[str, str] = dict()) -> Element:  # noqa: B006 (pythonfmu signature)
        root = super().to_xml(model_options)
        used = sorted({s.unit for s in self.specs if s.unit is not None})
        units = Element("UnitDefinitions")
        for name in used:
            base = {k: str(v) for k, v in UNITS[name].items() if v}
            SubElement(SubElement(units, "Unit", {"name": name}), "BaseUnit", base)
        if used:
            # FMI 2.0 schema order: CoSimulation, UnitDefinitions, ..., LogCategories, DefaultExperiment.
            position = list(root).index(root.find("CoSimulation")) + 1
            root.insert(position, units)
        return root


def _component(name: str, index: int) -> str:
    return name.rsplit(".", 1)[-1] if name.endswith(XYZ) and "." in name else f"leg {index + 1}"
