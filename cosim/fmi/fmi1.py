"""FMI 1.0 wrappers: co-simulation and model exchange, through fmpy's FMU1Slave and FMU1Model.

FMI 1.0 differs from 2.0 in ways the shared machinery does not see: every C function is named with the
model identifier as prefix (``Stair_fmiDoStep``); a Boolean is a ``char``; there is no initialization mode
(``fmiInitializeSlave`` / ``fmiInitialize`` do it in one call after the start values and first inputs are
set, model exchange's returning the result of the first event update); model exchange has no event mode
(``fmiEventUpdate`` is called in continuous time) and no flag for ``fmiCompletedIntegratorStep``, which is
called after every completed integrator step; the logger has no componentEnvironment (see
:mod:`.logger`). Co-simulation has no ``fmiTerminated`` status: a step returning ``fmiDiscard`` is a
failed step, as FMPy and libcosim take it, and only a model-exchange FMU can end the simulation
(``terminateSimulation`` of its event update).
"""

from __future__ import annotations

import ctypes
from ctypes import byref, c_double, c_int, c_int8, c_int32
from typing import Any

from ..errors import FMIError
from .description import BOOLEAN, INTEGER, REAL, STRING, Variable
from .fmi2 import FMI2, FMI2CoSimulation
from .logger import FMI1_INSTANTIATING, FMI2_LOG_TARGETS, fmi2_logger
from .model_exchange import ModelExchange
from .pythonfmu import KEEP_ALIVE
from .slave import Base, Buffers, CoSimulation, as_number

_CS_STATUS_FUNCTIONS = ("InitializeSlave", "DoStep", "CancelStep", "GetStatus", "GetRealStatus", "GetIntegerStatus",
                        "GetBooleanStatus", "GetStringStatus", "SetRealInputDerivatives", "GetRealOutputDerivatives")


class FMI1(Base):
    fmi = 1

    def _ctype(self, kind: str, fmi_type: str) -> Any:
        return {REAL: c_double, INTEGER: c_int32, BOOLEAN: c_int8}.get(kind)  # fmiBoolean is a char

    _group = FMI2._group  # buffers by kind, as FMI 2.0 (with this version's C types)
    _exchange_args = FMI2._exchange_args  # fmiSet<Type>(c, vr, nvr, value): FMI 2.0's signature

    @property
    def _identifier(self) -> str:
        md = self.info.md
        return (md.modelExchange if self.model_exchange else md.coSimulation).modelIdentifier

    def _symbol(self, function: str) -> str:
        """The C name of FMI 1.0 function ``fmi<function>``: prefixed with the model identifier."""
        return f"{self._identifier}_fmi{function}"

    def _make(self) -> Any:
        from fmpy.fmi1 import (  # lazy: --help loads this module without it
            FMU1Model,
            FMU1Slave,
        )

        cls = FMU1Model if self.model_exchange else FMU1Slave
        fmu = cls(guid=self.info.md.guid, unzipDirectory=str(self.info.unzipdir), modelIdentifier=self._identifier,
                  instanceName=self.name)
        if not self.model_exchange:
            # fmpy 0.3 declares these co-simulation functions as returning a string, not an fmiStatus: a status
            # other than fmiOK would be read as a pointer (a crash); declared here as the standard has them
            for name in _CS_STATUS_FUNCTIONS:
                getattr(fmu.dll, self._symbol(name)).restype = c_int
        return fmu

    def instantiate(self) -> None:
        from fmpy import (  # lazy: --help loads this module without it
            calloc,
            free,
        )
        from fmpy.fmi1 import (  # lazy: --help loads this module without it
            fmi1CallbackAllocateMemoryTYPE,
            fmi1CallbackFreeMemoryTYPE,
            fmi1CallbackFunctions,
            fmi1CallbackLoggerTYPE,
        )
        from fmpy.logging import addLoggerProxy  # lazy: --help loads this module without it

        self.fmu = self._load_library()
        self._note_library()
        cb = fmi1CallbackFunctions()
        cb.logger = ctypes.cast(fmi2_logger(), fmi1CallbackLoggerTYPE)  # the same signature as FMI 2.0's
        cb.allocateMemory = fmi1CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi1CallbackFreeMemoryTYPE(free)
        cb.stepFinished = None
        addLoggerProxy(byref(cb))
        self._callbacks = cb
        KEEP_ALIVE.append((cb, self.fmu))
        what = self._symbol("InstantiateModel" if self.model_exchange else "InstantiateSlave")
        key = self.name.encode("utf-8")
        FMI1_INSTANTIATING[key] = self  # what it logs before it has a component
        try:
            if self.model_exchange:
                self._guard(what, self.fmu.instantiate, cb, True)
            else:
                self._guard(what, self.fmu.instantiate, "application/x-fmu-sharedlibrary", 0, b"\x00", b"\x00", cb,
                            True)
        finally:
            FMI1_INSTANTIATING.pop(key, None)
        if not self.fmu.component:
            raise FMIError(self.name, what, self.time, None, self._last_log() or "no instance returned")
        self._instantiated = True
        self._c = self.fmu.component
        FMI2_LOG_TARGETS[self._c] = self  # FMI 1.0 loggers get the component as their first argument

    def _set_values(self, var: Variable, values: list[Any], what: str) -> None:
        kind = var.kind
        fn = {REAL: self.fmu.setReal, INTEGER: self.fmu.setInteger, BOOLEAN: self.fmu.setBoolean,
              STRING: self.fmu.setString}[kind]
        values = [str(v) for v in values] if kind == STRING else [as_number(kind, v) for v in values]
        self._guard(f"{self._symbol('Set' + kind)} ({what})", fn, [var.vr], values)

    _initialized = False  # fmiInitializeSlave / fmiInitialize called
    _set_after_init = False  # inputs set after it, before exit_initialization

    def enter_initialization(self, start: float, stop: float) -> None:
        """FMI 1.0 has no initialization mode: the FMU initializes when its outputs are first read (the
        execution reads them after it set the inputs whose sources come earlier in its order), or at
        :meth:`exit_initialization`; start values and inputs set before are what it initializes with."""
        self.time = start
        self._start, self._stop = start, stop

    def _initialize(self) -> None:
        """fmiInitializeSlave / fmiInitialize."""
        raise NotImplementedError

    def set_inputs(self) -> None:
        if self._initialized and self.in_bufs:
            self._set_after_init = True
        super().set_inputs()

    def get_outputs(self) -> None:
        if not self._initialized:  # FMI 1.0 outputs exist only after the FMU initialized
            self._initialize()
            self._initialized = True
        super().get_outputs()

    def _exchange_name(self, direction: str, b: Buffers) -> str:
        return self._symbol(f"{direction}{b.kind}")

    def _set_text(self, b: Buffers) -> None:
        self._guard(self._symbol("SetString"), self.fmu.setString, list(b.vrs), [str(s) for s in b.values])

    def _get_text(self, b: Buffers) -> None:
        got = self._guard(self._symbol("GetString"), self.fmu.getString, list(b.vrs))
        b.values[:] = [(s or b"").decode("utf-8", "replace") if isinstance(s, bytes) else (s or "") for s in got]


class FMI1CoSimulation(CoSimulation, FMI1):
    """FMI 1.0 co-simulation slave."""

    step = FMI2CoSimulation.step  # doStep through the bound call, the status checked as in FMI 2.0

    def _initialize(self) -> None:
        self._guard(self._symbol("InitializeSlave"), self.fmu.initialize, self._start, self._stop)

    def exit_initialization(self) -> None:
        if not self._initialized:
            self._initialize()
            self._initialized = True
        self._do_step = self._step_call(self._symbol("DoStep"), ctypes.c_char(b"\x01"))  # newStep: true
        self._bind_turn()

    def _step_failed(self, status: int, t: float, h: float) -> None:
        """fmiDiscard: the slave computed a part of the step only (FMI 1.0 has no way to ask to end the
        simulation); the time it reached is said when it tells it."""
        function = self._symbol("DoStep")
        if status == 2:
            from fmpy.fmi1 import fmi1LastSuccessfulTime  # lazy: --help loads this module without it

            detail = "the FMU rejected the step"
            try:
                t_last = float(self.fmu.getRealStatus(fmi1LastSuccessfulTime).value)
            except Exception:  # noqa: BLE001 - optional: then only the step's start is known to be done
                t_last = t
            if t < t_last < t + h and f"{t_last:.9g}" != f"{t:.9g}":  # beyond the step's start as shown
                detail += f" after reaching t = {t_last:.9g} s"
            if self._last_log():
                detail += f" ({self._last_log()})"
            raise FMIError(self.name, function, t, status, detail)
        self._check(status, function)


class FMI1ModelExchange(ModelExchange, FMI1):
    """FMI 1.0 model exchange, integrated by the master (see :class:`ModelExchange`)."""

    _initial_event: tuple | None = None  # fmiInitialize's event info, the first event update

    def instantiate(self) -> None:
        super().instantiate()
        md = self.info.md
        self.nx = md.numberOfContinuousStates
        self.nz = md.numberOfEventIndicators
        self._needs_completed = True  # FMI 1.0: after every completed integrator step
        self.next_event = None
        self._update_name = self._symbol("EventUpdate")
        self._completed_name = self._symbol("CompletedIntegratorStep")
        self._bind_me(f"{self._identifier}_fmi", "GetDerivatives", "GetNominalContinuousStates")

    def enter_initialization(self, start: float, stop: float) -> None:
        super().enter_initialization(start, stop)
        self._guard(self._symbol("SetTime"), self.fmu.setTime, start)

    def _initialize(self) -> None:
        self._initial_event = self._guard(self._symbol("Initialize"), self.fmu.initialize)

    def _exit_init(self):
        """Initialize now if the outputs were not read; inputs set after fmiInitialize are taken by an event
        update (FMI 1.0: a discrete input changes at events only), so its event info is not the last word."""
        if not self._initialized:
            self._initialize()
            self._initialized = True
        elif self._set_after_init:
            self._initial_event = None

    def _enter_event_mode(self):
        """FMI 1.0 has no event mode."""

    def _enter_continuous_mode(self):
        """FMI 1.0 has no continuous-time mode."""

    def _update_discrete(self):
        """fmiEventUpdate in the terms of FMI 2.0's fmi2NewDiscreteStates; the first one is fmiInitialize's."""
        info, self._initial_event = self._initial_event, None
        if info is None:
            info = self._guard(self._update_name, self.fmu.eventUpdate)
        converged, references_changed, values_changed, terminate, upcoming, t_next = info
        return not converged, terminate, references_changed, values_changed, upcoming, t_next

    def _completed_step(self):
        return self._guard(self._completed_name, self.fmu.completedIntegratorStep), False
