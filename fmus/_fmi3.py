"""FMI 3.0 model-exchange counterpart of :mod:`fmus._fmi` (pythonfmu3): declared variables
with unit and description; continuous states are declared with :meth:`AdapterME.state`."""

from __future__ import annotations

from typing import Any, Iterable

from pythonfmu3 import (
    DefaultExperiment,
    Float64,
    Fmi3Causality,
    Fmi3Initial,
    Fmi3SlaveBase,
    Fmi3Variability,
    ModelExchange,
    Unit,
)

from ._names import UNITS, ValueAccess, compensate_exporter_refcount

__all__ = ["AdapterME"]


class AdapterME(ValueAccess, Fmi3SlaveBase, ModelExchange):
    """Model-exchange slave: subclasses declare variables and implement ``start`` and ``derivatives``."""

    KIND: str | None = None
    EXPERIMENT: tuple[float, float, float] = (0.0, 1.0, 1e-3)

    def __init__(self, **kwargs: Any) -> None:
        compensate_exporter_refcount(type(self))
        super().__init__(**kwargs)
        self.author = "delta-cosim"
        start, stop, step = self.EXPERIMENT
        self.default_experiment = DefaultExperiment(start_time=start, stop_time=stop, step_size=step)
        self.values: dict[str, float] = {}
        self._started = False
        self._stale = True
        self.time = 0.0
        self._units: set[str] = set()
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous, description="simulation time",
                                       getter=lambda: self.time, setter=None), nested=False)

    def _add(self, name: str, start: float | None, unit: str | None, description: str, causality: Fmi3Causality,
             variability: Fmi3Variability, initial: Fmi3Initial | None = None, derivative: int | None = None,
             settable: bool = False) -> int:
        self.values[name] = 0.0 if start is None else float(start)
        self._stale = True
        if unit is not None and unit not in self._units:
            self._units.add(unit)
            base = {k: v for k, v in UNITS[unit].items() if v}
            self.register_units([Unit(unit, **base)])
        setter = (lambda v, n=name: self._set(n, v)) if settable else None
        if causality is Fmi3Causality.output:
            getter = lambda n=name: self._get_output(n)  # noqa: E731
        else:
            getter = lambda n=name: self.values[n]  # noqa: E731
        var = Float64(name, start=start, unit=unit, causality=causality, variability=variability, initial=initial,
                      derivative=derivative, description=description, getter=getter, setter=setter)
        self.register_variable(var, nested=False)
        return var.value_reference

    def parameter(self, name: str, start: float, unit: str | None, description: str) -> None:
        self._add(name, start, unit, description, Fmi3Causality.parameter, Fmi3Variability.fixed,
                  Fmi3Initial.exact, settable=True)

    def parameters3(self, names: Iterable[str], start: Iterable[float], unit: str, description: str, *,
                    tunable: bool = False) -> None:
        for i, (n, s) in enumerate(zip(names, start)):
            self.parameter(n, float(s), unit, f"{description} (leg {i + 1})")

    def input(self, name: str, unit: str | None, description: str, start: float = 0.0) -> None:
        self._add(name, start, unit, description, Fmi3Causality.input, Fmi3Variability.continuous, settable=True)

    def output(self, name: str, unit: str | None, description: str) -> None:
        self._add(name, None, unit, description, Fmi3Causality.output, Fmi3Variability.continuous,
                  Fmi3Initial.calculated)

    def state(self, name: str, der_name: str, unit: str, der_unit: str, description: str) -> None:
        """A continuous state (an output, set by the solver) and its derivative ``der_name``."""
        vr = self._add(name, None, unit, description, Fmi3Causality.output, Fmi3Variability.continuous,
                       Fmi3Initial.calculated, settable=True)
        self._add(der_name, None, der_unit, f"time derivative of {name}", Fmi3Causality.local,
                  Fmi3Variability.continuous, Fmi3Initial.calculated, derivative=vr)

    def _set(self, name: str, value: float) -> None:
        self.values[name] = float(value)
        self._stale = True

    def _get_output(self, name: str) -> float:
        # Outputs follow the current states and inputs, not the solver's last trial point.
        if self._stale and self._started:
            self.outputs()
            self._stale = False
        return self.values[name]

    def start(self) -> None:
        """Build the model from the parameters and set the initial states."""

    def derivatives(self) -> None:
        """Fill the derivative variables from the states and inputs."""

    def outputs(self) -> None:
        """Fill the output variables (other than the states) from the states and inputs."""

    def exit_initialization_mode(self) -> None:
        self.start()
        self._started = True
        self._stale = True

    def get_continuous_state_derivatives(self) -> list[float]:
        self.derivatives()
        return [float(self.vars[vr].getter()) for vr in self._derivative_refs()]

    def _derivative_refs(self) -> list[int]:
        return [v.value_reference for v in self.vars.values()
                if isinstance(v, Float64) and v.derivative is not None]
