"""FMI 3.0 wrappers: co-simulation and model exchange, every variable type and arrays."""

from __future__ import annotations

import ctypes
from ctypes import byref, c_double, c_int32, c_int64, c_size_t, c_uint32
from typing import Any, Iterable

from ..errors import FMIError, ScenarioError, shown
from .description import BINARY, STRING, Variable
from .model_exchange import ModelExchange
from .pythonfmu import KEEP_ALIVE
from .slave import Base, Buffers, CoSimulation, Terminated, as_number

# --------------------------------------------------------------------------- FMI 3.0

_CTYPE3 = {"Float64": c_double, "Float32": ctypes.c_float, "Int8": ctypes.c_int8, "Int16": ctypes.c_int16,
           "Int32": c_int32, "Int64": c_int64, "UInt8": ctypes.c_uint8, "UInt16": ctypes.c_uint16,
           "UInt32": c_uint32, "UInt64": ctypes.c_uint64, "Boolean": ctypes.c_bool, "Enumeration": c_int64}
# FMI 3.0 accessor per declared type (Enumeration values travel as Int64)
_ACCESSOR3 = {**{t: t for t in _CTYPE3}, "Enumeration": "Int64", "String": "String", "Binary": "Binary"}


class FMI3(Base):
    fmi = 3

    def _group(self, variables: Iterable[Variable]) -> list[Buffers]:
        # FMI 3.0 getters are per declared type, so group by accessor (kind kept for conversions)
        by_type: dict[str, list[Variable]] = {}
        for v in variables:
            by_type.setdefault(_ACCESSOR3[v.fmi_type], []).append(v)
        return [Buffers(vs[0].kind, t, vs, _CTYPE3.get(t)) for t, vs in by_type.items()]

    def _make(self) -> Any:
        from fmpy.fmi3 import (  # lazy: --help loads this module without it
            FMU3Model,
            FMU3Slave,
        )

        md = self.info.md
        cls, ident = (FMU3Model, md.modelExchange.modelIdentifier) if self.model_exchange else \
            (FMU3Slave, md.coSimulation.modelIdentifier)
        return cls(guid=md.guid, unzipDirectory=str(self.info.unzipdir), modelIdentifier=ident,
                   instanceName=self.name)

    def instantiate(self) -> None:
        self.fmu = self._load_library()
        self._note_library()
        logger = lambda env, status, cat, msg: self._on_log(status, cat, msg)  # noqa: E731
        self._logger = logger
        KEEP_ALIVE.append((logger, self.fmu))
        what = "fmi3InstantiateModelExchange" if self.model_exchange else "fmi3InstantiateCoSimulation"
        # loggingOn: pythonfmu3 (like pythonfmu) reports the exceptions of its Python code only then
        self._guard(what, lambda: self.fmu.instantiate(loggingOn=True, logMessage=logger))
        self._instantiated = True
        self._c = self.fmu.component

    def _exchange_name(self, direction: str, b: Buffers) -> str:
        return f"fmi3{direction}{b.fmi_type}"

    def _exchange_args(self, b: Buffers) -> tuple:
        return self._c, b.vrs, b.n, b.values, b.size

    def _set_values(self, var: Variable, values: list[Any], what: str) -> None:
        t = _ACCESSOR3[var.fmi_type]
        if var.kind == STRING:
            values = [str(v) for v in values]
        elif var.kind == BINARY:
            values = [_binary(v, var.name) for v in values]
        else:
            values = [as_number(var.kind, v) for v in values]
        self._guard(f"fmi3Set{t} ({what})", self._py_set, t, [var.vr], values)

    def _py_set(self, accessor: str, vrs: list[int], values: list[Any]) -> None:
        """fmi3Set<accessor> for any element count (fmpy's setters pass nValues = len(values))."""
        getattr(self.fmu, f"set{accessor}")(vrs, values)

    def enter_initialization(self, start: float, stop: float) -> None:
        self.time = start
        self._guard("fmi3EnterInitializationMode", self.fmu.enterInitializationMode, None, start, stop)

    def _set_text(self, b: Buffers) -> None:
        self._guard(f"fmi3Set{b.fmi_type}", self._py_set, b.fmi_type, list(b.vrs), list(b.values))

    def _get_text(self, b: Buffers) -> None:
        """Strings and binaries: copied out of the FMU's memory (valid only until its next call)."""
        c = self._c
        if b.kind == STRING:
            raw = (ctypes.c_char_p * b.size)()
            self._check(self.fmu.dll.fmi3GetString(c, b.vrs, b.n, raw, b.size), "fmi3GetString")
            b.values[:] = [(s or b"").decode("utf-8", "replace") for s in raw]
        else:
            from fmpy.fmi3 import fmi3Binary  # lazy: --help loads this module without it

            sizes = (c_size_t * b.size)()
            ptrs = (fmi3Binary * b.size)()
            self._check(self.fmu.dll.fmi3GetBinary(c, b.vrs, b.n, sizes, ptrs, b.size), "fmi3GetBinary")
            b.values[:] = [ctypes.string_at(p, n) if p else b"" for p, n in zip(ptrs, sizes)]



def _binary(value: Any, name: str) -> bytes:
    """A Binary start value from a scenario: bytes, or a hex string as in modelDescription.xml."""
    if isinstance(value, (bytes, bytearray)):
        return bytes(value)
    try:
        return bytes.fromhex(str(value))
    except ValueError:
        # Refused (correctness): bytes we cannot read: the value set would be a guess
        raise ScenarioError(f"{name}: a Binary value is given as hexadecimal digits, got {shown(repr(value))}") from None


class FMI3CoSimulation(CoSimulation, FMI3):
    """FMI 3.0 co-simulation instance (no event mode, no early return)."""

    def exit_initialization(self) -> None:
        self._guard("fmi3ExitInitializationMode", self.fmu.exitInitializationMode)
        # eventHandlingNeeded, terminateSimulation, earlyReturn, lastSuccessfulTime: written by the FMU
        self._flags = [ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), c_double()]
        # noSetFMUStatePriorToCurrentPoint = true, then the flags' addresses
        self._do_step = self._step_call("fmi3DoStep", ctypes.c_bool(True), *[byref(x) for x in self._flags])
        self._bind_turn()

    def step(self, t: float, h: float) -> None:
        self.time = t
        self._t.value = t
        self._h.value = h
        status = self._do_step()
        if status > 1 or self._flags[1].value:
            self._step_failed(status, t, h)
        self.time = t + h

    def _step_failed(self, status: int, t: float, h: float) -> None:
        """A doStep that failed or asked to end the simulation (terminateSimulation): raise accordingly."""
        if status == 2 and self._flags[1].value and not self._error_logged_at(t):
            # fmi3Discard with terminateSimulation: the FMU ends the run (unless it logged an error)
            t_last = self._flags[3].value if self._flags[2].value and self._flags[3].value > t else t
            self.time = t_last
            raise Terminated(self.name, "fmi3DoStep", t_last)
        if status > 1:
            detail = "the FMU rejected the step" if status == 2 else ""
            if status == 2 and self._last_log():
                detail += f" ({self._last_log()})"
            self._fatal = self._fatal or status == 4
            raise FMIError(self.name, "fmi3DoStep", t, status, detail or self._last_log())
        if self._flags[1].value:  # terminateSimulation
            t_last = self._flags[3].value if self._flags[2].value else t + h
            self.time = t_last
            raise Terminated(self.name, "fmi3DoStep", t_last)


class FMI3ModelExchange(ModelExchange, FMI3):
    """FMI 3.0 model exchange, integrated by the master (see :class:`ModelExchange`)."""

    _update_name = "fmi3UpdateDiscreteStates"
    _completed_name = "fmi3CompletedIntegratorStep"

    def instantiate(self) -> None:
        super().instantiate()
        self.next_event = None
        self._needs_completed = bool(self.info.md.modelExchange.needsCompletedIntegratorStep)
        self._bind_me("fmi3", "GetContinuousStateDerivatives")

    def exit_initialization(self) -> None:
        self.nx = self._guard("fmi3GetNumberOfContinuousStates", self.fmu.getNumberOfContinuousStates)
        self.nz = self._guard("fmi3GetNumberOfEventIndicators", self.fmu.getNumberOfEventIndicators)
        super().exit_initialization()

    def _exit_init(self):
        self._guard("fmi3ExitInitializationMode", self.fmu.exitInitializationMode)

    def _enter_event_mode(self):
        self._guard("fmi3EnterEventMode", self.fmu.enterEventMode)

    def _enter_continuous_mode(self):
        self._guard("fmi3EnterContinuousTimeMode", self.fmu.enterContinuousTimeMode)

    def _update_discrete(self):
        return self._guard("fmi3UpdateDiscreteStates", self.fmu.updateDiscreteStates)

    def _completed_step(self):
        return self._guard("fmi3CompletedIntegratorStep", self.fmu.completedIntegratorStep)
