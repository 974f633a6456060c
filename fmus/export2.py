"""The exporter side, FMI 2.0: the pythonfmu slave base our python FMUs stand on (the importer side, how the
master loads any FMU, is :mod:`cosim.fmi`). A declarative layer shared by every FMI 2.0 adapter: variables with
unit, description, causality, variability and initial, stored by name, plus the FMI 2.0 slave base.

An adapter declares its interface in ``__init__`` with :meth:`Adapter.input`,
:meth:`Adapter.output`, :meth:`Adapter.parameter` (or the vector forms) and
implements :meth:`Adapter.start` (builds the core objects from the parameters) and
:meth:`Adapter.advance` (one communication step). Outputs are refreshed through
:meth:`Adapter.refresh`, called lazily when an output is read after an input or
parameter changed, so algebraic blocks (IK, FK) have direct feedthrough.

Outputs are valid whenever they are read, initialization mode included: the first read
builds the core objects (:meth:`Adapter.start`) from the parameter values of that moment
(again after a parameter changes, until ``exitInitializationMode``) and computes the outputs
from the inputs, so an importer that reads a trajectory's ``p_ref`` in initialization mode
gets the reference at the start time, not a placeholder. Outputs are therefore declared
``initial="calculated"`` (no start value) and listed in ``InitialUnknowns``.

Every output declares the inputs it depends on directly (``depends=``); ``to_xml`` writes
them as the output's ``dependencies`` in ModelStructure (``dependenciesKind="dependent"``:
no particular structure claimed), and the ``InitialUnknowns`` depend on those inputs and on
the parameters (every parameter: they are not tracked per output, an over-approximation the
standard allows). A plant or controller with no direct feedthrough declares ``depends=()``.

A step that cannot be taken (the adapter's ``advance`` raises) returns ``fmi2Discard`` with
the reason logged through the FMI logger (status error), never ``fmi2Fatal``; the instance
then refuses further steps, since its state after a failed step is undefined.

FMU state: every adapter can get, set and serialize its state (``canGetAndSetFMUstate``,
``canSerializeFMUstate``; :class:`fmus._names.StateAccess`, with the adapter's
:meth:`~fmus._names.StateAccess.internal_state` hook). After initialization a tunable parameter
takes effect at once through the adapter's :meth:`~fmus._names.StateAccess.retune` (the motion
state kept), and setting a fixed one is refused with the reason logged. pythonfmu's binary gives
Python code no failing status but fmi2Fatal (any exception), so a refusal is fmi2Fatal; the
instance stays valid (:func:`fmus._names.spare_wrapper_references`).
"""

from __future__ import annotations

from dataclasses import dataclass
from operator import itemgetter
from typing import Any, Callable, Iterable, Union
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability
from pythonfmu.enums import Fmi2Status
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.variables import Boolean, Integer, Real, String

from ._names import (UNITS, XYZ, StateAccess, ValueAccess, axis_names, compensate_exporter_refcount, component,
                     hold_thread_state, initial_knowns, joint_names, writer)

__all__ = ["Adapter", "Depends", "UNITS", "XYZ", "joint_names", "axis_names", "DefaultExperiment", "writer"]

Depends = Union[Iterable[str], Callable[[int], Iterable[str]]]
"""Inputs an output depends on directly: names, or (for the vector helpers) ``i -> names`` of output ``i``."""


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
    depends: tuple[str, ...] = ()  # outputs: the inputs this output depends on directly


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
_STATE_CAPABILITIES = {"canGetAndSetFMUstate": True, "canSerializeFMUstate": True}


class Adapter(StateAccess, ValueAccess, Fmi2Slave):
    """FMI 2.0 co-simulation slave declared from :class:`Spec` records.

    Subclasses set the class attributes ``KIND`` (robot kind, or None) and
    ``EXPERIMENT`` (start, stop, step) and call the ``input``/``output``/``parameter``
    helpers in ``__init__``.
    """

    KIND: str | None = None
    EXPERIMENT: tuple[float, float, float] = (0.0, 1.0, 1e-3)
    _STATUS_ERROR = Fmi2Status.error
    _STATUS_WARNING = Fmi2Status.warning

    def __init__(self, **kwargs: Any) -> None:
        compensate_exporter_refcount(type(self))
        super().__init__(**kwargs)
        self._hosted = "logger" in kwargs  # made by pythonfmu's binary (it passes its logger), not in Python
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
        self._param_vrs: set[int] = set()
        self._get_plans: dict[tuple[int, ...], tuple[bool, Any] | None] = {}
        self._set_plans: dict[tuple[int, ...], tuple[Any, bool] | None] = {}
        self._dirty = True  # outputs are stale: recompute (refresh) when one is read
        self._built = False  # start() has run with the current parameter values
        self._initialized = False  # exitInitializationMode done: parameters no longer rebuild
        self._failed: str | None = None  # why the last step failed (the instance cannot continue)
        self._parameters: list[str] = []  # parameter names, in declaration order
        self._fixed: set[str] = set()  # the fixed ones: refused after initialization
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
            setter=self._setter(name, spec.kind, spec.causality == "parameter") if settable else None,
        )
        start: Any = spec.start
        if spec.causality == "output":
            # computed on demand in every mode (see the module docstring): no start value
            kwargs["initial"] = Fmi2Initial.calculated
            start = None
        if spec.kind == "real":
            var = _UnitReal(name, spec.unit, start=None if start is None else float(start), **kwargs)
        else:
            var = {"integer": Integer, "boolean": Boolean, "string": String}[spec.kind](
                name, start=start, **kwargs
            )
        self.register_variable(var, nested=False)
        vr = var.value_reference
        if spec.causality == "output":
            self._output_vrs.add(vr)
        elif spec.causality == "parameter":
            self._param_vrs.add(vr)
            self._parameters.append(name)
            if spec.variability == "fixed":
                self._fixed.add(name)
        if spec.kind == "real":
            self._real_get[vr] = name
            if settable:
                self._real_set[vr] = name

    def _update(self) -> None:
        """Bring the outputs up to date: build from the parameters if needed, then refresh."""
        hold_thread_state()
        if not self._built:
            self.start()
            self._built = True
        self._dirty = False
        self.refresh()

    def _getter(self, name: str, is_output: bool):
        if is_output:
            def get() -> Any:
                if self._dirty:
                    self._update()
                return self.values[name]
            return get
        return lambda: self.values[name]

    def _setter(self, name: str, kind: str, is_parameter: bool = False):
        cast = _TYPES[kind]

        def set_(value: Any) -> None:
            if is_parameter:
                self._set_parameters((name,), lambda values, new: values.__setitem__(name, cast(new[0])), (value,))
                return
            self.values[name] = cast(value)
            self._dirty = True
        return set_

    def _set_parameters(self, names: tuple[str, ...], write, new) -> None:  # noqa: ANN001
        """Store ``new`` (``write(values, new)``), which sets the parameters ``names``: before initialization the
        core objects are rebuilt when next needed; after it a fixed one is refused (nothing stored) and the tunable
        ones that changed are retuned (:meth:`retune`)."""
        if not self._initialized:
            write(self.values, new)
            self._dirty = True
            self._built = False
            return
        self._refuse_fixed(names)
        before = {n: self.values[n] for n in names}
        write(self.values, new)
        self._dirty = True
        self._retune_changed(before)

    def input(self, name: str, unit: str | None, description: str, start: Any = 0.0, kind: str = "real") -> None:
        self._declare(Spec(name, kind, "input", "continuous" if kind == "real" else "discrete",
                           start, unit, description))

    def output(self, name: str, unit: str | None, description: str, *, depends: Iterable[str],
               kind: str = "real") -> None:
        """An output; ``depends`` names the inputs it depends on directly (empty: no direct feedthrough)."""
        self._declare(Spec(name, kind, "output", "continuous" if kind == "real" else "discrete",
                           _TYPES[kind](), unit, description, tuple(depends)))

    def parameter(self, name: str, start: Any, unit: str | None, description: str, *,
                  tunable: bool = False, kind: str | None = None) -> None:
        if kind is None:
            kind = {bool: "boolean", int: "integer", str: "string"}.get(type(start), "real")
        self._declare(Spec(name, kind, "parameter", "tunable" if tunable else "fixed", start, unit, description))

    def inputs3(self, names: Iterable[str], unit: str, description: str, start: Iterable[float] = (0.0, 0.0, 0.0)) -> None:
        for i, (n, s) in enumerate(zip(names, start)):
            self.input(n, unit, f"{description} ({component(n, i)})", s)

    def outputs3(self, names: Iterable[str], unit: str, description: str, *, depends: Depends) -> None:
        """Three outputs; ``depends`` is the inputs of each (names), or ``i -> names`` for output ``i`` (0-based)."""
        for i, n in enumerate(names):
            self.output(n, unit, f"{description} ({component(n, i)})",
                        depends=depends(i) if callable(depends) else depends)

    def parameters3(self, names: Iterable[str], start: Iterable[float], unit: str, description: str,
                    *, tunable: bool = False) -> None:
        for i, (n, s) in enumerate(zip(names, start)):
            self.parameter(n, float(s), unit, f"{description} ({component(n, i)})", tunable=tunable)

    # ------------------------------------------------------------------ behaviour
    def start(self) -> None:
        """Build the core objects from the parameters and set the initial state; called before the
        first output is read (initialization mode included) and again if a parameter changes there."""

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
        if reads_outputs and self._dirty:
            self._update()
        return read(self.values)

    def _get_plan(self, vrs: tuple[int, ...]) -> tuple[bool, Any] | None:
        """(whether an output is read, values -> list of the values of ``vrs``), None if one is not a Real."""
        if not all(vr in self._real_get for vr in vrs):
            return None
        names = [self._real_get[vr] for vr in vrs]
        if not names:  # fmi2GetReal of no variables
            return False, lambda values: []
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
            plan = self._set_plans[key]
        except KeyError:
            plan = self._set_plans[key] = self._set_plan(key)
        if plan is None:  # not all settable Reals: pythonfmu's error, before anything is stored
            return super().set_real(vrs, values)
        write, parameters = plan
        if parameters:
            self._set_parameters(parameters, write, values)
            return
        write(self.values, values)  # fmi2SetReal hands over Python floats
        self._dirty = True

    def _set_plan(self, vrs: tuple[int, ...]) -> tuple[Any, tuple[str, ...]] | None:
        """(write, the parameters set): ``write(values, new values)`` stores under the names of ``vrs``; None if
        one is not a settable Real."""
        if not vrs or not all(vr in self._real_set for vr in vrs):
            return None
        return writer([self._real_set[vr] for vr in vrs]), tuple(self._real_set[vr] for vr in vrs
                                                                 if vr in self._param_vrs)

    def setup_experiment(self, start_time: float, stop_time: float | None = None, tolerance: float | None = None):
        self.time = float(start_time)

    def exit_initialization_mode(self) -> None:
        hold_thread_state()
        if not self._built:  # no output was read in initialization mode
            self.start()
            self._built = True
            self._dirty = True
        self._initialized = True

    def do_step(self, current_time: float, step_size: float) -> bool:
        """One communication step; False (fmi2Discard) with the reason logged when it cannot be taken."""
        hold_thread_state()
        if self._failed is not None:
            self.log(f"doStep at t = {current_time!r} s refused: an earlier step failed ({self._failed}); "
                     "this instance cannot continue", Fmi2Status.error)
            return False
        if not step_size > 0.0 or step_size == float("inf"):
            self.log(f"doStep at t = {current_time!r} s: the communication step must be a finite h > 0, "
                     f"got {step_size!r}", Fmi2Status.error)
            return False
        try:
            if not self._built:  # a state set from before the build (taken in initialization mode)
                self.start()
                self._built = True
            self.advance(current_time, step_size)
        except Exception as exc:  # noqa: BLE001 - reported through the FMI logger, never fmi2Fatal
            self._failed = f"{type(exc).__name__}: {exc}"
            self.log(self._step_failure(current_time, step_size, exc), Fmi2Status.error)
            return False
        self.time = current_time + step_size
        self._dirty = True  # outputs are recomputed once, when next read
        return True

    def _step_failure(self, t: float, h: float, exc: Exception) -> str:
        """What a failed step logs: the step, the exception's type and text."""
        return f"doStep from t = {t!r} s over h = {h!r} s failed: {self._failed}"

    # ------------------------------------------------------------------ FMU state (fmus._names.StateAccess)
    def _flags(self) -> dict:
        return {"dirty": self._dirty, "built": self._built, "initialized": self._initialized, "failed": self._failed}

    def _restore_flags(self, flags: dict) -> None:
        self._dirty, self._built = flags["dirty"], flags["built"]
        self._initialized, self._failed = flags["initialized"], flags["failed"]

    def _broken(self, reason: str) -> None:
        self._failed = reason  # doStep refuses from now on

    def to_xml(self, model_options: dict[str, str] = dict()) -> Element:  # noqa: B006 (pythonfmu signature)
        root = super().to_xml({**model_options, **_STATE_CAPABILITIES})
        used = sorted({s.unit for s in self.specs if s.unit is not None})
        units = Element("UnitDefinitions")
        for name in used:
            base = {k: str(v) for k, v in UNITS[name].items() if v}
            SubElement(SubElement(units, "Unit", {"name": name}), "BaseUnit", base)
        if used:
            # FMI 2.0 schema order: CoSimulation, UnitDefinitions, ..., LogCategories, DefaultExperiment.
            position = list(root).index(root.find("CoSimulation")) + 1
            root.insert(position, units)
        structure = root.find("ModelStructure")
        for child in list(structure):
            structure.remove(child)
        self._write_model_structure(structure)
        return root

    def _write_model_structure(self, structure: Element) -> None:
        """Outputs with their direct-feedthrough ``dependencies`` and the InitialUnknowns (FMI 2.0 2.2.8).

        Indices are 1-based positions in ModelVariables (pythonfmu writes ``self.vars`` in order).
        """
        index = {v.name: i + 1 for i, v in enumerate(self.vars.values())}
        inputs = {s.name for s in self.specs if s.causality == "input"}
        parameters = [s.name for s in self.specs if s.causality == "parameter"]
        outputs = sorted((s for s in self.specs if s.causality == "output"), key=lambda s: index[s.name])
        for spec in outputs:
            unknown = set(spec.depends) - inputs
            if unknown:
                raise ValueError(f"{type(self).__name__}: output {spec.name} depends on {sorted(unknown)}, "
                                 f"which are not inputs; inputs: {sorted(inputs)}")
        if not outputs:
            return

        def unknown(parent: Element, spec: Spec, known: Iterable[int]) -> None:
            deps = sorted(set(known))
            SubElement(parent, "Unknown", {"index": str(index[spec.name]),
                                           "dependencies": " ".join(map(str, deps)),
                                           "dependenciesKind": " ".join(["dependent"] * len(deps))})

        node = SubElement(structure, "Outputs")
        for spec in outputs:
            unknown(node, spec, (index[n] for n in spec.depends))
        node = SubElement(structure, "InitialUnknowns")
        for spec in outputs:
            unknown(node, spec, (index[n] for n in initial_knowns(spec.depends, inputs, parameters)))
