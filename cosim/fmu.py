"""FMU access layer: the only module that calls fmpy.

One protocol, :class:`Slave`, over four wrappers: FMI 2.0 and 3.0, co-simulation
and model exchange. Model exchange FMUs are integrated between communication
points with fmpy's CVode (BDF, dense Jacobian) with state, time and step events.

Every FMI status passes through :meth:`_Base._check` (the hot path calls the
C functions directly with pre-built ctypes buffers); a failure raises
:class:`~cosim.errors.FMIError` naming the component, the function, the
simulation time and the FMU's last log message.
"""

from __future__ import annotations

import ctypes
import shutil
import tempfile
from collections import deque
from ctypes import byref, c_double, c_int32, c_int64, c_uint32
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, Iterable, Protocol

from .errors import ComponentSourceError, FMIError, Issue

__all__ = ["Variable", "FMUInfo", "load_fmu", "Slave", "make_slave", "REAL", "INTEGER", "BOOLEAN", "STRING"]

NS = 1e-9
REAL, INTEGER, BOOLEAN, STRING = "Real", "Integer", "Boolean", "String"
# FMI 3.0 type names mapped onto the four kinds the master exchanges
_KIND3 = {"Float64": REAL, "Float32": REAL, "Int32": INTEGER, "Int64": INTEGER, "Int16": INTEGER, "Int8": INTEGER,
          "UInt32": INTEGER, "UInt64": INTEGER, "UInt16": INTEGER, "UInt8": INTEGER, "Boolean": BOOLEAN,
          "String": STRING, "Real": REAL, "Integer": INTEGER, "Enumeration": INTEGER}


@dataclass(frozen=True)
class Variable:
    """A model variable as the master sees it."""

    name: str
    vr: int
    kind: str  # REAL, INTEGER, BOOLEAN or STRING
    fmi_type: str  # the type as declared (Real, Float64, Int32, ...)
    causality: str
    variability: str
    unit: str | None
    description: str | None
    start: Any
    index: int  # 1-based position in ModelVariables (FMI 2.0 ModelStructure indices)


@dataclass
class FMUInfo:
    """A parsed and extracted FMU: model description, variables, interfaces, feedthrough."""

    path: Path
    unzipdir: Path
    md: Any  # fmpy.model_description.ModelDescription
    variables: dict[str, Variable]

    @property
    def fmi_major(self) -> int:
        return int(self.md.fmiVersion.split(".")[0])

    @property
    def interfaces(self) -> list[str]:
        return [k for k, v in (("cs", self.md.coSimulation), ("me", self.md.modelExchange)) if v is not None]

    @cached_property
    def feedthrough(self) -> dict[str, list[str] | None]:
        """Output name -> the inputs it depends on directly; None when the FMU does not declare it."""
        inputs = {v.name for v in self.variables.values() if v.causality == "input"}
        out: dict[str, list[str] | None] = {}
        for u in self.md.outputs:
            if u.dependencies is None:
                out[u.variable.name] = None
            else:
                # every listed input counts, whatever its dependenciesKind (conservative)
                out[u.variable.name] = [d.name for d in u.dependencies if d.name in inputs]
        return out

    def model_description_xml(self) -> bytes:
        return (self.unzipdir / "modelDescription.xml").read_bytes()


_CACHE: dict[Path, FMUInfo] = {}
# Callbacks and library handles handed to FMUs live as long as the process: an FMU may call its
# logger while being freed, and pythonfmu libraries must not be unloaded (GC of their objects crashes).
_KEEP_ALIVE: list[Any] = []


def load_fmu(path: str | Path) -> FMUInfo:
    """Read the model description and extract the FMU once per path (cached for the process)."""
    import fmpy

    path = Path(path).resolve()
    if path in _CACHE:
        return _CACHE[path]
    if not path.exists():
        raise ComponentSourceError(Issue("", f"FMU not found: {path}"))
    try:
        md = fmpy.read_model_description(str(path), validate=False)
    except Exception as exc:  # fmpy raises bare Exception for malformed files
        raise ComponentSourceError(Issue("", f"{path}: cannot read modelDescription.xml: {exc}")) from None
    unzipdir = Path(tempfile.mkdtemp(prefix=f"cosim_{path.stem}_"))
    fmpy.extract(str(path), str(unzipdir))
    variables = {}
    for i, v in enumerate(md.modelVariables, start=1):
        variables[v.name] = Variable(
            name=v.name, vr=v.valueReference, kind=_KIND3.get(v.type, v.type), fmi_type=v.type,
            causality=v.causality, variability=v.variability, unit=_unit(v), description=v.description,
            start=v.start, index=i)
    info = FMUInfo(path, unzipdir, md, variables)
    _CACHE[path] = info
    return info


def _unit(v: Any) -> str | None:
    if getattr(v, "unit", None):
        return v.unit
    dt = getattr(v, "declaredType", None)
    return getattr(dt, "unit", None) if dt is not None else None


def cleanup_extracted(keep: Iterable[Path] = ()) -> None:
    """Remove every extracted FMU directory but those of the FMUs in ``keep`` (call at process end).

    A forked worker process keeps its parent's extractions (``keep``): they are still in use.
    """
    keep = set(keep)
    for path in [p for p in _CACHE if p not in keep]:
        shutil.rmtree(_CACHE.pop(path).unzipdir, ignore_errors=True)


class Slave(Protocol):
    """What the algorithm needs from a component, whatever its FMI version and kind."""

    name: str
    info: FMUInfo
    time: float

    def instantiate(self) -> None: ...
    def set_start(self, values: dict[str, Any]) -> None: ...
    def enter_initialization(self, start: float, stop: float) -> None: ...
    def exit_initialization(self) -> None: ...
    def bind(self, inputs: list[Variable], outputs: list[Variable]) -> None: ...
    def set_inputs(self) -> None: ...
    def get_outputs(self) -> None: ...
    def step(self, t: float, h: float) -> None: ...
    def terminate(self) -> None: ...
    def free(self) -> None: ...


class _Buffers:
    """ctypes arrays for one kind of variable: value references and values."""

    __slots__ = ("vrs", "values", "n", "kind", "variables")

    def __init__(self, kind: str, variables: list[Variable], ctype: Any):
        self.kind = kind
        self.variables = list(variables)
        self.n = len(variables)
        self.vrs = (c_uint32 * self.n)(*[v.vr for v in variables])
        self.values = (ctype * self.n)()


class _Base:
    """Shared machinery: lifecycle through fmpy, hot path through the C functions, one status check."""

    fmi: int = 2
    model_exchange = False

    def __init__(self, name: str, info: FMUInfo):
        self.name = name
        self.info = info
        self.time = 0.0
        self.log: deque[str] = deque(maxlen=20)
        self.in_bufs: list[_Buffers] = []
        self.out_bufs: list[_Buffers] = []
        self._set_calls: list | None = None
        self._get_calls: list | None = None
        self.fmu: Any = None
        self._instantiated = False
        self._terminated = False
        self._fatal = False  # after fmi2Fatal/fmi3Fatal no FMI function may be called, freeInstance included

    # -- the one place where statuses are checked
    def _check(self, status: int, function: str) -> None:
        if status > 1:  # OK = 0, Warning = 1; Discard, Error, Fatal, Pending fail
            self._fatal = self._fatal or status == 4
            raise FMIError(self.name, function, self.time, status, self._last_log())

    def _last_log(self) -> str:
        return self.log[-1] if self.log else ""

    def _guard(self, function: str, call, *args):
        """Lifecycle calls through fmpy (which raises on a failing status): translate to FMIError."""
        from fmpy.fmi1 import FMICallException

        try:
            return call(*args)
        except FMICallException as exc:
            status = getattr(exc, "status", None)
            self._fatal = self._fatal or status == 4
            raise FMIError(self.name, function, self.time, status, self._last_log() or str(exc)) from None
        except FMIError:
            raise
        except Exception as exc:  # fmpy uses bare Exception for failed instantiation
            raise FMIError(self.name, function, self.time, None, self._last_log() or str(exc)) from None

    def _on_log(self, status: int, category: bytes | None, message: bytes | None) -> None:
        text = (message or b"").decode("utf-8", "replace").strip()
        if text:
            self.log.append(text)

    # -- start values (parameters), before initialization
    def set_start(self, values: dict[str, Any]) -> None:
        for name, value in values.items():
            var = self.info.variables[name]
            self._set_values(var.kind, var.fmi_type, [var.vr], [value], f"set start value of {name}")

    def bind(self, inputs: list[Variable], outputs: list[Variable]) -> None:
        """Pre-build buffers for the inputs the master sets and the outputs it reads."""
        self.in_bufs = self._group(inputs)
        self.out_bufs = self._group(outputs)
        self._set_calls = self._get_calls = None  # hot-path call lists, bound at first use

    def _group(self, variables: Iterable[Variable]) -> list[_Buffers]:
        by_kind: dict[str, list[Variable]] = {}
        for v in variables:
            by_kind.setdefault(v.kind, []).append(v)
        return [_Buffers(k, vs, self._ctype(k, vs[0].fmi_type)) for k, vs in by_kind.items()]

    def locate(self, var: Variable, output: bool = True) -> tuple[Any, int]:
        """(ctypes values array, index) where ``var``'s value lives after bind()."""
        for b in (self.out_bufs if output else self.in_bufs):
            if var in b.variables:
                return b.values, b.variables.index(var)
        raise KeyError(f"{self.name}.{var.name} is not bound as an {'output' if output else 'input'}")

    def terminate(self) -> None:
        if self._instantiated and not self._terminated and not self._fatal:
            self._terminated = True
            self._guard(f"fmi{self.fmi}Terminate", self.fmu.terminate)

    def free(self) -> None:
        if self.fmu is None:
            return
        try:
            if self._instantiated and not self._fatal:
                self.fmu.freeInstance()
        finally:
            # the shared library stays loaded: unloading a pythonfmu library while the interpreter
            # still holds objects it created crashes at garbage collection
            self._instantiated = False
            self.fmu = None


# --------------------------------------------------------------------------- FMI 2.0


class _FMI2(_Base):
    fmi = 2

    def _ctype(self, kind: str, fmi_type: str) -> Any:
        return {REAL: c_double, INTEGER: c_int32, BOOLEAN: c_int32, STRING: ctypes.c_char_p}[kind]

    def _make(self) -> Any:
        from fmpy.fmi2 import FMU2Model, FMU2Slave

        md = self.info.md
        cls, ident = (FMU2Model, md.modelExchange.modelIdentifier) if self.model_exchange else \
            (FMU2Slave, md.coSimulation.modelIdentifier)
        return cls(guid=md.guid, unzipDirectory=str(self.info.unzipdir), modelIdentifier=ident,
                   instanceName=self.name)

    def instantiate(self) -> None:
        from fmpy import calloc, free
        from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                               fmi2CallbackLoggerTYPE)
        from fmpy.logging import addLoggerProxy

        self.fmu = self._guard("load library", self._make)
        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(lambda env, inst, status, cat, msg: self._on_log(status, cat, msg))
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(byref(cb))
        self._callbacks = cb
        _KEEP_ALIVE.append((cb, self.fmu))
        self._guard("fmi2Instantiate", self.fmu.instantiate, False, cb, True)
        self._instantiated = True
        dll = self.fmu.dll
        self._c = self.fmu.component
        fn = self._hot_function
        self._get = {k: fn(dll, f"fmi2Get{k}") for k in (REAL, INTEGER, BOOLEAN)}
        self._set = {k: fn(dll, f"fmi2Set{k}") for k in (REAL, INTEGER, BOOLEAN)}

    def _hot_function(self, dll: Any, name: str) -> Any:
        """The C function ``name`` for the per-step path.

        FMUs exported by PythonFMU run Python: each call takes the GIL back (PyGILState_Ensure)
        right after ctypes released it. For them the function is called through a PYFUNCTYPE
        prototype with the same signature, which keeps the GIL across the call and saves that
        round trip; any other FMU keeps ctypes' default (GIL released, so its own threads may
        call back into Python).
        """
        f = getattr(dll, name)
        if not (self.info.md.generationTool or "").startswith("PythonFMU"):
            return f
        proto = ctypes.PYFUNCTYPE(f.restype, *f.argtypes)
        return proto(ctypes.cast(f, ctypes.c_void_p).value)

    def _set_values(self, kind: str, fmi_type: str, vrs: list[int], values: list[Any], what: str) -> None:
        fn = {REAL: self.fmu.setReal, INTEGER: self.fmu.setInteger, BOOLEAN: self.fmu.setBoolean,
              STRING: self.fmu.setString}[kind]
        if kind == STRING:
            values = [str(v) for v in values]
        elif kind == REAL:
            values = [float(v) for v in values]
        else:
            values = [int(v) for v in values]
        self._guard(f"fmi2Set{kind} ({what})", fn, vrs, values)

    def enter_initialization(self, start: float, stop: float) -> None:
        self.time = start
        self._guard("fmi2SetupExperiment", self.fmu.setupExperiment, None, start, stop)
        self._guard("fmi2EnterInitializationMode", self.fmu.enterInitializationMode)

    def _calls(self, bufs: list[_Buffers], table: dict, prefix: str) -> list[tuple[Any, Any, int, Any, str]]:
        """(C function, value references, count, values, FMI name) per buffer, bound once."""
        return [(table[b.kind], b.vrs, b.n, b.values, prefix + b.kind) for b in bufs]

    def set_inputs(self) -> None:
        c = self._c
        calls = self._set_calls
        if calls is None:
            calls = self._set_calls = self._calls(self.in_bufs, self._set, "fmi2Set")
        for fn, vrs, n, values, name in calls:
            status = fn(c, vrs, n, values)
            if status > 1:
                self._check(status, name)

    def get_outputs(self) -> None:
        c = self._c
        calls = self._get_calls
        if calls is None:
            calls = self._get_calls = self._calls(self.out_bufs, self._get, "fmi2Get")
        for fn, vrs, n, values, name in calls:
            status = fn(c, vrs, n, values)
            if status > 1:
                self._check(status, name)

    def read(self, variables: list[Variable]) -> list[Any]:
        """Values of arbitrary variables (slow path, for reports and initialization)."""
        out = []
        for v in variables:
            fn = {REAL: self.fmu.getReal, INTEGER: self.fmu.getInteger, BOOLEAN: self.fmu.getBoolean,
                  STRING: self.fmu.getString}[v.kind]
            out.append(self._guard(f"fmi2Get{v.kind}", fn, [v.vr])[0])
        return out


class FMI2CoSimulation(_FMI2):
    """FMI 2.0 co-simulation slave."""

    def exit_initialization(self) -> None:
        self._guard("fmi2ExitInitializationMode", self.fmu.exitInitializationMode)
        self._do_step = self._hot_function(self.fmu.dll, "fmi2DoStep")

    def step(self, t: float, h: float) -> None:
        self.time = t
        status = self._do_step(self._c, t, h, 1)
        if status > 1:
            self._check(status, "fmi2DoStep")
        self.time = t + h


class _MEMixin:
    """Model exchange: CVode between communication points, event iteration at events."""

    rtol = 1e-6
    _event_eps = 1e-12  # s; a time event within this of the solver's stop time is taken there

    _pending: FMIError | None = None

    def _cb(self, status: int, function: str) -> None:
        """Status check inside CVode callbacks: ctypes swallows exceptions there, so keep the first one."""
        if status > 1 and self._pending is None:
            self._pending = FMIError(self.name, function, self.time, status, self._last_log())

    def _raise_pending(self) -> None:
        if self._pending is not None:
            err, self._pending = self._pending, None
            raise err

    def _setup_solver(self, t0: float) -> None:
        from fmpy.sundials import CVodeSolver

        class _HeldInputs:  # inputs are held constant over a communication step (zero-order hold)
            @staticmethod
            def apply(t: float) -> None:
                return None

        self.solver = CVodeSolver(
            nx=self.nx, nz=self.nz, get_x=self._get_x, set_x=self._set_x, get_dx=self._get_dx, get_z=self._get_z,
            get_nominals=self._get_nominals, set_time=self._set_time, input=_HeldInputs(), startTime=t0,
            relativeTolerance=self.rtol)

    def _handle_event(self) -> bool:
        """Event iteration; returns True when the continuous states changed (solver restart needed)."""
        self._enter_event_mode()
        changed = self._iterate_discrete_states()
        self._enter_continuous_mode()
        return changed

    def _iterate_discrete_states(self) -> bool:
        changed = False
        while True:
            need, terminate, nominals, values, defined, t_next = self._update_discrete()
            if terminate:
                raise FMIError(self.name, self._update_name, self.time, None, "the FMU requested termination")
            changed |= bool(values or nominals)
            self.next_event = t_next if defined else None
            if not need:
                return changed

    def exit_initialization(self) -> None:
        self._exit_init()
        self._iterate_discrete_states()
        self._enter_continuous_mode()
        self._setup_solver(self.time)
        self._raise_pending()

    def step(self, t: float, h: float) -> None:
        t_end = t + h
        self.time = t
        self.solver.reset(t)  # inputs may have jumped at the communication point
        while self.time < t_end - self._event_eps:
            t_stop = t_end if self.next_event is None else min(t_end, self.next_event)
            try:
                state_event, _, t_reached = self.solver.step(self.time, t_stop)
            except RuntimeError as exc:  # CVode failure (fmpy raises RuntimeError with CVode's message)
                self._raise_pending()
                raise FMIError(self.name, "CVode", self.time, None, str(exc)) from None
            self._raise_pending()
            self.time = t_reached
            time_event = self.next_event is not None and abs(self.time - self.next_event) <= self._event_eps
            step_event, terminate = self._completed_step()
            if terminate:
                raise FMIError(self.name, "completedIntegratorStep", self.time, None, "the FMU requested termination")
            if state_event or time_event or step_event:
                if self._handle_event():
                    self.solver.reset(self.time)
        self.time = t_end


class FMI2ModelExchange(_MEMixin, _FMI2):
    """FMI 2.0 model exchange, integrated with CVode."""

    model_exchange = True
    _update_name = "fmi2NewDiscreteStates"

    def instantiate(self) -> None:
        super().instantiate()
        self.nx = self.info.md.numberOfContinuousStates
        self.nz = self.info.md.numberOfEventIndicators
        self.next_event = None

    def _get_x(self, x, nx):
        self._cb(self.fmu.dll.fmi2GetContinuousStates(self._c, x, nx), "fmi2GetContinuousStates")

    def _set_x(self, x, nx):
        self._cb(self.fmu.dll.fmi2SetContinuousStates(self._c, x, nx), "fmi2SetContinuousStates")

    def _get_dx(self, dx, nx):
        self._cb(self.fmu.dll.fmi2GetDerivatives(self._c, dx, nx), "fmi2GetDerivatives")

    def _get_z(self, z, nz):
        self._cb(self.fmu.dll.fmi2GetEventIndicators(self._c, z, nz), "fmi2GetEventIndicators")

    def _get_nominals(self, x, nx):
        self._cb(self.fmu.dll.fmi2GetNominalsOfContinuousStates(self._c, x, nx), "fmi2GetNominalsOfContinuousStates")

    def _set_time(self, t):
        self._cb(self.fmu.dll.fmi2SetTime(self._c, t), "fmi2SetTime")

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


# --------------------------------------------------------------------------- FMI 3.0


class _FMI3(_Base):
    fmi = 3
    _GET = {"Float64": "Float64", "Float32": "Float32", "Int32": "Int32", "Int64": "Int64", "Boolean": "Boolean",
            "Int8": "Int8", "Int16": "Int16", "UInt8": "UInt8", "UInt16": "UInt16", "UInt32": "UInt32",
            "UInt64": "UInt64", "Enumeration": "Int64", "String": "String"}

    def _ctype(self, kind: str, fmi_type: str) -> Any:
        return {"Float64": c_double, "Float32": ctypes.c_float, "Int32": c_int32, "Int64": c_int64,
                "Int16": ctypes.c_int16, "Int8": ctypes.c_int8, "UInt8": ctypes.c_uint8, "UInt16": ctypes.c_uint16,
                "UInt32": c_uint32, "UInt64": ctypes.c_uint64, "Boolean": ctypes.c_bool,
                "Enumeration": c_int64}[fmi_type]

    def _group(self, variables: Iterable[Variable]) -> list[_Buffers]:
        # FMI 3.0 getters are per declared type, so group by fmi_type (kind kept for conversions)
        by_type: dict[str, list[Variable]] = {}
        for v in variables:
            by_type.setdefault(v.fmi_type, []).append(v)
        out = []
        for t, vs in by_type.items():
            out.append(_Buffers(t, vs, self._ctype(vs[0].kind, t)))
        return out

    def _make(self) -> Any:
        from fmpy.fmi3 import FMU3Model, FMU3Slave

        md = self.info.md
        cls, ident = (FMU3Model, md.modelExchange.modelIdentifier) if self.model_exchange else \
            (FMU3Slave, md.coSimulation.modelIdentifier)
        return cls(guid=md.guid, unzipDirectory=str(self.info.unzipdir), modelIdentifier=ident,
                   instanceName=self.name)

    def instantiate(self) -> None:
        self.fmu = self._guard("load library", self._make)
        logger = lambda env, status, cat, msg: self._on_log(status, cat, msg)  # noqa: E731
        self._logger = logger
        _KEEP_ALIVE.append((logger, self.fmu))
        self._guard("fmi3InstantiateCoSimulation", lambda: self.fmu.instantiate(logMessage=logger))
        self._instantiated = True
        self._c = self.fmu.component
        dll = self.fmu.dll
        self._getf = {t: getattr(dll, f"fmi3Get{t}") for t in set(self._GET.values()) if t != "String"}
        self._setf = {t: getattr(dll, f"fmi3Set{t}") for t in set(self._GET.values()) if t != "String"}

    def _set_values(self, kind: str, fmi_type: str, vrs: list[int], values: list[Any], what: str) -> None:
        t = self._GET[fmi_type]
        fn = getattr(self.fmu, f"set{t}")
        if kind == REAL:
            values = [float(v) for v in values]
        elif kind == INTEGER:
            values = [int(v) for v in values]
        elif kind == BOOLEAN:
            values = [bool(v) for v in values]
        else:
            values = [str(v).encode() if t == "String" else v for v in values]
        self._guard(f"fmi3Set{t} ({what})", fn, vrs, values)

    def enter_initialization(self, start: float, stop: float) -> None:
        self.time = start
        self._guard("fmi3EnterInitializationMode", self.fmu.enterInitializationMode, None, start, stop)

    def set_inputs(self) -> None:
        c = self._c
        for b in self.in_bufs:
            self._check(self._setf[self._GET[b.kind]](c, b.vrs, b.n, b.values, b.n), "fmi3Set" + b.kind)

    def get_outputs(self) -> None:
        c = self._c
        for b in self.out_bufs:
            self._check(self._getf[self._GET[b.kind]](c, b.vrs, b.n, b.values, b.n), "fmi3Get" + b.kind)

    def read(self, variables: list[Variable]) -> list[Any]:
        out = []
        for v in variables:
            t = self._GET[v.fmi_type]
            out.append(self._guard(f"fmi3Get{t}", getattr(self.fmu, f"get{t}"), [v.vr])[0])
        return out


class FMI3CoSimulation(_FMI3):
    """FMI 3.0 co-simulation instance (no event mode, no early return)."""

    def exit_initialization(self) -> None:
        self._guard("fmi3ExitInitializationMode", self.fmu.exitInitializationMode)
        self._do_step = self.fmu.dll.fmi3DoStep
        self._flags = [ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), c_double()]
        self._refs = [byref(x) for x in self._flags]

    def step(self, t: float, h: float) -> None:
        self.time = t
        self._check(self._do_step(self._c, t, h, True, *self._refs), "fmi3DoStep")
        if self._flags[1].value:
            raise FMIError(self.name, "fmi3DoStep", t, None, "the FMU requested termination")
        self.time = t + h


class FMI3ModelExchange(_MEMixin, _FMI3):
    """FMI 3.0 model exchange, integrated with CVode."""

    model_exchange = True
    _update_name = "fmi3UpdateDiscreteStates"

    def instantiate(self) -> None:
        self.fmu = self._guard("load library", self._make)
        logger = lambda env, status, cat, msg: self._on_log(status, cat, msg)  # noqa: E731
        self._logger = logger
        _KEEP_ALIVE.append((logger, self.fmu))
        self._guard("fmi3InstantiateModelExchange", lambda: self.fmu.instantiate(logMessage=logger))
        self._instantiated = True
        self._c = self.fmu.component
        dll = self.fmu.dll
        self._getf = {t: getattr(dll, f"fmi3Get{t}") for t in set(self._GET.values()) if t != "String"}
        self._setf = {t: getattr(dll, f"fmi3Set{t}") for t in set(self._GET.values()) if t != "String"}
        self.next_event = None

    def exit_initialization(self) -> None:
        self.nx = self._guard("fmi3GetNumberOfContinuousStates", self.fmu.getNumberOfContinuousStates)
        self.nz = self._guard("fmi3GetNumberOfEventIndicators", self.fmu.getNumberOfEventIndicators)
        super().exit_initialization()

    def _get_x(self, x, nx):
        self._cb(self.fmu.dll.fmi3GetContinuousStates(self._c, x, nx), "fmi3GetContinuousStates")

    def _set_x(self, x, nx):
        self._cb(self.fmu.dll.fmi3SetContinuousStates(self._c, x, nx), "fmi3SetContinuousStates")

    def _get_dx(self, dx, nx):
        self._cb(self.fmu.dll.fmi3GetContinuousStateDerivatives(self._c, dx, nx), "fmi3GetContinuousStateDerivatives")

    def _get_z(self, z, nz):
        self._cb(self.fmu.dll.fmi3GetEventIndicators(self._c, z, nz), "fmi3GetEventIndicators")

    def _get_nominals(self, x, nx):
        self._cb(self.fmu.dll.fmi3GetNominalsOfContinuousStates(self._c, x, nx), "fmi3GetNominalsOfContinuousStates")

    def _set_time(self, t):
        self._cb(self.fmu.dll.fmi3SetTime(self._c, t), "fmi3SetTime")

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


def make_slave(name: str, info: FMUInfo, interface: str = "auto", rtol: float = 1e-6) -> Slave:
    """The wrapper for ``info``'s FMI version and the requested interface (auto: co-simulation first)."""
    available = info.interfaces
    if interface == "auto":
        interface = "cs" if "cs" in available else "me"
    if interface not in available:
        raise ComponentSourceError(Issue(f"components.{name}.interface",
                                         f"{info.path.name} has no {interface} interface (it has: "
                                         f"{', '.join(available) or 'none'})"))
    cls = {(2, "cs"): FMI2CoSimulation, (2, "me"): FMI2ModelExchange,
           (3, "cs"): FMI3CoSimulation, (3, "me"): FMI3ModelExchange}.get((info.fmi_major, interface))
    if cls is None:
        raise ComponentSourceError(Issue(f"components.{name}", f"FMI {info.md.fmiVersion} is not supported "
                                                               "(FMI 2.0 and 3.0 are)"))
    slave = cls(name, info)
    if slave.model_exchange:
        slave.rtol = rtol
    return slave
