"""The :class:`Slave` protocol the algorithms call, and the machinery every wrapper shares: lifecycle through
fmpy, the hot path through the C functions, one status check; co-simulation stepping."""

from __future__ import annotations

import ctypes
import math
import os
import threading
from collections import deque
from ctypes import c_double, c_size_t, c_uint32
from functools import partial
from typing import Any, Callable, Protocol, Sequence

from ..errors import FMIError, printable
from . import extract
from .description import BINARY, BOOLEAN, REAL, FMUInfo, Variable
from .logger import CALLING, log_text
from .pythonfmu import PYTHONFMU_LIBRARIES, release_pythonfmu_state
from .turn import GET, SET, STEP, Exchange, Finite, make_turn

isfinite = math.isfinite  # a module global: one lookup less per output buffer in the hot path

_PRELOADED: dict[tuple, list[Any]] = {}
"""fmpy FMU objects made ahead by :func:`preload` (library loaded, functions bound, nothing instantiated), by
(wrapper class, extraction directory); each is taken by one instantiation, here or in a process forked since."""


def preload(slave: Any) -> None:
    """Load ``slave``'s library and bind its functions now, for the next instantiation of that FMU in this process
    or in a process forked from it (a sweep's workers and their cases' children: binding fmpy's functions took about
    3 ms an FMU, every case). Only for libraries that run no code of their own at load, such as our native FMUs:
    a crash there would take this process. :func:`drop_preloaded` lets go of those not taken."""
    with extract._LOCK:
        _PRELOADED.setdefault((type(slave), str(slave.info.unzipdir)), []).append(slave._make())


def drop_preloaded() -> None:
    with extract._LOCK:
        _PRELOADED.clear()


class Terminated(Exception):
    """An FMU ended the simulation (FMI: terminateSimulation / fmi2Terminated). Not an error.

    ``time`` is the time the FMU reached; its outputs are valid there.
    """

    def __init__(self, component: str, function: str, time: float):
        self.component = component
        self.function = function
        self.time = time
        super().__init__(f"component {component!r} ended the simulation at t = {time:.9g} s ({function})")


class ComponentState:
    """One component's saved state (libcosim's ``save_state``): the FMU's state handle (FMI 2.0 / 3.0 FMUstate),
    the time the component had reached, the master's copies of its exchanged values (input and output buffers)
    and what a wrapper keeps beside the FMU (:meth:`Base._extra_state`: a model-exchange wrapper's event
    bookkeeping). Reused by :meth:`Base.save_state` (``into``): the FMU overwrites the handle's state."""

    __slots__ = ("handle", "time", "buffers", "extra", "refresh")

    def __init__(self, handle: Any, time: float, buffers: list, extra: dict, refresh: bool = False):
        self.handle = handle
        self.time = time
        self.buffers = buffers
        self.extra = extra
        self.refresh = refresh  # outputs this system reads that the state does not hold: read from the FMU


class Slave(Protocol):
    """What the execution and its algorithms need from a component, whatever its FMI version and kind (the four
    wrappers here, and the offload's proxy of a component run by a worker process)."""

    name: str
    info: FMUInfo
    time: float  # s: the time the component reached (the watchdog names it)
    model_exchange: bool  # the master integrates it
    events: int  # model exchange: events handled (the initial event iteration excluded); else 0

    def locate(self, var: Variable, output: bool = True) -> tuple[Any, int]: ...  # (values array, index) of var

    # initialization, in this order (FMPy's and libcosim's): instantiate, setup_experiment (FMI 2's
    # fmi2SetupExperiment; nothing for the FMI versions that take the times at initialization), set_start,
    # enter_initialization (which gets the times again), exit_initialization
    def instantiate(self) -> None: ...
    def setup_experiment(self, start: float, stop: float) -> None: ...
    def set_start(self, values: dict[str, Any]) -> None: ...
    def enter_initialization(self, start: float, stop: float) -> None: ...
    def exit_initialization(self) -> None: ...
    def bind(self, inputs: list[Variable], outputs: list[Variable]) -> None: ...
    def set_inputs(self) -> None: ...
    def get_outputs(self) -> None: ...
    def step(self, t: float, h: float) -> None: ...
    def set_step_get(self, t: float, h: float) -> None: ...  # set_inputs, step, get_outputs
    def terminate(self) -> None: ...
    def free(self) -> None: ...

    # FMU state (FMI 2.0 / 3.0; libcosim's save_state / restore_state / export_state / import_state)
    can_save_state: bool
    can_serialize_state: bool
    def save_state(self, into: "ComponentState | None" = None) -> "ComponentState": ...
    def restore_state(self, state: "ComponentState") -> None: ...
    def free_state(self, state: "ComponentState") -> None: ...
    def export_state(self, state: "ComponentState") -> bytes: ...
    def exchanged(self, state: "ComponentState") -> dict[str, Any]: ...
    def import_state(self, data: bytes, time: float, exchanged: dict, extra: dict) -> "ComponentState": ...
    def set_values(self, values: dict[Variable, list]) -> None: ...  # an event's changes, between steps


class Buffers:
    """Value references and values of one kind (FMI 3.0: one declared type), every element.

    ``values`` is a ctypes array (numbers) or a Python list (String, Binary) of ``size``
    elements; variable ``variables[i]`` occupies ``values[offsets[i]:offsets[i] + count]``.
    """

    __slots__ = ("vrs", "values", "n", "size", "kind", "fmi_type", "variables", "offsets", "applied", "ctype_free",
                 "call", "function")

    def __init__(self, kind: str, fmi_type: str, variables: list[Variable], ctype: Any):
        self.kind = kind
        self.fmi_type = fmi_type
        self.variables = list(variables)
        self.n = len(variables)
        self.offsets = []
        size = 0
        for v in variables:
            self.offsets.append(size)
            size += v.count
        self.size = size
        self.vrs = (c_uint32 * self.n)(*[v.vr for v in variables])
        self.values = [b"" if kind == BINARY else ""] * size if ctype is None else (ctype * size)()
        self.ctype_free = ctype is None  # a Python list (strings, binaries), copied through Python
        self.applied: bytes | list | None = None  # model exchange: the values last set (change detection)
        self.call: Callable[[], int] | None = None  # the bound Set/Get of the whole buffer (Base._bound)
        self.function = ""  # its FMI name, for errors

    def snapshot(self) -> bytes | list:
        return list(self.values) if self.ctype_free else bytes(self.values)

    def restore(self, saved: bytes | list) -> None:
        """Put back the values of a :meth:`snapshot`."""
        if self.ctype_free:
            self.values[:] = saved
        else:
            ctypes.memmove(self.values, saved, len(saved))


def _status_ok(exchange: Callable[[Buffers], None], b: Buffers) -> int:
    """``exchange(b)`` (a String or Binary exchange through fmpy, which raises on a failing status) as a call
    returning a status like the bound C calls: OK."""
    exchange(b)
    return 0


def as_number(kind: str, value: Any) -> Any:
    if kind == REAL:
        return float(value)
    if kind == BOOLEAN:
        return bool(value)
    return int(value)


class Base:
    """Shared machinery: lifecycle through fmpy, hot path through the C functions, one status check."""

    fmi: int = 2
    model_exchange = False
    events = 0
    in_c_loop = False  # a loop in C (cosim.engine.cloop) runs this component's turns: self.time is not kept

    def __init__(self, name: str, info: FMUInfo):
        self.name = name
        self.info = info
        self.time = 0.0
        self.log: deque[str] = deque(maxlen=20)
        self.in_bufs: list[Buffers] = []
        self.out_bufs: list[Buffers] = []
        self._finite: list[memoryview] = []  # the real output buffers' values (bind)
        self._finite_bufs: list[Buffers] = []  # their buffers
        self._set_calls: list | None = None
        self._get_calls: list | None = None
        self.fmu: Any = None
        self._instantiated = False
        self._terminated = False
        self._fatal = False  # after fmi2Fatal/fmi3Fatal no FMI function may be called, freeInstance included
        self._error_log: tuple[float, str] | None = None  # (time, text) of the last error-status log message
        self._fast_get: tuple | None = None  # fmiXGetFMUstate bound for save_state

    # -- the one place where statuses are checked
    def _check(self, status: int, function: str) -> None:
        if status > 1:  # OK = 0, Warning = 1; Discard, Error, Fatal, Pending fail
            self._fatal = self._fatal or status == 4
            raise FMIError(self.name, function, self.time, status, self._last_log())

    def _last_log(self) -> str:
        return self.log[-1] if self.log else ""

    def _symbol(self, function: str) -> str:
        """The C name of FMI function ``function`` (``DoStep``: ``fmi2DoStep``; FMI 1.0 prefixes the model
        identifier)."""
        return f"fmi{self.fmi}{function}"

    def _guard(self, function: str, call, *args):
        """Lifecycle calls through fmpy (which raises on a failing status): translate to FMIError."""
        from fmpy.fmi1 import FMICallException  # lazy: --help loads this module without it

        before, CALLING.slave = getattr(CALLING, "slave", None), self  # a log without environment is this call's
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
        finally:
            CALLING.slave = before

    def _on_log(self, status: int, category: bytes | None, message: bytes | None) -> None:
        text = printable(log_text((message or b"").decode("utf-8", "replace").strip()))
        if text:
            self.log.append(text)
            if status is not None and status >= 3:  # error, fatal
                # in a loop in C (in_c_loop) only its turns call the FMU, each from the time in self._t
                self._error_log = (self._t.value if self.in_c_loop else self.time, text)

    def _error_logged_at(self, t: float) -> bool:
        """Whether the FMU logged an error-status message while at time ``t`` (e.g. during a step from t)."""
        return self._error_log is not None and self._error_log[0] == t

    def setup_experiment(self, start: float, stop: float) -> None:
        """Before the start values: FMI 2 sets up the experiment here (fmi2SetupExperiment); FMI 1.0 and 3.0
        take start and stop time when initialization begins (:meth:`enter_initialization`), so nothing here."""
        self.time = start

    # -- start values, after setup_experiment and before enter_initialization (as FMPy and libcosim set them)
    def set_start(self, values: dict[str, Any]) -> None:
        for name, value in values.items():
            var = self.info.variables[name]
            flat = list(value) if isinstance(value, (list, tuple)) else [value]
            if len(flat) != var.count:
                raise FMIError(self.name, f"set start value of {name}", self.time, None,
                               f"{len(flat)} value(s) given, {name} has {var.count} element(s)")
            self._set_values(var, flat, f"set start value of {name}")

    def bind(self, inputs: list[Variable], outputs: list[Variable]) -> None:
        """Pre-build buffers for the inputs the master sets and the outputs it reads."""
        self.in_bufs = self._group(inputs)
        self.out_bufs = self._group(outputs)
        self._set_calls = self._get_calls = None  # hot-path call lists, bound at first use
        # the real outputs as flat memoryviews of their buffers: one sum per buffer and step tells
        # whether a value is NaN or infinite (see _check_finite)
        self._finite_bufs = [b for b in self.out_bufs if b.kind == REAL and not b.ctype_free]
        self._finite = [memoryview(b.values).cast("B").cast("f" if b.fmi_type == "Float32" else "d")
                        for b in self._finite_bufs]

    def _check_finite(self) -> None:
        """Stop on a NaN or infinite output, naming component, variable and time. The sum of finite values
        overflows only near 1e308; then every element is looked at and nothing is raised."""
        for view, b in zip(self._finite, self._finite_bufs):
            if not isfinite(sum(view)):
                for v, offset in zip(b.variables, b.offsets):
                    for k in range(v.count):
                        x = b.values[offset + k]
                        if not isfinite(x):
                            name = v.name if v.count == 1 else f"{v.name} (element {k + 1})"
                            raise FMIError(self.name, f"fmi{self.fmi}Get{b.fmi_type}", self.time, None,
                                           f"non-finite output {name} = {x!r}")

    def locate(self, var: Variable, output: bool = True) -> tuple[Any, int]:
        """(values array, index of the first element) where ``var``'s value lives after bind()."""
        for b in (self.out_bufs if output else self.in_bufs):
            for v, offset in zip(b.variables, b.offsets):
                if v == var:
                    return b.values, offset
        raise KeyError(f"{self.name}.{var.name} is not bound as an {'output' if output else 'input'}")

    def terminate(self) -> None:
        if self._instantiated and not self._terminated and not self._fatal:
            self._terminated = True
            self._guard(f"fmi{self.fmi}Terminate", self.fmu.terminate)

    def free(self) -> None:
        if self.fmu is None:
            return
        try:
            if self._pythonfmu:  # while loaded: fmpy's freeInstance unloads it
                release_pythonfmu_state(self.fmu.dll._name)
            if self._instantiated and not self._fatal:
                self.fmu.freeInstance()
        finally:
            # the shared library stays loaded: unloading a pythonfmu library while the interpreter
            # still holds objects it created crashes at garbage collection
            self._instantiated = False
            self.fmu = None
            self._fast_get = None

    def _load_library(self) -> Any:
        """fmpy's FMU object with the library loaded.

        fmpy changes the process's working directory to the library's folder around the load, for
        Windows, where a DLL's dependencies are looked up there; it does not change back when the
        load fails. In a process where other threads run (runs in threads, a Dask worker) that would
        move their relative paths into the FMU's folder. On POSIX systems, where ``dlopen`` does not
        look in the working directory, the loading thread's ``chdir`` calls are skipped; elsewhere
        the directory is restored when the load fails. Loads are serialised.
        """
        with extract._LOCK:  # the module's: a forked child makes a new one
            cwd, chdir, loader = os.getcwd(), os.chdir, threading.get_ident()
            if os.name == "posix":
                def skip_for_loader(path: Any) -> None:
                    if threading.get_ident() != loader:  # another thread's chdir is its own business
                        chdir(path)
                os.chdir = skip_for_loader
            try:
                ahead = _PRELOADED.get((type(self), str(self.info.unzipdir)))
                if ahead:  # made by preload(): the same object _make makes, under another instance name
                    fmu = ahead.pop()
                    fmu.instanceName = self.name
                    return fmu
                return self._guard("load library", self._make)
            finally:
                if os.name == "posix":
                    os.chdir = chdir
                elif not os.path.samefile(os.getcwd(), cwd):  # pragma: no cover - Windows
                    os.chdir(cwd)

    @property
    def _pythonfmu(self) -> bool:
        """Whether PythonFMU exported this FMU (its binary runs Python in this process)."""
        return (self.info.md.generationTool or "").startswith("PythonFMU")

    def _note_library(self) -> None:
        """Remember a PythonFMU library, whose global state is reset before it is unloaded or the
        process exits (see :func:`cosim.fmi.pythonfmu.release_pythonfmu_state`)."""
        if self._pythonfmu:
            PYTHONFMU_LIBRARIES.add(self.fmu.dll._name)

    def _hot_function(self, dll: Any, name: str) -> Any:
        """The C function ``name`` for the per-step path.

        FMUs exported by PythonFMU run Python: each call takes the GIL back (PyGILState_Ensure)
        right after ctypes released it. For them the function is called through a PYFUNCTYPE
        prototype with the same signature, which keeps the GIL across the call and saves that
        round trip; any other FMU keeps ctypes' default (GIL released, so its own threads may
        call back into Python).
        """
        f = getattr(dll, name)
        return self._prototype(f, f.argtypes) if self._pythonfmu else f

    def _prototype(self, f: Any, argtypes: Sequence[Any] | None) -> Any:
        """``f`` through a prototype of its return type and ``argtypes`` (None: none declared): PYFUNCTYPE
        for a PythonFMU library (the GIL kept, see :meth:`_hot_function`), CFUNCTYPE for any other."""
        factory = ctypes.PYFUNCTYPE if self._pythonfmu else ctypes.CFUNCTYPE
        proto = factory(f.restype) if argtypes is None else factory(f.restype, *argtypes)
        return proto(ctypes.cast(f, ctypes.c_void_p).value)

    # -- FMU state: FMI 2.0 / 3.0 get, set, free, serialize (FMI 1.0 has none)
    def _capabilities(self) -> Any:
        md = self.info.md
        return md.modelExchange if self.model_exchange else md.coSimulation

    @property
    def can_save_state(self) -> bool:
        """The FMU declares ``canGetAndSetFMUstate`` (FMI 3.0: ``canGetAndSetFMUState``) for the interface in use."""
        kind = self._capabilities()
        return self.fmi >= 2 and kind is not None and bool(getattr(kind, "canGetAndSetFMUstate", False))

    @property
    def can_serialize_state(self) -> bool:
        """The FMU also declares ``canSerializeFMUstate`` (FMI 3.0: ``canSerializeFMUState``)."""
        kind = self._capabilities()
        return self.can_save_state and bool(getattr(kind, "canSerializeFMUstate", False))

    def _state_function(self, name: str) -> tuple[str, Any]:
        """(C name, fmpy's status-checked function) of FMU-state function ``name`` (``Get``, ``Set``, ``Free``)."""
        c_name = f"fmi2{name}FMUstate" if self.fmi == 2 else f"fmi3{name}FMUState"
        return c_name, getattr(self.fmu, c_name)

    def _require_state(self, what: str) -> None:
        if not self.can_save_state:
            raise FMIError(self.name, what, self.time, None, "the FMU does not declare canGetAndSetFMUstate: its "
                           "state cannot be saved or restored")

    def save_state(self, into: ComponentState | None = None) -> ComponentState:
        """The FMU's state now, with the master's copies of its exchanged values; ``into``: a saved state to
        overwrite (its FMU state handle reused, as FMI allows)."""
        c_name, get = self._state_function("Get")
        self._require_state(c_name)
        handle = into.handle if into is not None else ctypes.c_void_p()
        if self._pythonfmu and handle:  # PythonFMU's get makes a new state without freeing the one it is given
            self.free_state(into)
            handle = into.handle = ctypes.c_void_p()
        if self._fast_get is None:  # the C function called as the hot path calls: no conversions per call
            self._fast_get = (self._prototype(getattr(self.fmu.dll, c_name), None), ctypes.c_void_p(self._c))
        fn, instance = self._fast_get
        before, CALLING.slave = getattr(CALLING, "slave", None), self  # its log messages are this component's
        try:
            status = fn(instance, ctypes.byref(handle))
        finally:
            CALLING.slave = before
        if status > 1:
            self._check(status, c_name)
        buffers = [b.snapshot() for b in (*self.in_bufs, *self.out_bufs)]
        if into is None:
            return ComponentState(handle, self.time, buffers, self._extra_state())
        into.time, into.buffers, into.extra = self.time, buffers, self._extra_state()
        return into

    def restore_state(self, state: ComponentState) -> None:
        """Back to ``state``: the FMU's state, the time, the exchanged values, the wrapper's bookkeeping."""
        c_name, set_ = self._state_function("Set")
        self._require_state(c_name)
        self._guard(c_name, set_, self._c, state.handle)
        for b, saved in zip((*self.in_bufs, *self.out_bufs), state.buffers):
            b.restore(saved)
        self.time = state.time
        self._restore_extra(state.extra)
        if state.refresh:
            self.get_outputs()
            state.refresh = False

    def free_state(self, state: ComponentState) -> None:
        if self.fmu is None or self._fatal or not state.handle:
            return
        c_name, free = self._state_function("Free")
        self._guard(c_name, free, self._c, ctypes.byref(state.handle))

    def export_state(self, state: ComponentState) -> bytes:
        """The FMU's serialized state (fmi2SerializeFMUstate / fmi3SerializeFMUState)."""
        what = "fmi2SerializeFMUstate" if self.fmi == 2 else "fmi3SerializeFMUState"
        if not self.can_serialize_state:
            raise FMIError(self.name, what, self.time, None, "the FMU does not declare canSerializeFMUstate: its "
                           "state cannot be written to a checkpoint")
        serialize = self.fmu.serializeFMUstate if self.fmi == 2 else self.fmu.serializeFMUState
        return bytes(self._guard(what, serialize, state.handle))

    def exchanged(self, state: ComponentState) -> dict[str, Any]:
        """The exchanged values of ``state`` by variable (``in:NAME`` / ``out:NAME`` -> its bytes, or its list of
        strings or binaries): what a checkpoint keeps, independent of how this run grouped them into buffers."""
        out: dict[str, Any] = {}
        for prefix, bufs, saved in (("in", self.in_bufs, state.buffers[:len(self.in_bufs)]),
                                    ("out", self.out_bufs, state.buffers[len(self.in_bufs):])):
            for b, snap in zip(bufs, saved):
                size = 1 if b.ctype_free else ctypes.sizeof(b.values._type_)
                for v, offset in zip(b.variables, b.offsets):
                    out[f"{prefix}:{v.name}"] = snap[offset * size:(offset + v.count) * size]
        return out

    def import_state(self, data: bytes, time: float, exchanged: dict, extra: dict) -> ComponentState:
        """A state from :meth:`export_state` bytes (the FMU checks they are its own) and :meth:`exchanged` values.
        Outputs this system reads that ``exchanged`` lacks (a run that logs more than the one that saved) are read
        from the FMU once its state is restored."""
        what = "fmi2DeSerializeFMUstate" if self.fmi == 2 else "fmi3DeserializeFMUState"
        if not self.can_serialize_state:
            raise FMIError(self.name, what, self.time, None, "the FMU does not declare canSerializeFMUstate")
        buffers, refresh = [], False
        for prefix, bufs in (("in", self.in_bufs), ("out", self.out_bufs)):
            for b in bufs:
                snap = b.snapshot()
                size = 1 if b.ctype_free else ctypes.sizeof(b.values._type_)
                parts = []
                for v, offset in zip(b.variables, b.offsets):
                    value = exchanged.get(f"{prefix}:{v.name}")
                    expected = v.count * size
                    if value is None or len(value) != expected:
                        if prefix == "in" or value is not None:
                            raise FMIError(self.name, what, time, None, f"the checkpoint holds no value of "
                                           f"{prefix}put {v.name} of this system" if value is None else
                                           f"the checkpoint's {prefix}put {v.name} has {len(value)} bytes, this "
                                           f"system's {expected}")
                        refresh = True
                        value = snap[offset * size:(offset + v.count) * size]
                    parts.append(value)
                buffers.append(b"".join(parts) if not b.ctype_free else [x for p in parts for x in p])
        deserialize = self.fmu.deSerializeFMUstate if self.fmi == 2 else self.fmu.deserializeFMUState
        handle = self._guard(what, deserialize, bytes(data))
        return ComponentState(handle, time, buffers, extra, refresh)

    def _extra_state(self) -> dict:
        """What a wrapper keeps beside the FMU that a restored state needs (plain data: a checkpoint holds it)."""
        return {}

    def _restore_extra(self, extra: dict) -> None:
        """Put back :meth:`_extra_state`."""

    def set_values(self, values: dict[Variable, list]) -> None:
        """Set variables between two steps (an event's changes: inputs no connection drives, tunable parameters)."""
        for var, flat in values.items():
            self._set_values(var, flat, f"set {var.name} at an event")

    # -- the per-step exchange: numbers through bound C calls, strings and binaries through fmpy
    def set_inputs(self) -> None:
        calls = self._set_calls
        if calls is None:
            calls = self._set_calls = self._exchange_calls(self.in_bufs, "Set")
        for call, function in calls:
            status = call()
            if status > 1:
                self._check(status, function)

    def _set_buffers(self, bufs: list[Buffers]) -> None:
        """Set the given input buffers only (model exchange: what changed)."""
        for b in bufs:
            if b.ctype_free:
                self._set_text(b)
            else:
                if b.call is None:
                    self._bound([b], "Set")
                status = b.call()
                if status > 1:
                    self._check(status, b.function)

    def get_outputs(self) -> None:
        calls = self._get_calls
        if calls is None:
            calls = self._get_calls = self._exchange_calls(self.out_bufs, "Get")
        for call, function in calls:
            status = call()
            if status > 1:
                self._check(status, function)
        for view in self._finite:
            if not isfinite(sum(view)):
                self._check_finite()

    def set_step_get(self, t: float, h: float) -> None:
        """One Gauss-Seidel turn: :meth:`set_inputs`, :meth:`step` from ``t`` over ``h``, :meth:`get_outputs`.
        The co-simulation wrappers do the same in one method (no dispatch per part)."""
        self.set_inputs()
        self.step(t, h)
        self.get_outputs()

    def _exchange_calls(self, bufs: list[Buffers], direction: str) -> list[tuple[Callable[[], int], str]]:
        """(call, FMI function name) per buffer of ``bufs``, in the order the exchange makes them: the numeric
        buffers through their bound C calls, then strings and binaries through fmpy (a call returning OK:
        fmpy raises on a failing status, which :meth:`_guard` translates)."""
        text = self._set_text if direction == "Set" else self._get_text
        text_calls = [(partial(_status_ok, text, b), self._exchange_name(direction, b)) for b in bufs if b.ctype_free]
        return [(b.call, b.function) for b in self._bound(bufs, direction)] + text_calls

    def _set_text(self, b: Buffers) -> None:
        """Set a String or Binary input buffer (through fmpy)."""
        raise NotImplementedError

    def _get_text(self, b: Buffers) -> None:
        """Read a String or Binary output buffer into ``b.values`` (through fmpy)."""
        raise NotImplementedError

    def _bound(self, bufs: list[Buffers], direction: str) -> list[Buffers]:
        """The numeric buffers of ``bufs``, each with its ``fmiXSet``/``fmiXGet`` call (``direction``) bound."""
        numeric = [b for b in bufs if not b.ctype_free]
        for b in numeric:
            if b.call is None:
                b.function = self._exchange_name(direction, b)
                b.call = self._bound_call(self.fmu.dll, b.function, *self._exchange_args(b))
        return numeric

    def _exchange_name(self, direction: str, b: Buffers) -> str:
        raise NotImplementedError

    def _exchange_args(self, b: Buffers) -> tuple:
        raise NotImplementedError

    def _step_call(self, name: str, *flags: Any) -> Callable[[], int]:
        """The doStep function ``name`` as a call without arguments: instance, then the current time and step
        size read from ``self._t`` and ``self._h`` (``c_double`` s the step updates in place), then ``flags``
        (C values). Nothing is converted per call, as in :meth:`_bound_call`; an argument-typed call (fmpy's)
        converts each of them, about 0.4 us more per step."""
        self._t, self._h = c_double(), c_double()
        f = getattr(self.fmu.dll, name)
        return partial(self._prototype(f, None), ctypes.c_void_p(self._c), self._t, self._h, *flags)

    def _bound_call(self, dll: Any, name: str, *args: Any) -> Callable[[], int]:
        """``name(*args)`` as a call without arguments, for a per-step exchange whose arguments never
        change (instance, value references, counts and values are fixed buffers).

        The arguments are converted to C once (``c_void_p`` for the instance, ``c_size_t`` for counts,
        the ctypes arrays themselves, which the call keeps alive), and the prototype declares no
        argument types, so ctypes skips its ``from_param`` conversions on every call (0.36 us a call,
        measured on a GetReal of 9 values). GIL handling as in :meth:`_hot_function`.
        """
        c_args = [ctypes.c_void_p(a) if i == 0 else c_size_t(a) if isinstance(a, int) else a
                  for i, a in enumerate(args)]
        return partial(self._prototype(getattr(dll, name), None), *c_args)


# --------------------------------------------------------------------------- co-simulation


class CoSimulation:
    """Co-simulation (FMI 2.0 and 3.0): a Gauss-Seidel turn (set, doStep, get, NaN check) in one C call
    (:mod:`cosim.fmi.turn`) where the helper is available and the FMU exchanges numbers only."""

    _flags: list[Any] | None = None  # FMI 3.0 doStep's outputs
    _c_turn: Callable[[], int] | None = None  # the C turn, bound after initialization (None: none for this FMU)
    _turn_state: Any = None  # its cosim.fmi.turn.Turn

    def bind(self, inputs: list[Variable], outputs: list[Variable]) -> None:
        super().bind(inputs, outputs)
        self._c_turn = self._turn_state = None  # a C turn points into the buffers: one of these is bound after init

    def _bind_turn(self) -> None:
        """After initialization (``self._do_step`` bound): the per-step exchange calls and the turn."""
        if self._set_calls is None:
            self._set_calls = self._exchange_calls(self.in_bufs, "Set")
        if self._get_calls is None:
            self._get_calls = self._exchange_calls(self.out_bufs, "Get")
        made = None
        if not any(b.ctype_free for b in (*self.in_bufs, *self.out_bufs)):  # strings, binaries: through fmpy
            dll = self.fmu.dll

            def exchanges(bufs: list[Buffers]) -> list[Exchange]:
                return [Exchange(ctypes.cast(getattr(dll, b.function), ctypes.c_void_p).value,
                                 ctypes.addressof(b.vrs), b.n, ctypes.addressof(b.values), b.size) for b in bufs]

            do_step = ctypes.cast(getattr(dll, self._symbol("DoStep")), ctypes.c_void_p).value
            finite = [Finite(ctypes.addressof(b.values), b.size, b.fmi_type == "Float32")
                      for b in self._finite_bufs]
            made = make_turn(self.fmi, self._c, do_step, self._t, self._h, exchanges(self.in_bufs),
                             exchanges(self.out_bufs), finite, self._flags, lambda f: self._prototype(f, None))
        self._c_turn, self._turn_state = made if made is not None else (None, None)

    def set_step_get(self, t: float, h: float) -> None:
        self.time = t
        self._t.value = t
        self._h.value = h
        c_turn = self._c_turn
        if c_turn is not None:
            ended = c_turn()
            if ended:
                self._turn_ended(ended, t, h)
        else:
            self._turn_in_python(t, h)
        self.time = t + h

    def c_turn(self) -> tuple[Any, bool] | None:
        """For a loop in C (:mod:`cosim.engine.cloop`): this component's :class:`~cosim.fmi.turn.Turn` and whether
        its calls run Python (a PythonFMU: called with the Python lock held, as its turn is); None without one."""
        return None if self._c_turn is None else (self._turn_state, self._pythonfmu)

    def turn_failed(self, ended: int, t: float, h: float) -> None:
        """Raise for a C turn from ``t`` over ``h`` that a loop in C ran and that ``ended`` early (SET, STEP, GET
        or NONFINITE of :mod:`cosim.fmi.turn`), as :meth:`set_step_get` raises."""
        self.time = t
        self._turn_ended(ended, t, h)

    def _turn_in_python(self, t: float, h: float) -> None:
        """The C turn's calls made from Python one by one (no C turn for this FMU); raises where it ends."""
        for call, function in self._set_calls:
            status = call()
            if status > 1:
                self._check(status, function)
        status = self._do_step()
        flags = self._flags
        if status > 1 or flags is not None and flags[1].value:  # FMI 3.0: terminateSimulation
            self._step_failed(status, t, h)
        self.time = t + h
        self.get_outputs()

    def _turn_ended(self, ended: int, t: float, h: float) -> None:
        """Raise for the call that ended a C turn early, as the same call made from Python raises."""
        u = self._turn_state
        if ended == SET:
            self._check(u.status, self._set_calls[u.index][1])
        if ended == STEP:
            self._step_failed(u.status, t, h)
        self.time = t + h
        if ended == GET:
            self._check(u.status, self._get_calls[u.index][1])
        self._check_finite()  # NONFINITE
