"""FMU instances driven directly through FMPy, for the FMU-state tests of the python build
(tests/integration/test_fmu_state_python.py) and of the native build (tests/integration/test_native_state.py).

An :class:`Instance` is one FMI 2.0 or 3.0 instance, co-simulation (CS: doStep) or model exchange (ME: explicit Euler
steps driven from here: setTime, setContinuousStates, derivatives, completedIntegratorStep), with inputs varied by
the step index and the FMU's log messages collected; it gets, sets, frees, serializes and deserializes FMU states.
:class:`Instances` makes a test's instances and frees them together; :func:`across_initialization` drives instances
through a state taken or set in initialization mode. Outputs are compared bit for bit (:func:`same_bits`,
:func:`differ` for the message); the tests keep their assertions.
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass
from functools import lru_cache
from itertools import count
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np
import pytest

__all__ = ["BOOLEAN", "H", "REAL", "Built", "Instance", "Instances", "Taken", "across_initialization", "differ",
           "fmi2_callbacks", "probe", "refused", "same_bits", "set_tunable"]

H = 1e-3  # communication / Euler step, s (every FMU's default experiment step)
REAL, BOOLEAN = ("Real", "Float64"), ("Boolean",)  # variable types, FMI 2.0 and 3.0 names
FMI_STATUS = {0: "ok", 1: "warning", 2: "discard", 3: "error", 4: "fatal", 5: "pending"}


@dataclass(frozen=True)
class Built:
    """One built FMU, unzipped once."""

    name: str
    fmi: int
    md: object
    unzip: str

    @classmethod
    def load(cls, path: Path, name: str, fmi: int) -> Built:
        """The FMU at ``path`` unzipped (into the suite's temp folder), its model description read."""
        from fmpy import extract, read_model_description

        return cls(name, fmi, read_model_description(str(path)), extract(str(path)))

    def var(self, name: str):  # noqa: ANN201
        return next(v for v in self.md.modelVariables if v.name == name)

    def has(self, name: str) -> bool:
        return any(v.name == name for v in self.md.modelVariables)


_FMI2_LOGS: dict[int, list[str]] = {}
_FMI2_KEYS = count(1)


def _fmi2_log(env, instance_name, status, category, message) -> None:  # noqa: ANN001
    _FMI2_LOGS[env].append(message.decode())


@lru_cache(maxsize=1)
def _fmi2_logger():  # noqa: ANN202
    from fmpy.fmi2 import fmi2CallbackLoggerTYPE

    return fmi2CallbackLoggerTYPE(_fmi2_log)


def fmi2_callbacks(messages: list[str]):  # noqa: ANN201
    """FMI 2 callbacks whose logger appends to ``messages``. FMPy's proxy (which formats the variadic message) keeps
    one Python logger for the process, the last one given, so one logger serves every instance and tells them apart
    by the componentEnvironment, a key of ``_FMI2_LOGS``."""
    from fmpy.fmi2 import (calloc, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                           fmi2CallbackFunctions, free)
    from fmpy.logging import addLoggerProxy

    key = next(_FMI2_KEYS)
    _FMI2_LOGS[key] = messages
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = _fmi2_logger()
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    callbacks.componentEnvironment = key
    addLoggerProxy(ctypes.byref(callbacks))
    return callbacks


class Taken(NamedTuple):
    """An FMU state and the importer's part when it was taken: step index, time (``inst.set_state(*taken)``)."""

    state: object
    k: int
    t: float


class Instance:
    """One instance driven from here (``interface`` "cs" or "me"): inputs varied with the step index, CS doStep or ME
    explicit Euler steps; the FMU's log messages collected in ``messages`` (``logging_on``: FMI's loggingOn, which
    some FMUs need to log at all)."""

    def __init__(self, built: Built, interface: str, label: str = "a", *, logging_on: bool = False) -> None:
        from fmpy.fmi2 import FMU2Model, FMU2Slave
        from fmpy.fmi3 import FMU3Model, FMU3Slave

        self.built, self.fmi, self.me = built, built.fmi, interface == "me"
        md = built.md
        cls = {(2, False): FMU2Slave, (2, True): FMU2Model, (3, False): FMU3Slave, (3, True): FMU3Model}
        kind = md.modelExchange if self.me else md.coSimulation
        self.fmu = cls[self.fmi, self.me](guid=md.guid, unzipDirectory=built.unzip,
                                          modelIdentifier=kind.modelIdentifier,
                                          instanceName=f"{built.name}_{interface}_{label}")
        self.messages: list[str] = []
        if self.fmi == 2:
            self.fmu.instantiate(callbacks=fmi2_callbacks(self.messages), loggingOn=logging_on)
        else:
            self.fmu.instantiate(loggingOn=logging_on, logMessage=lambda *args: self.messages.append(args[-1].decode()))
        variables = md.modelVariables
        self.inputs = [v for v in variables if v.causality == "input" and v.type in REAL]
        self.real_out = [v.valueReference for v in variables if v.causality == "output" and v.type in REAL]
        self.bool_out = [v.valueReference for v in variables if v.causality == "output" and v.type in BOOLEAN]
        self.nx = len(md.derivatives) if self.me else 0
        self.x = (ctypes.c_double * max(self.nx, 1))()
        self.dx = (ctypes.c_double * max(self.nx, 1))()
        self.k, self.t = 0, 0.0
        self.wobble = 1e-3  # relative size of the input variation (0: the inputs stay at their start values)

    # -- values
    def set_real(self, names_values: dict[str, float]) -> None:
        vrs = [self.built.var(n).valueReference for n in names_values]
        (self.fmu.setReal if self.fmi == 2 else self.fmu.setFloat64)(vrs, [float(x) for x in names_values.values()])

    def get_real(self, names: list[str]) -> list[float]:
        vrs = [self.built.var(n).valueReference for n in names]
        return list((self.fmu.getReal if self.fmi == 2 else self.fmu.getFloat64)(vrs))

    def set_start(self, start: dict) -> None:
        """Parameters: strings through setString, numbers through setReal / setFloat64."""
        strings = {n: v for n, v in start.items() if isinstance(v, str)}
        if strings:
            self.fmu.setString([self.built.var(n).valueReference for n in strings], list(strings.values()))
        numbers = {n: v for n, v in start.items() if not isinstance(v, str)}
        if numbers:
            self.set_real(numbers)

    def set_inputs(self) -> None:
        """Inputs of step ``k``: their start values (a valid pose, the hold or zero efforts) moved by a few
        thousandths (``wobble``)."""
        if not self.inputs:
            return
        values = [float(v.start or 0.0) for v in self.inputs]
        values = [s + self.wobble * max(1.0, abs(s)) * math.sin(0.7 * self.k + 1.3 * i) for i, s in enumerate(values)]
        (self.fmu.setReal if self.fmi == 2 else self.fmu.setFloat64)([v.valueReference for v in self.inputs], values)

    def outputs(self) -> np.ndarray:
        """Every output (booleans as 0/1), then (ME) the continuous states the importer holds."""
        real = (self.fmu.getReal if self.fmi == 2 else self.fmu.getFloat64)(self.real_out) if self.real_out else []
        boolean = [float(b) for b in self.fmu.getBoolean(self.bool_out)] if self.bool_out else []
        return np.array([*real, *boolean, *self.x[:self.nx]], dtype=float)

    # -- life cycle
    def initialize(self, start: dict | None = None, t0: float = 0.0, *, exit_: bool = True) -> None:
        """Initialization mode at ``t0`` with the parameters ``start`` and the inputs of step 0; then (``exit_``)
        out of it, into step mode (CS) or continuous-time mode (ME)."""
        if self.fmi == 2:
            self.fmu.setupExperiment(startTime=t0)
            self.fmu.enterInitializationMode()
        else:
            self.fmu.enterInitializationMode(startTime=t0)
        self.t, self.k = t0, 0
        if start:
            self.set_start(start)
        self.set_inputs()
        if exit_:
            self.exit_initialization()

    def exit_initialization(self) -> None:
        self.fmu.exitInitializationMode()
        if self.me:
            self.event_iteration()
            self.fmu.enterContinuousTimeMode()
            self.read_states()

    def event_iteration(self) -> None:
        (self.fmu.newDiscreteStates if self.fmi == 2 else self.fmu.updateDiscreteStates)()

    def read_states(self) -> None:
        """The importer's copy of the continuous states from the FMU (after an FMU state was set)."""
        if self.nx:
            self.fmu.getContinuousStates(self.x, self.nx)

    def derivatives(self) -> np.ndarray:
        if self.fmi == 2:
            self.fmu.getDerivatives(self.dx, self.nx)
        else:
            self.fmu.getContinuousStateDerivatives(self.dx, self.nx)
        return np.array(self.dx[:self.nx])

    def step(self) -> np.ndarray:
        """One step with the inputs of step ``k``; the outputs after it."""
        self.set_inputs()
        if not self.me:
            self.fmu.doStep(self.t, H)
        else:
            self.fmu.setTime(self.t)
            if self.nx:
                self.fmu.setContinuousStates(self.x, self.nx)
                dx = self.derivatives()
                for i in range(self.nx):
                    self.x[i] += H * dx[i]
            self.fmu.setTime(self.t + H)
            if self.nx:
                self.fmu.setContinuousStates(self.x, self.nx)
            self.fmu.completedIntegratorStep()
        self.t += H
        self.k += 1
        return self.outputs()

    def steps(self, n: int) -> np.ndarray:
        return np.stack([self.step() for _ in range(n)])

    # -- FMU state
    def get_state(self, into=None):  # noqa: ANN001, ANN201
        """A new FMU state, or the state now written into the handle ``into`` (FMI's reuse, as the master's
        ``save_state(into=...)``)."""
        if into is None:
            return self.fmu.getFMUstate() if self.fmi == 2 else self.fmu.getFMUState()
        get = self.fmu.fmi2GetFMUstate if self.fmi == 2 else self.fmu.fmi3GetFMUState
        get(self.fmu.component, ctypes.byref(into))
        return into

    def set_state(self, state, k: int, t: float) -> None:  # noqa: ANN001
        """The FMU state, and the importer's part: step index, time, (ME) continuous states read back."""
        (self.fmu.setFMUstate if self.fmi == 2 else self.fmu.setFMUState)(state)
        self.k, self.t = k, t
        self.read_states()

    def take(self) -> Taken:
        return Taken(self.get_state(), self.k, self.t)

    def twice(self, n: int) -> tuple[Taken, np.ndarray, np.ndarray]:
        """The FMU state now; ``n`` steps; the state set again and the same ``n`` steps. The state taken (the caller
        frees it) and both histories (equal bit for bit where the state is complete)."""
        taken = self.take()
        first = self.steps(n)
        self.set_state(*taken)
        return taken, first, self.steps(n)

    def free_state(self, state) -> None:  # noqa: ANN001
        (self.fmu.freeFMUstate if self.fmi == 2 else self.fmu.freeFMUState)(state)

    def serialize(self, state) -> bytes:  # noqa: ANN001
        return bytes((self.fmu.serializeFMUstate if self.fmi == 2 else self.fmu.serializeFMUState)(state))

    def deserialize(self, data: bytes):  # noqa: ANN201
        return (self.fmu.deSerializeFMUstate if self.fmi == 2 else self.fmu.deserializeFMUState)(data)

    def serialized(self) -> bytes:
        """The FMU state now, serialized (the state itself freed)."""
        state = self.get_state()
        data = self.serialize(state)
        self.free_state(state)
        return data

    def set_serialized(self, data: bytes, k: int, t: float) -> None:
        """The FMU state serialized in ``data`` (deserialized, set, freed), and the importer's part."""
        copy = self.deserialize(data)
        self.set_state(copy, k, t)
        self.free_state(copy)

    def free(self) -> None:
        self.fmu.freeInstance()


class Instances:
    """The instances one test makes (``instances(built, interface, label)``), freed together at its end whatever
    happened: an ``instances`` fixture yields one and then calls :meth:`free`."""

    def __init__(self, *, logging_on: bool = False) -> None:
        self.logging_on = logging_on
        self._made: list[Instance] = []

    def __call__(self, built: Built, interface: str, label: str = "a") -> Instance:
        self._made.append(Instance(built, interface, label, logging_on=self.logging_on))
        return self._made[-1]

    def free(self) -> None:
        for inst in reversed(self._made):
            inst.free()
        self._made.clear()


def across_initialization(make: Callable[[str], Instance], k: int, n: int
                          ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Two pairs of histories that must be equal when an FMU state crosses initialization; ``make(label)`` makes an
    instance.

    * ``n`` steps of a freshly initialized instance; the ``n`` steps of another after a state it took in
      initialization mode is set after ``k`` steps;
    * those ``n`` steps after the ``k``; the ``n`` steps of a third instance that, in initialization mode, was set to
      the state taken after the ``k`` steps and then left initialization mode.
    """
    reference = make("reference")
    reference.initialize()
    from_start = reference.steps(n)

    a = make("a")
    a.initialize(exit_=False)
    initial = a.get_state()
    a.exit_initialization()
    a.steps(k)
    later = a.take()
    after_k = a.steps(n)
    a.set_state(initial, 0, 0.0)
    restarted = a.steps(n)

    b = make("b")
    b.initialize(exit_=False)
    (b.fmu.setFMUstate if b.fmi == 2 else b.fmu.setFMUState)(later.state)
    b.exit_initialization()
    b.k, b.t = later.k, later.t
    continued = b.steps(n)
    a.free_state(initial)
    a.free_state(later.state)
    return (from_start, restarted), (after_k, continued)


def differ(a: np.ndarray, b: np.ndarray) -> str:
    """Where two output histories differ, with both values (for an assertion's message)."""
    if a.shape != b.shape:
        return f"shapes {a.shape} vs {b.shape}"
    bad = np.argwhere(a.view(np.uint64) != b.view(np.uint64))
    return "; ".join(f"at {tuple(int(i) for i in idx)}: {a[tuple(idx)]!r} vs {b[tuple(idx)]!r}" for idx in bad[:4])


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def refused(inst: Instance, call, *args, status: int) -> list[str]:  # noqa: ANN001
    """Call an FMU function that must refuse with the FMI status ``status`` (FMPy raises); the messages it logged."""
    from fmpy.fmi1 import FMICallException

    before = len(inst.messages)
    with pytest.raises(FMICallException) as exc:
        call(*args)
    assert exc.value.status == status, \
        f"{exc.value} (status {exc.value.status}, expected {status}: {FMI_STATUS[status]})"
    return inst.messages[before:]


def set_tunable(inst: Instance, values: dict[str, float]) -> None:
    """Set tunable parameters after initialization: in step mode (CS), in event mode (ME, as FMI requires)."""
    if inst.me:
        inst.fmu.enterEventMode()
        inst.set_real(values)
        inst.event_iteration()
        inst.fmu.enterContinuousTimeMode()
    else:
        inst.set_real(values)


def probe(inst: Instance) -> np.ndarray:
    """What the payload must change: CS, the outputs after one step; ME, at the current time and states with the
    inputs of the next step, the derivatives and the outputs."""
    if not inst.me:
        return inst.step()
    inst.set_inputs()
    inst.fmu.setTime(inst.t)
    if inst.nx:
        inst.fmu.setContinuousStates(inst.x, inst.nx)
        return np.concatenate([inst.derivatives(), inst.outputs()])
    return inst.outputs()
