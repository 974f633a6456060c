"""FMI 2.0 wrappers: co-simulation and model exchange."""

from __future__ import annotations

import ctypes
from ctypes import byref, c_double, c_int32
from typing import Any, Iterable

from ..errors import FMIError
from .description import BOOLEAN, INTEGER, REAL, STRING, Variable
from .logger import FMI2_ENVIRONMENTS, FMI2_LOG_TARGETS, fmi2_logger
from .model_exchange import ModelExchange
from .pythonfmu import KEEP_ALIVE
from .slave import Base, Buffers, CoSimulation, Terminated, as_number

# --------------------------------------------------------------------------- FMI 2.0


class FMI2(Base):
    fmi = 2

    def _ctype(self, kind: str, fmi_type: str) -> Any:
        return {REAL: c_double, INTEGER: c_int32, BOOLEAN: c_int32}.get(kind)

    def _group(self, variables: Iterable[Variable]) -> list[Buffers]:
        by_kind: dict[str, list[Variable]] = {}
        for v in variables:
            by_kind.setdefault(v.kind, []).append(v)
        return [Buffers(k, vs[0].fmi_type, vs, self._ctype(k, vs[0].fmi_type)) for k, vs in by_kind.items()]

    def _make(self) -> Any:
        from fmpy.fmi2 import (  # lazy: --help loads this module without it
            FMU2Model,
            FMU2Slave,
        )

        md = self.info.md
        cls, ident = (FMU2Model, md.modelExchange.modelIdentifier) if self.model_exchange else \
            (FMU2Slave, md.coSimulation.modelIdentifier)
        return cls(guid=md.guid, unzipDirectory=str(self.info.unzipdir), modelIdentifier=ident,
                   instanceName=self.name)

    def instantiate(self) -> None:
        from fmpy import (  # lazy: --help loads this module without it
            calloc,
            free,
        )
        from fmpy.fmi2 import (  # lazy: --help loads this module without it
            fmi2CallbackAllocateMemoryTYPE,
            fmi2CallbackFreeMemoryTYPE,
            fmi2CallbackFunctions,
        )
        from fmpy.logging import addLoggerProxy  # lazy: --help loads this module without it

        self.fmu = self._load_library()
        self._note_library()
        cb = fmi2CallbackFunctions()
        environment = next(FMI2_ENVIRONMENTS)
        FMI2_LOG_TARGETS[environment] = self
        cb.logger = fmi2_logger()
        cb.componentEnvironment = environment
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(byref(cb))
        self._callbacks = cb
        KEEP_ALIVE.append((cb, self.fmu))
        self._guard("fmi2Instantiate", self.fmu.instantiate, False, cb, True)
        self._instantiated = True
        self._c = self.fmu.component

    def _set_values(self, var: Variable, values: list[Any], what: str) -> None:
        kind = var.kind
        fn = {REAL: self.fmu.setReal, INTEGER: self.fmu.setInteger, BOOLEAN: self.fmu.setBoolean,
              STRING: self.fmu.setString}[kind]
        values = [str(v) for v in values] if kind == STRING else [as_number(kind, v) for v in values]
        self._guard(f"fmi2Set{kind} ({what})", fn, [var.vr], values)

    def setup_experiment(self, start: float, stop: float) -> None:
        """fmi2SetupExperiment before the start values: some exporters' FMUs reset their variables in it, and
        FMPy and libcosim set start values after it."""
        self.time = start
        self._guard("fmi2SetupExperiment", self.fmu.setupExperiment, None, start, stop)

    def enter_initialization(self, start: float, stop: float) -> None:
        self.time = start
        self._guard("fmi2EnterInitializationMode", self.fmu.enterInitializationMode)

    def _exchange_name(self, direction: str, b: Buffers) -> str:
        return f"fmi2{direction}{b.kind}"

    def _exchange_args(self, b: Buffers) -> tuple:
        return self._c, b.vrs, b.n, b.values

    def _set_text(self, b: Buffers) -> None:
        self._guard("fmi2SetString", self.fmu.setString, list(b.vrs), [str(s) for s in b.values])

    def _get_text(self, b: Buffers) -> None:
        got = self._guard("fmi2GetString", self.fmu.getString, list(b.vrs))
        b.values[:] = [(s or b"").decode("utf-8", "replace") if isinstance(s, bytes) else (s or "") for s in got]



class FMI2CoSimulation(CoSimulation, FMI2):
    """FMI 2.0 co-simulation slave."""

    def exit_initialization(self) -> None:
        self._guard("fmi2ExitInitializationMode", self.fmu.exitInitializationMode)
        self._do_step = self._step_call("fmi2DoStep", ctypes.c_int(1))  # noSetFMUStatePriorToCurrentPoint: true
        self._bind_turn()

    def step(self, t: float, h: float) -> None:
        self.time = t
        self._t.value = t
        self._h.value = h
        status = self._do_step()
        if status > 1:
            self._step_failed(status, t, h)
        self.time = t + h

    def _step_failed(self, status: int, t: float, h: float) -> None:
        """fmi2Discard with fmi2Terminated is the FMU ending the simulation; anything else fails."""
        from fmpy.fmi2 import (  # lazy: --help loads this module without it
            fmi2LastSuccessfulTime,
            fmi2Terminated,
        )

        if status == 2:  # fmi2Discard
            try:
                terminated = bool(self.fmu.getBooleanStatus(fmi2Terminated))
            except Exception:  # noqa: BLE001 - optional function: the FMU did not say it terminated
                terminated = False
            # pythonfmu sets fmi2Terminated on every rejected step: one that logged an error failed
            if terminated and not self._error_logged_at(t):
                try:
                    t_last = float(self.fmu.getRealStatus(fmi2LastSuccessfulTime))
                except Exception:  # noqa: BLE001 - optional: the step's start is what we know succeeded
                    t_last = t
                self.time = t_last
                raise Terminated(self.name, "fmi2DoStep", t_last)
            if terminated:
                raise FMIError(self.name, "fmi2DoStep", t, status, f"the FMU rejected the step: {self._error_log[1]}")
            detail = "the FMU rejected the step and did not ask to terminate"
            if self._last_log():
                detail += f" ({self._last_log()})"
            raise FMIError(self.name, "fmi2DoStep", t, status, detail)
        self._check(status, "fmi2DoStep")


class FMI2ModelExchange(ModelExchange, FMI2):
    """FMI 2.0 model exchange, integrated by the master (see :class:`ModelExchange`)."""

    _update_name = "fmi2NewDiscreteStates"
    _completed_name = "fmi2CompletedIntegratorStep"

    def instantiate(self) -> None:
        super().instantiate()
        md = self.info.md
        self.nx = md.numberOfContinuousStates
        self.nz = md.numberOfEventIndicators
        self._needs_completed = bool(md.modelExchange.needsCompletedIntegratorStep)
        self.next_event = None
        self._bind_me("fmi2", "GetDerivatives")

    def _exit_init(self):
        self._guard("fmi2ExitInitializationMode", self.fmu.exitInitializationMode)

    def _enter_event_mode(self):
        self._guard("fmi2EnterEventMode", self.fmu.enterEventMode)

    def _enter_continuous_mode(self):
        self._guard("fmi2EnterContinuousTimeMode", self.fmu.enterContinuousTimeMode)

    def _update_discrete(self):
        return self._guard("fmi2NewDiscreteStates", self.fmu.newDiscreteStates)

    def _completed_step(self):
        return self._guard("fmi2CompletedIntegratorStep", self.fmu.completedIntegratorStep)
