"""The exporter side, FMI 3.0 model exchange: the counterpart of :mod:`fmus.export2` on pythonfmu3 (the importer
side is :mod:`cosim.fmi`): declared variables with unit and description; continuous states are declared with
:meth:`AdapterME.state`.

As in :mod:`fmus.export2`, outputs, states and derivatives are valid whenever they are read,
initialization mode included (the model is built from the parameter values of that moment,
again if a parameter changes before ``exitInitializationMode``), and ModelStructure is exact:
each output and state derivative lists the inputs and states it depends on (``depends=``),
and each InitialUnknown the inputs among those plus the parameters (all of them, an
over-approximation the standard allows).

FMU state as in :mod:`fmus.export2` (``canGetAndSetFMUState``, ``canSerializeFMUState``;
:class:`fmus._names.StateAccess`): the continuous states are variable values, so the state is the
values, the time and the flags. A tunable parameter set after initialization takes effect at the
next evaluation (:meth:`~fmus._names.StateAccess.retune`), a fixed one is refused (fmi3Fatal: see
:func:`fmus._names.spare_wrapper_references`)."""

from __future__ import annotations

import math
from functools import cached_property
from typing import Any, Iterable
from xml.etree.ElementTree import Element

from pythonfmu3 import (
    DefaultExperiment,
    Float64,
    Fmi3Causality,
    Fmi3Initial,
    Fmi3SlaveBase,
    Fmi3Status,
    Fmi3Variability,
    ModelExchange,
    Unit,
)

from delta.errors import ParameterError

from ._names import (UNITS, StateAccess, ValueAccess, compensate_exporter_refcount, component, hold_thread_state,
                     initial_knowns)

__all__ = ["AdapterME"]

_STATE_CAPABILITIES = {"canGetAndSetFMUState": True, "canSerializeFMUState": True}


class AdapterME(StateAccess, ValueAccess, Fmi3SlaveBase, ModelExchange):
    """Model-exchange slave: subclasses declare variables and implement ``start`` and ``derivatives``."""

    KIND: str | None = None
    EXPERIMENT: tuple[float, float, float] = (0.0, 1.0, 1e-3)
    LINEAR: frozenset[tuple[str, str]] = frozenset()
    """(unknown, known) pairs where the known enters as a constant factor (dependenciesKind "constant")."""
    _STATUS_ERROR = Fmi3Status.error
    _STATUS_WARNING = Fmi3Status.warning

    def __init__(self, **kwargs: Any) -> None:
        compensate_exporter_refcount(type(self))
        super().__init__(**kwargs)
        self._hosted = "logger" in kwargs  # made by pythonfmu3's binary (it passes its logger), not in Python
        self.author = "delta-cosim"
        start, stop, step = self.EXPERIMENT
        self.default_experiment = DefaultExperiment(start_time=start, stop_time=stop, step_size=step)
        self.values: dict[str, float] = {}
        self._depends: dict[str, tuple[str, ...]] = {}  # output or derivative -> inputs and states it depends on
        self._kinds: dict[str, str] = {}  # name -> "parameter" | "input" | "output" | "state" | "derivative"
        self._built = False  # start() has run with the current parameter values
        self._initialized = False  # exitInitializationMode done: parameters no longer rebuild
        self._stale = True
        self._parameters: list[str] = []  # parameter names, in declaration order
        self._fixed: set[str] = set()  # the fixed ones: refused after initialization
        self.time = 0.0
        self._units: set[str] = set()
        self._unit("s")
        self.register_variable(Float64("time", causality=Fmi3Causality.independent, unit="s",
                                       variability=Fmi3Variability.continuous, description="simulation time",
                                       getter=lambda: self.time, setter=None), nested=False)

    def _unit(self, unit: str | None) -> None:
        """Declare ``unit`` (its SI base-unit exponents, :data:`fmus._names.UNITS`) once."""
        if unit is not None and unit not in self._units:
            self._units.add(unit)
            self.register_units([Unit(unit, **{k: v for k, v in UNITS[unit].items() if v})])

    def _add(self, name: str, start: float | None, unit: str | None, description: str, causality: Fmi3Causality,
             variability: Fmi3Variability, initial: Fmi3Initial | None = None, derivative: int | None = None,
             settable: bool = False, kind: str = "") -> int:
        self.values[name] = 0.0 if start is None else float(start)
        self._kinds[name] = kind
        self._stale = True
        self._unit(unit)
        setter = (lambda v, n=name: self._set(n, v)) if settable else None
        if causality is Fmi3Causality.output:
            getter = lambda n=name: self._get_output(n)  # noqa: E731
        elif derivative is not None:
            getter = lambda n=name: self._get_derivative(n)  # noqa: E731
        else:
            getter = lambda n=name: self.values[n]  # noqa: E731
        var = Float64(name, start=start, unit=unit, causality=causality, variability=variability, initial=initial,
                      derivative=derivative, description=description, getter=getter, setter=setter)
        self.register_variable(var, nested=False)
        if kind == "parameter":
            self._parameters.append(name)
            if variability is Fmi3Variability.fixed:
                self._fixed.add(name)
        return var.value_reference

    def parameter(self, name: str, start: float, unit: str | None, description: str, *, tunable: bool = False) -> None:
        self._add(name, start, unit, description, Fmi3Causality.parameter,
                  Fmi3Variability.tunable if tunable else Fmi3Variability.fixed,
                  Fmi3Initial.exact, settable=True, kind="parameter")

    def parameters3(self, names: Iterable[str], start: Iterable[float], unit: str, description: str, *,
                    tunable: bool = False) -> None:
        for i, (n, s) in enumerate(zip(names, start)):
            self.parameter(n, float(s), unit, f"{description} ({component(n, i)})", tunable=tunable)

    def input(self, name: str, unit: str | None, description: str, start: float = 0.0) -> None:
        self._add(name, start, unit, description, Fmi3Causality.input, Fmi3Variability.continuous, settable=True,
                  kind="input")

    def output(self, name: str, unit: str | None, description: str, *, depends: Iterable[str]) -> None:
        """An output computed from the states and inputs ``depends`` (inputs among them: direct feedthrough)."""
        self._add(name, None, unit, description, Fmi3Causality.output, Fmi3Variability.continuous,
                  Fmi3Initial.calculated, kind="output")
        self._depends[name] = tuple(depends)

    def state(self, name: str, der_name: str, unit: str, der_unit: str, description: str, *,
              depends: Iterable[str]) -> None:
        """A continuous state (an output, set by the solver) and its derivative ``der_name``, which
        depends on the states and inputs ``depends``."""
        vr = self._add(name, None, unit, description, Fmi3Causality.output, Fmi3Variability.continuous,
                       Fmi3Initial.calculated, settable=True, kind="state")
        self._depends[name] = (name,)  # the output is the state itself
        self._add(der_name, None, der_unit, f"time derivative of {name}", Fmi3Causality.local,
                  Fmi3Variability.continuous, Fmi3Initial.calculated, derivative=vr, kind="derivative")
        self._depends[der_name] = tuple(depends)

    def _set(self, name: str, value: float) -> None:
        if self._kinds[name] != "parameter":
            self.values[name] = float(value)
            self._stale = True
        elif not self._initialized:
            self.values[name] = float(value)
            self._stale = True
            self._built = False
        else:  # a tunable one (set_float64 refused fixed ones): retuned if it changed
            before = {name: self.values[name]}
            self.values[name] = float(value)
            self._stale = True
            self._retune_changed(before)

    def set_float64(self, vrs: list[int], values: list[float]) -> None:
        """fmi3SetFloat64; after initialization a fixed parameter among ``vrs`` is refused before anything is
        stored."""
        if self._initialized:
            self._refuse_fixed([self.vars[vr].name for vr in vrs if vr in self.vars])
        super().set_float64(vrs, values)

    def _build(self) -> None:
        """Build the model and the initial states from the current parameters if not done yet."""
        if not self._built:
            hold_thread_state()
            self.start()
            self._built = True
            self._stale = True

    def _get_output(self, name: str) -> float:
        # Outputs follow the current states and inputs, not the solver's last trial point.
        self._build()
        if self._stale:
            self.outputs()
            self._stale = False
        return self.values[name]

    def _get_derivative(self, name: str) -> float:
        self._build()
        self.derivatives()
        return self.values[name]

    def start(self) -> None:
        """Build the model from the parameters and set the initial states (before the first read,
        initialization mode included, and again if a parameter changes there)."""

    def derivatives(self) -> None:
        """Fill the derivative variables from the states and inputs."""

    def outputs(self) -> None:
        """Fill the output variables (other than the states) from the states and inputs."""

    def exit_initialization_mode(self) -> None:
        hold_thread_state()
        self._build()
        self._initialized = True

    def get_continuous_state_derivatives(self) -> list[float]:
        """Every derivative from one evaluation of the dynamics (reading each derivative variable
        through its getter would evaluate them once per state).

        Never raises: pythonfmu3 (0.3.4) handles an exception from this one call by printing it
        (``PyErr_Print``, which clears it), then finds no exception pending and reads the missing
        result as a list, which crashes the whole process (exit 139). A failure is logged with
        status error instead and the derivatives returned as NaN, which the importer must not
        integrate (our master stops on them naming the component, the reason and the time).
        """
        try:
            self._build()
            self.derivatives()
            values = self.values
            return [values[n] for n in self._derivative_names()]
        except Exception as exc:  # noqa: BLE001 - reported through the FMI logger (see above)
            self.log(f"derivatives at t = {self.time!r} s failed: {type(exc).__name__}: {exc}", Fmi3Status.error)
            return [math.nan] * len(self._derivative_names())

    def set_continuous_states(self, values: list[float]) -> None:
        # the states in ModelStructure order, set in one pass (pythonfmu3's generic version
        # filters every variable on each call)
        names = self._state_names()
        if len(values) != len(names):
            raise ParameterError(f"{type(self).__name__}: {len(values)} continuous state values given, "
                                 f"the model has {len(names)} ({', '.join(names)})")
        store = self.values
        for n, v in zip(names, values):
            store[n] = float(v)
        self._stale = True

    def get_continuous_states(self) -> list[float]:
        self._build()
        return [self.values[n] for n in self._state_names()]

    @cached_property
    def _state_order(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """(state names, derivative names) in the order of the derivatives in ModelStructure."""
        by_vr = {v.value_reference: v for v in self.vars.values()}
        ders = [by_vr[vr] for vr in self._derivative_refs()]
        return tuple(by_vr[d.derivative].name for d in ders), tuple(d.name for d in ders)

    def _state_names(self) -> tuple[str, ...]:
        return self._state_order[0]

    def _derivative_names(self) -> tuple[str, ...]:
        return self._state_order[1]

    def _derivative_refs(self) -> list[int]:
        return [v.value_reference for v in self.vars.values()
                if isinstance(v, Float64) and v.derivative is not None]

    # -- FMU state (fmus._names.StateAccess)
    def _flags(self) -> dict:
        return {"built": self._built, "initialized": self._initialized, "stale": self._stale}

    def _restore_flags(self, flags: dict) -> None:
        self._built, self._initialized, self._stale = flags["built"], flags["initialized"], flags["stale"]

    def to_xml(self, model_options: dict[str, str] = dict()) -> Element:  # noqa: B006 (pythonfmu3 signature)
        root = super().to_xml({**model_options, **_STATE_CAPABILITIES})
        vr = {v.name: v.value_reference for v in self.vars.values()}
        name = {r: n for n, r in vr.items()}
        unknown = set().union(*self._depends.values()) - {n for n, k in self._kinds.items() if k in ("input", "state")}
        if unknown:
            raise ValueError(f"{type(self).__name__}: dependencies on {sorted(unknown)}, which are neither inputs "
                             "nor states")
        inputs = {n for n, k in self._kinds.items() if k == "input"}
        parameters = [n for n, k in self._kinds.items() if k == "parameter"]
        for element in root.find("ModelStructure"):
            ref = int(element.get("valueReference"))
            deps = self._depends.get(name[ref], ())
            if element.tag == "InitialUnknown":
                known = sorted(vr[n] for n in initial_knowns(deps, inputs, parameters))
            elif element.tag in ("Output", "ContinuousStateDerivative"):
                known = sorted(vr[n] for n in deps)
            else:
                continue
            kinds = ["constant" if self._linear(name[ref], name[k]) else "dependent" for k in known]
            element.set("dependencies", " ".join(map(str, known)))
            element.set("dependenciesKind", " ".join(kinds))
        return root

    def _linear(self, unknown: str, known: str) -> bool:
        """Whether ``known`` enters ``unknown`` as a constant factor times itself (a state as its own
        output, dq/dt = qd); subclasses list such pairs in ``LINEAR``."""
        return (unknown, known) in self.LINEAR or (unknown == known and self._kinds[unknown] == "state")
