"""FMU access layer: the only module that calls fmpy.

One protocol, :class:`Slave`, over four wrappers: FMI 2.0 and 3.0, co-simulation
and model exchange. Model-exchange FMUs are integrated by the master as FMPy's and
OMSimulator's loops do it (one continuous integration across communication points,
re-started only after an event or an input change; time, state and step events;
event iteration; termination); the numerics live in :mod:`cosim.fmi.integrators`.

Every FMI 3.0 variable type is exchanged: Float32/64, Int8..UInt64, Boolean, String,
Binary, Enumeration, and arrays (buffers hold every element; ``Variable.shape`` gives the
dimensions, fixed or from structural parameters). Clocks are rejected when loading.

Every FMI status passes through :meth:`_Base._check` (the hot path calls the C functions
directly with pre-built ctypes buffers; a co-simulation FMU's Gauss-Seidel turn, set, doStep
and get, and a model-exchange FMU's right-hand side, set time, set states and get derivatives,
are one call each into :mod:`cosim.fmi.turn` where that helper can be built); a failure raises
:class:`~cosim.errors.FMIError` naming the component, the function, the simulation time and
the FMU's last log message.
An FMU that asks to end the simulation raises :class:`Terminated`, which the algorithm
turns into a normal end of the run.
"""

from __future__ import annotations

import ast
import atexit
import ctypes
import itertools
import math
import os
import re
import shutil
import tempfile
import threading
import weakref
from collections import deque
from contextvars import ContextVar
from ctypes import byref, c_double, c_int32, c_int64, c_size_t, c_uint32
from dataclasses import dataclass, replace
from functools import cached_property, partial
from pathlib import Path
from typing import Any, Callable, Iterable, Protocol, Sequence

from fmus.requirements import release_pythonfmu_state

from ..errors import ComponentSourceError, FMIError, Issue, ScenarioError, printable
from .turn import DERIVATIVES, GET, SET, STATES, STEP, TIME, Exchange, Finite, make_rhs, make_turn

isfinite = math.isfinite  # a module global: one lookup less per output buffer in the hot path

__all__ = ["Variable", "FMUInfo", "load_fmu", "Slave", "make_slave", "Terminated", "cleanup_extracted", "Extractions",
           "REAL", "INTEGER", "BOOLEAN", "STRING", "BINARY"]

REAL, INTEGER, BOOLEAN, STRING, BINARY, CLOCK = "Real", "Integer", "Boolean", "String", "Binary", "Clock"
# declared FMI 2.0 / 3.0 types mapped onto the kinds the master exchanges (connections need equal kinds)
_KIND = {"Real": REAL, "Float64": REAL, "Float32": REAL,
         "Integer": INTEGER, "Enumeration": INTEGER, "Int8": INTEGER, "Int16": INTEGER, "Int32": INTEGER,
         "Int64": INTEGER, "UInt8": INTEGER, "UInt16": INTEGER, "UInt32": INTEGER, "UInt64": INTEGER,
         "Boolean": BOOLEAN, "String": STRING, "Binary": BINARY, "Clock": CLOCK}
# kinds whose values live in Python lists (copied through Python), not in ctypes arrays
PY_KINDS = (STRING, BINARY)


class Terminated(Exception):
    """An FMU ended the simulation (FMI: terminateSimulation / fmi2Terminated). Not an error.

    ``time`` is the time the FMU reached; its outputs are valid there.
    """

    def __init__(self, component: str, function: str, time: float):
        self.component = component
        self.function = function
        self.time = time
        super().__init__(f"component {component!r} ended the simulation at t = {time:.9g} s ({function})")


@dataclass(frozen=True)
class Variable:
    """A model variable as the master sees it."""

    name: str
    vr: int
    kind: str  # REAL, INTEGER, BOOLEAN, STRING or BINARY
    fmi_type: str  # the type as declared (Real, Float64, Int32, Enumeration, ...)
    causality: str
    variability: str
    unit: str | None
    description: str | None
    start: Any
    index: int  # 1-based position in ModelVariables (FMI 2.0 ModelStructure indices)
    shape: tuple[int, ...] = ()  # FMI 3.0 array dimensions; () for a scalar
    dims: tuple[tuple[int | None, int | None], ...] = ()  # per dimension: (fixed size, structural parameter vr)
    initial: str | None = None
    min: str | None = None
    max: str | None = None

    @property
    def count(self) -> int:
        """Number of elements (1 for a scalar)."""
        return math.prod(self.shape) if self.shape else 1

    @property
    def is_array(self) -> bool:
        return bool(self.dims)


@dataclass
class FMUInfo:
    """A parsed FMU: model description, variables, interfaces, feedthrough.

    The archive is extracted (into a temporary directory) only when an instance needs its
    binaries (:attr:`unzipdir`), and removed at the end of the run (:class:`Extractions`).
    """

    path: Path
    md: Any  # fmpy.model_description.ModelDescription
    variables: dict[str, Variable]
    stamp: tuple[int, ...] = ()  # the file as read (:func:`_stamp`): a rebuilt file is another extraction

    @property
    def unzipdir(self) -> Path:
        """The extracted archive (extracted at first use, shared by every copy of this info)."""
        return _extract((self.path, self.stamp))

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
        import zipfile

        with zipfile.ZipFile(self.path) as z:
            return z.read("modelDescription.xml")

    def structural_parameters(self) -> dict[str, Variable]:
        return {n: v for n, v in self.variables.items() if v.causality == "structuralParameter"}

    def with_structure(self, values: dict[str, Any]) -> "FMUInfo":
        """A copy whose array shapes follow the structural parameter values ``values`` (name -> value)."""
        by_vr = {v.vr: int(values[n]) if n in values else _scalar_start(v)
                 for n, v in self.structural_parameters().items()}
        variables = {n: replace(v, shape=_shape(v.dims, by_vr, n)) if v.dims else v
                     for n, v in self.variables.items()}
        return FMUInfo(self.path, self.md, variables, self.stamp)


def _scalar_start(v: Variable) -> int:
    try:
        return int(str(v.start).split()[0])
    except (ValueError, IndexError):
        raise ComponentSourceError(Issue("", f"structural parameter {v.name} has no usable start value "
                                             f"({v.start!r})")) from None


def _shape(dims, by_vr: dict[int, int], name: str) -> tuple[int, ...]:
    shape = []
    for size, vr in dims:
        if size is None:
            if vr not in by_vr:
                raise ComponentSourceError(Issue("", f"{name}: dimension refers to value reference {vr}, "
                                                     "which is not a structural parameter"))
            size = by_vr[vr]
        shape.append(int(size))
    return tuple(shape)


Key = tuple  # (resolved FMU path, its stamp): one extraction per file as it was read
_CACHE: dict[Path, FMUInfo] = {}  # resolved path -> its description, read from the file of info.stamp
_EXTRACTED: dict[Key, Path] = {}  # FMU file -> its extraction directory
_USERS: dict[Key, int] = {}  # FMU file -> how many running runs hold its extraction
_LOCK = threading.RLock()  # _EXTRACTED, _USERS and library loading: runs may run in threads of one process


def _fresh_lock() -> None:
    """In a forked child: a new lock. The parent's may have been held by another thread at the
    fork, and that thread does not exist in the child (an offload worker would wait for ever)."""
    global _LOCK
    _LOCK = threading.RLock()


if hasattr(os, "register_at_fork"):  # POSIX
    os.register_at_fork(after_in_child=_fresh_lock)


def _stamp(st: os.stat_result) -> tuple[int, ...]:
    """What tells one build of a file from the next at the same path: inode, size, mtime and ctime
    (a copy that keeps the mtime still changes the ctime)."""
    return st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns
# Callbacks and library handles handed to FMUs live as long as the process: an FMU may call its
# logger while being freed, and pythonfmu libraries must not be unloaded (GC of their objects crashes).
_KEEP_ALIVE: list[Any] = []

# PythonFMU's native wrapper (pythonfmu 0.7.0 and pythonfmu3 0.3.4, PySlaveInstance.cpp) keeps a
# global std::shared_ptr<PyState>: made by the first fmiXInstantiate, reset by the exported
# finalizePythonInterpreter(), which the library's __attribute__((destructor)) also calls. A
# library still loaded when the process exits (the first pythonfmu library a process loads
# stays: its STB_GNU_UNIQUE symbols make it NODELETE, so fmpy's dlclose in freeInstance leaves
# it) is torn down in the wrong order: exit() runs the pointer's static destructor (it frees the
# 128-byte control block), then _dl_fini runs that destructor function, whose reset decrements
# the use count inside the freed block (``lock xadd`` at offset 8; valgrind: "Invalid read of
# size 4 at finalizePythonInterpreter ... inside a block of size 128 free'd"). In a chunk of
# glibc's unsorted bin that word is the low half of its bk pointer, so the next free or malloc
# that walks the bin aborts: "corrupted double-linked list", "free(): corrupted unsorted chunks".
# Resetting the state ourselves while the library is loaded (pythonfmu makes it again at the
# next instantiation) leaves both destructors an empty pointer: no write to freed memory.
_PYTHONFMU_LIBRARIES: set[str] = set()  # file names of the PythonFMU libraries this process instantiated


def _release_pythonfmu_libraries() -> None:
    """At interpreter exit (before ``exit`` runs the libraries' destructors): the PythonFMU libraries
    still loaded, e.g. the process's first one or one whose instance was never freed."""
    for name in sorted(_PYTHONFMU_LIBRARIES):
        release_pythonfmu_state(name)


atexit.register(_release_pythonfmu_libraries)

# FMI 2.0 loggers are variadic; fmpy formats the message in a native proxy that keeps *one* global
# target (the logger of the instance created last), so every instance gets the same dispatcher and
# is told apart by the componentEnvironment it was instantiated with.
_FMI2_LOG_TARGETS: weakref.WeakValueDictionary[int, "_Base"] = weakref.WeakValueDictionary()
_FMI2_ENVIRONMENTS = itertools.count(1)
_FMI2_LOGGER: Any = None


def _fmi2_logger() -> Any:
    global _FMI2_LOGGER
    if _FMI2_LOGGER is None:
        from fmpy.fmi2 import fmi2CallbackLoggerTYPE

        def dispatch(env, instance, status, category, message):  # noqa: ANN001, ANN202
            slave = _FMI2_LOG_TARGETS.get(env or 0)
            if slave is not None:
                slave._on_log(status, category, message)

        _FMI2_LOGGER = fmi2CallbackLoggerTYPE(dispatch)
    return _FMI2_LOGGER


# pythonfmu / pythonfmu3 report a Python exception as this text and the exception's repr
_PY_EXCEPTION = re.compile(r"Fatal py exception encountered: \[[^\]]*\][^\n]*\n(?P<repr>.*)", re.S)
_REPR = re.compile(r"(?P<type>[A-Za-z_][\w.]*)\((?P<args>.*)\)", re.S)


def log_text(message: str) -> str:
    """An FMU's log message as shown to the user: a Python exception reported by pythonfmu as
    ``Fatal py exception encountered: [where] ...\\nType('text')`` becomes ``Type: text``."""
    m = _PY_EXCEPTION.match(message)
    if m is None:
        return message
    rep = m["repr"].strip()
    r = _REPR.fullmatch(rep)
    if r is not None:
        try:
            args = ast.literal_eval(f"({r['args']},)") if r["args"].strip() else ()
        except (ValueError, SyntaxError):
            return rep
        if len(args) == 1 and isinstance(args[0], str):
            return f"{r['type']}: {args[0]}"
        if not args:
            return r["type"]
    return rep


MAX_FMU_BYTES = 4 * 1024 ** 3
"""What an FMU archive may unpack to, all members together (ours are under 100 kB, the Exudyn plant's a few MB)."""
MAX_DESCRIPTION_BYTES = 64 * 1024 ** 2
"""What its modelDescription.xml may unpack to."""


def check_archive(path: Path) -> None:
    """Refuse an FMU archive whose members unpack past :data:`MAX_FMU_BYTES` (or whose modelDescription.xml
    does past :data:`MAX_DESCRIPTION_BYTES`) before anything is read or extracted: a zip bomb. Python's zip
    reader reads no member past its declared size, so the declared sizes bound what is written."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as zf:
            members = zf.infolist()
    except (zipfile.BadZipFile, OSError) as exc:
        raise ComponentSourceError(Issue("", f"{path}: not an FMU (a zip archive): {exc}")) from None
    total = sum(m.file_size for m in members)
    description = sum(m.file_size for m in members if m.filename == "modelDescription.xml")
    if total > MAX_FMU_BYTES or description > MAX_DESCRIPTION_BYTES:
        raise ComponentSourceError(Issue("", f"{path}: unpacks to {total:,} bytes (modelDescription.xml "
                                             f"{description:,}); at most {MAX_FMU_BYTES:,} "
                                             f"({MAX_DESCRIPTION_BYTES:,}) are accepted: refused"))


def load_fmu(path: str | Path) -> FMUInfo:
    """Read the model description (once per path and process); nothing is extracted yet."""
    import fmpy

    path = Path(path).resolve()
    try:
        st = path.stat()
    except OSError:
        raise ComponentSourceError(Issue("", f"FMU not found: {path}")) from None
    stamp = _stamp(st)
    cached = _CACHE.get(path)
    if cached is not None:
        if cached.stamp == stamp:
            return cached
        _forget_extractions(path)  # the file was rebuilt in place: its old extractions are stale
    if path.is_file():
        check_archive(path)
    try:
        md = fmpy.read_model_description(str(path), validate=False)
    except Exception as exc:  # fmpy raises bare Exception for malformed files
        raise ComponentSourceError(Issue("", f"{path}: cannot read modelDescription.xml: {exc}")) from None
    clocks = [v for v in md.modelVariables if v.type == "Clock"]
    if clocks:
        names = ", ".join(f"{v.name} (vr {v.valueReference})" for v in clocks[:5])
        raise ComponentSourceError(Issue("", f"{path.name} declares Clock variables ({names}): clocks (FMI 3.0 "
                                             "scheduled execution and synchronous clocks) are not supported"))
    variables = {}
    for i, v in enumerate(md.modelVariables, start=1):
        dims = tuple((int(d.start) if d.start is not None else None, d.valueReference) for d in v.dimensions)
        variables[v.name] = Variable(
            name=v.name, vr=v.valueReference, kind=_KIND.get(v.type, v.type), fmi_type=v.type,
            causality=v.causality, variability=v.variability, unit=_unit(v), description=v.description,
            start=v.start, index=i, shape=tuple(v.shape or ()) if dims else (), dims=dims, initial=v.initial,
            min=_attr(v, "min"), max=_attr(v, "max"))
    info = FMUInfo(path, md, variables, stamp)
    _CACHE[path] = info
    return info


_PREFIX = "cosim-fmu-"  # extraction directories: cosim-fmu-<pid>-<FMU stem>-<random>
SSP_PREFIX = "cosim-ssp-"  # unpacked SSP archives (cosim.io.ssp.open_ssp): cosim-ssp-<pid>-<archive stem>-<random>


def sweep_orphans() -> None:
    """Remove extraction directories and unpacked archives left by processes that no longer exist (killed with
    SIGKILL, which no handler can catch). A directory whose process is alive, or not ours to see, stays."""
    for prefix in (_PREFIX, SSP_PREFIX):
        for d in Path(tempfile.gettempdir()).glob(prefix + "*"):
            try:
                pid = int(d.name[len(prefix):].split("-", 1)[0])
                os.kill(pid, 0)
            except ProcessLookupError:
                shutil.rmtree(d, ignore_errors=True)
            except (ValueError, PermissionError, OSError):
                continue


class Extractions:
    """The FMU extractions one run uses, so that runs in threads of one process share them safely.

    ``with Extractions() as held:`` makes ``held`` the current run's (a context variable: each thread
    has its own); every extraction the run asks for is then held until ``held.release()``, which
    removes each one that no other running run holds. Extractions made outside a run stay until
    :func:`cleanup_extracted` (at the latest at interpreter exit).
    """

    def __init__(self) -> None:
        self.keys: set[Key] = set()
        self._token = None

    def __enter__(self) -> "Extractions":
        self._token = _RUN.set(self)
        return self

    def __exit__(self, *exc: Any) -> None:
        _RUN.reset(self._token)

    def hold(self, key: Key) -> None:
        if key not in self.keys:
            self.keys.add(key)
            _USERS[key] = _USERS.get(key, 0) + 1

    def release(self) -> None:
        """Let go of this run's extractions (any thread: the watchdog's shutdown calls it too)."""
        with _LOCK:
            for key in self.keys:
                users = _USERS.pop(key, 1) - 1
                if users > 0:
                    _USERS[key] = users
                elif key in _EXTRACTED:
                    shutil.rmtree(_EXTRACTED.pop(key), ignore_errors=True)
            self.keys.clear()


_RUN: ContextVar[Extractions | None] = ContextVar("cosim_run_extractions", default=None)


def _extract(key: Key) -> Path:
    """The extraction directory of the FMU file ``key`` = (path, stamp), held by the current run."""
    import fmpy

    path = key[0]
    with _LOCK:
        held = _RUN.get()
        unzipdir = _EXTRACTED.get(key)
        if unzipdir is None:
            if not _EXTRACTED:
                sweep_orphans()
            unzipdir = Path(tempfile.mkdtemp(prefix=f"{_PREFIX}{os.getpid()}-{path.stem}-"))
            try:
                fmpy.extract(str(path), str(unzipdir))
            except Exception as exc:  # a corrupt archive  # noqa: BLE001
                shutil.rmtree(unzipdir, ignore_errors=True)
                raise ComponentSourceError(Issue("", f"{path}: cannot extract: {exc}")) from None
            _EXTRACTED[key] = unzipdir
        if held is not None:
            held.hold(key)
        return unzipdir


def _forget_extractions(path: Path) -> None:
    """Remove the extractions of earlier builds of ``path`` that no running run holds (a run that
    holds one removes it at its end)."""
    with _LOCK:
        for key in [k for k in _EXTRACTED if k[0] == path and not _USERS.get(k)]:
            shutil.rmtree(_EXTRACTED.pop(key), ignore_errors=True)


def _unit(v: Any) -> str | None:
    if getattr(v, "unit", None):
        return v.unit
    dt = getattr(v, "declaredType", None)
    return getattr(dt, "unit", None) if dt is not None else None


def _attr(v: Any, name: str) -> str | None:
    value = getattr(v, name, None)
    if value is None and getattr(v, "declaredType", None) is not None:
        value = getattr(v.declaredType, name, None)
    return None if value is None else str(value)


def cleanup_extracted(keep: Iterable[Key] = ()) -> None:
    """Remove every extracted FMU directory of the process but those of the FMU files in ``keep``
    (keys of ``_EXTRACTED``).

    Called at interpreter exit, when a worker process ends and when the watchdog leaves the process
    (a run releases its own through :class:`Extractions`). A forked worker process keeps its parent's
    extractions (``keep``): they are still in use. Libraries already loaded stay loaded (Linux keeps
    a removed file's mapping).
    """
    keep = set(keep)
    with _LOCK:
        for key in [k for k in _EXTRACTED if k not in keep]:
            _USERS.pop(key, None)
            shutil.rmtree(_EXTRACTED.pop(key), ignore_errors=True)


atexit.register(cleanup_extracted)


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
    def set_step_get(self, t: float, h: float) -> None: ...  # set_inputs, step, get_outputs
    def terminate(self) -> None: ...
    def free(self) -> None: ...


class _Buffers:
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
        self.call: Callable[[], int] | None = None  # the bound Set/Get of the whole buffer (_Base._bound)
        self.function = ""  # its FMI name, for errors

    def snapshot(self) -> bytes | list:
        return list(self.values) if self.ctype_free else bytes(self.values)


def _status_ok(exchange: Callable[[_Buffers], None], b: _Buffers) -> int:
    """``exchange(b)`` (a String or Binary exchange through fmpy, which raises on a failing status) as a call
    returning a status like the bound C calls: OK."""
    exchange(b)
    return 0


def _number(kind: str, value: Any) -> Any:
    if kind == REAL:
        return float(value)
    if kind == BOOLEAN:
        return bool(value)
    return int(value)


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
        self._finite: list[memoryview] = []  # the real output buffers' values (bind)
        self._finite_bufs: list[_Buffers] = []  # their buffers
        self._set_calls: list | None = None
        self._get_calls: list | None = None
        self.fmu: Any = None
        self._instantiated = False
        self._terminated = False
        self._fatal = False  # after fmi2Fatal/fmi3Fatal no FMI function may be called, freeInstance included
        self._error_log: tuple[float, str] | None = None  # (time, text) of the last error-status log message

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
        text = printable(log_text((message or b"").decode("utf-8", "replace").strip()))
        if text:
            self.log.append(text)
            if status is not None and status >= 3:  # error, fatal
                self._error_log = (self.time, text)

    def _error_logged_at(self, t: float) -> bool:
        """Whether the FMU logged an error-status message while at time ``t`` (e.g. during a step from t)."""
        return self._error_log is not None and self._error_log[0] == t

    # -- start values (parameters), before initialization
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

    def _load_library(self) -> Any:
        """fmpy's FMU object with the library loaded.

        fmpy changes the process's working directory to the library's folder around the load, for
        Windows, where a DLL's dependencies are looked up there; it does not change back when the
        load fails. In a process where other threads run (runs in threads, a Dask worker) that would
        move their relative paths into the FMU's folder. On POSIX systems, where ``dlopen`` does not
        look in the working directory, the loading thread's ``chdir`` calls are skipped; elsewhere
        the directory is restored when the load fails. Loads are serialised.
        """
        with _LOCK:
            cwd, chdir, loader = os.getcwd(), os.chdir, threading.get_ident()
            if os.name == "posix":
                def skip_for_loader(path: Any) -> None:
                    if threading.get_ident() != loader:  # another thread's chdir is its own business
                        chdir(path)
                os.chdir = skip_for_loader
            try:
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
        process exits (see :func:`fmus.requirements.release_pythonfmu_state`)."""
        if self._pythonfmu:
            _PYTHONFMU_LIBRARIES.add(self.fmu.dll._name)

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

    # -- the per-step exchange: numbers through bound C calls, strings and binaries through fmpy
    def set_inputs(self) -> None:
        calls = self._set_calls
        if calls is None:
            calls = self._set_calls = self._exchange_calls(self.in_bufs, "Set")
        for call, function in calls:
            status = call()
            if status > 1:
                self._check(status, function)

    def _set_buffers(self, bufs: list[_Buffers]) -> None:
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

    def _exchange_calls(self, bufs: list[_Buffers], direction: str) -> list[tuple[Callable[[], int], str]]:
        """(call, FMI function name) per buffer of ``bufs``, in the order the exchange makes them: the numeric
        buffers through their bound C calls, then strings and binaries through fmpy (a call returning OK:
        fmpy raises on a failing status, which :meth:`_guard` translates)."""
        text = self._set_text if direction == "Set" else self._get_text
        text_calls = [(partial(_status_ok, text, b), self._exchange_name(direction, b)) for b in bufs if b.ctype_free]
        return [(b.call, b.function) for b in self._bound(bufs, direction)] + text_calls

    def _set_text(self, b: _Buffers) -> None:
        """Set a String or Binary input buffer (through fmpy)."""
        raise NotImplementedError

    def _get_text(self, b: _Buffers) -> None:
        """Read a String or Binary output buffer into ``b.values`` (through fmpy)."""
        raise NotImplementedError

    def _bound(self, bufs: list[_Buffers], direction: str) -> list[_Buffers]:
        """The numeric buffers of ``bufs``, each with its ``fmiXSet``/``fmiXGet`` call (``direction``) bound."""
        numeric = [b for b in bufs if not b.ctype_free]
        for b in numeric:
            if b.call is None:
                b.function = self._exchange_name(direction, b)
                b.call = self._bound_call(self.fmu.dll, b.function, *self._exchange_args(b))
        return numeric

    def _exchange_name(self, direction: str, b: _Buffers) -> str:
        raise NotImplementedError

    def _exchange_args(self, b: _Buffers) -> tuple:
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


# --------------------------------------------------------------------------- model exchange


class _MEMixin:
    """Model exchange: the master's own integration loop around an FMU in continuous-time mode.

    As FMPy's ``simulateME`` and OMSimulator do it: one integration across communication
    points, the FMU's time set to the time the integrator reached, time events
    (``nextEventTime``), state events (event indicators, located by the integrator's root
    finding), step events (``completedIntegratorStep``), event iteration until no new
    discrete states are needed, and ``terminateSimulation`` honoured. The integrator is
    re-started only after an event or when an input changed value (a discrete input change
    is an event: the FMU gets it in event mode).
    """

    rtol = 1e-6
    max_step = math.inf
    solver = "cvode"
    model_exchange = True
    _update_name = ""
    events = 0  # events handled (the initial event iteration excluded)
    next_event: float | None = None
    event_log: list[tuple[float, str]]  # (time, kind: state/time/step/input) not yet taken by an observer
    _continuous = False  # in continuous-time mode (after the initial event iteration)
    _c_rhs: Callable[[Any, Any], int] | None = None  # the C right-hand side (None: the Python calls)
    _rhs_state: Any = None  # its cosim.fmi.turn.Rhs

    # -- the integrator's view (cosim.fmi.integrators.OdeModel): a failing status raises FMIError,
    #    which the integrator re-raises from advance()
    def rhs(self, t, x, dx):
        """The derivatives ``dx`` at time ``t`` and states ``x`` (``c_double`` arrays or pointers of ``nx``
        values): :meth:`set_time`, :meth:`set_x`, :meth:`get_dx`, in one C call where the helper of
        :mod:`cosim.fmi.turn` is available, raising as those do."""
        c_rhs = self._c_rhs
        if c_rhs is None:
            self.set_time(t)
            self.set_x(x)
            self.get_dx(dx)
            return
        self.time = t
        self._rhs_t.value = t
        ended = c_rhs(x, dx)
        if ended:
            self._rhs_ended(ended, dx)

    def _rhs_ended(self, ended: int, dx) -> None:
        """Raise for the call that ended a C right-hand side, as the same call made from Python raises."""
        status = self._rhs_state.status
        if ended == TIME:
            self._check(status, self._name_set_time)
        if ended == STATES:
            self._check(status, self._name_set_x)
        if ended == DERIVATIVES:
            self._check(status, self._name_get_dx)
        self._non_finite_dx(dx)  # NONFINITE

    def _bind_rhs(self) -> None:
        """After initialization (``nx`` known): the C right-hand side, where the helper is available."""
        dll = self.fmu.dll

        def address(name: str) -> int:
            return ctypes.cast(getattr(dll, name), ctypes.c_void_p).value

        self._rhs_t = c_double()
        made = make_rhs(self._c, address(self._name_set_time), address(self._name_set_x),
                        address(self._name_get_dx), self.nx, self._rhs_t, lambda f: self._prototype(f, None))
        self._c_rhs, self._rhs_state = made if made is not None else (None, None)

    def set_time(self, t):
        self.time = t
        status = self._fn_set_time(self._c, t)
        if status > 1:
            self._check(status, self._name_set_time)

    def get_x(self, x):
        status = self._fn_get_x(self._c, x, self.nx)
        if status > 1:
            self._check(status, self._name_get_x)

    def set_x(self, x):
        status = self._fn_set_x(self._c, x, self.nx)
        if status > 1:
            self._check(status, self._name_set_x)

    def get_dx(self, dx):
        status = self._fn_get_dx(self._c, dx, self.nx)
        if status > 1:
            self._check(status, self._name_get_dx)
        # NaN or inf in any element, one sum per call; dx may be a bare pointer (CVode's): slice it
        if not isfinite(sum(dx[: self.nx])):
            self._non_finite_dx(dx)

    def _non_finite_dx(self, dx) -> None:
        """Derivatives that are not finite: integrating them would only fail later and nameless (an
        FMU may also report a failure so, with the reason logged: our pythonfmu3 adapters do). The sum of
        finite values overflows only near 1e308; then every element is looked at and nothing is raised."""
        names = [d.variable.name for d in self.info.md.derivatives]
        bad = [f"{names[i] if i < len(names) else f'derivative {i + 1}'} = {dx[i]!r}"
               for i in range(self.nx) if not isfinite(dx[i])]
        if not bad:
            return
        detail = self._error_log[1] if self._error_logged_at(self.time) else "non-finite " + ", ".join(bad)
        raise FMIError(self.name, self._name_get_dx, self.time, None, detail)

    def get_z(self, z):
        status = self._fn_get_z(self._c, z, self.nz)
        if status > 1:
            self._check(status, self._name_get_z)

    def get_nominals(self, x):
        status = self._fn_get_nom(self._c, x, self.nx)
        if status > 1:
            self._check(status, self._name_get_nom)

    def _bind_me(self, prefix: str, derivatives: str) -> None:
        dll = self.fmu.dll
        fn = self._hot_function
        self._name_get_x, self._name_set_x = f"{prefix}GetContinuousStates", f"{prefix}SetContinuousStates"
        self._name_get_dx, self._name_get_z = f"{prefix}{derivatives}", f"{prefix}GetEventIndicators"
        self._name_get_nom, self._name_set_time = f"{prefix}GetNominalsOfContinuousStates", f"{prefix}SetTime"
        self._fn_get_x, self._fn_set_x = fn(dll, self._name_get_x), fn(dll, self._name_set_x)
        self._fn_get_dx, self._fn_get_z = fn(dll, self._name_get_dx), fn(dll, self._name_get_z)
        self._fn_get_nom, self._fn_set_time = fn(dll, self._name_get_nom), fn(dll, self._name_set_time)

    # -- events
    def _event_iteration(self) -> bool:
        """Update discrete states until none is needed; True when continuous states or nominals changed."""
        changed = False
        while True:
            need, terminate, nominals, values, defined, t_next = self._update_discrete()
            changed |= bool(values or nominals)
            self.next_event = t_next if defined else None
            if terminate:
                raise Terminated(self.name, self._update_name, self.time)
            if not need:
                return changed

    def _handle_event(self, kinds: str) -> None:
        self._enter_event_mode()
        self.events += 1
        self.event_log.append((self.time, kinds))
        self._event_iteration()
        self._enter_continuous_mode()
        self.integrator.reset(self.time)

    def exit_initialization(self) -> None:
        from .integrators import make_integrator

        self._exit_init()
        self.event_log = []
        self._continuous = False
        self._event_iteration()  # the initial event iteration (FMI 2: after exitInitializationMode)
        self._enter_continuous_mode()
        self._continuous = True
        for b in self.in_bufs:
            b.applied = b.snapshot()
        self._restart = False
        self._bind_rhs()
        self.integrator = make_integrator(self.solver, self, self.time, self.rtol, self.max_step)

    def set_inputs(self) -> None:
        if not self._continuous:
            super().set_inputs()  # initialization mode: plain setting
            return
        changed = [b for b in self.in_bufs if b.snapshot() != b.applied]
        if not changed:
            return
        discrete = any(v.variability != "continuous" for b in changed for v in b.variables)
        if discrete:  # FMI: discrete inputs change in event mode only, and that is an event
            self._enter_event_mode()
            self._set_buffers(changed)
            self.events += 1
            self.event_log.append((self.time, "input"))
            self._event_iteration()
            self._enter_continuous_mode()
        else:
            self._set_buffers(changed)
        for b in changed:
            b.applied = b.snapshot()
        self._restart = True

    MAX_EVENTS_AT_ONE_TIME = 1000  # event iterations at one instant before the FMU is called stuck

    def step(self, t: float, h: float) -> None:
        t_end = t + h
        integ = self.integrator
        tol = 100.0 * 2.220446049250313e-16 * max(1.0, abs(t_end))  # times closer than this coincide
        if self._restart or abs(self.time - t) > tol:
            self.time = t
            integ.reset(t)
            self._restart = False
        completed = self._needs_completed
        same_instant = 0
        while True:
            t_next = self.next_event
            time_event = t_next is not None and t_next <= self.time + tol
            state_event = False
            if not time_event:
                if self.time >= t_end - tol:
                    break
                t_stop = t_end if t_next is None or t_next >= t_end - tol else t_next
                try:
                    t_reached, state_event = integ.advance(t_stop)
                except (FMIError, Terminated):
                    raise
                except Exception as exc:  # the integrator gave up
                    raise FMIError(self.name, f"{self.solver} integration", self.time, None, str(exc)) from None
                same_instant = 0
                time_event = t_next is not None and t_reached >= t_next - tol
            step_event = False
            if completed:
                step_event, terminate = self._completed_step()
                if terminate:
                    raise Terminated(self.name, self._completed_name, self.time)
            if state_event or time_event or step_event:
                same_instant += 1
                if same_instant > self.MAX_EVENTS_AT_ONE_TIME:
                    raise FMIError(self.name, self._update_name, self.time, None,
                                   f"{self.MAX_EVENTS_AT_ONE_TIME} events at the same time: nextEventTime "
                                   "does not advance")
                self._handle_event("+".join(k for k, on in (("state", state_event), ("time", time_event),
                                                            ("step", step_event)) if on))
        self.time = t_end


# --------------------------------------------------------------------------- co-simulation


class _CoSimulation:
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

            def exchanges(bufs: list[_Buffers]) -> list[Exchange]:
                return [Exchange(ctypes.cast(getattr(dll, b.function), ctypes.c_void_p).value,
                                 ctypes.addressof(b.vrs), b.n, ctypes.addressof(b.values), b.size) for b in bufs]

            do_step = ctypes.cast(getattr(dll, f"fmi{self.fmi}DoStep"), ctypes.c_void_p).value
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


# --------------------------------------------------------------------------- FMI 2.0


class _FMI2(_Base):
    fmi = 2

    def _ctype(self, kind: str, fmi_type: str) -> Any:
        return {REAL: c_double, INTEGER: c_int32, BOOLEAN: c_int32}.get(kind)

    def _group(self, variables: Iterable[Variable]) -> list[_Buffers]:
        by_kind: dict[str, list[Variable]] = {}
        for v in variables:
            by_kind.setdefault(v.kind, []).append(v)
        return [_Buffers(k, vs[0].fmi_type, vs, self._ctype(k, vs[0].fmi_type)) for k, vs in by_kind.items()]

    def _make(self) -> Any:
        from fmpy.fmi2 import FMU2Model, FMU2Slave

        md = self.info.md
        cls, ident = (FMU2Model, md.modelExchange.modelIdentifier) if self.model_exchange else \
            (FMU2Slave, md.coSimulation.modelIdentifier)
        return cls(guid=md.guid, unzipDirectory=str(self.info.unzipdir), modelIdentifier=ident,
                   instanceName=self.name)

    def instantiate(self) -> None:
        from fmpy import calloc, free
        from fmpy.fmi2 import (
            fmi2CallbackAllocateMemoryTYPE,
            fmi2CallbackFreeMemoryTYPE,
            fmi2CallbackFunctions,
        )
        from fmpy.logging import addLoggerProxy

        self.fmu = self._load_library()
        self._note_library()
        cb = fmi2CallbackFunctions()
        environment = next(_FMI2_ENVIRONMENTS)
        _FMI2_LOG_TARGETS[environment] = self
        cb.logger = _fmi2_logger()
        cb.componentEnvironment = environment
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(byref(cb))
        self._callbacks = cb
        _KEEP_ALIVE.append((cb, self.fmu))
        self._guard("fmi2Instantiate", self.fmu.instantiate, False, cb, True)
        self._instantiated = True
        self._c = self.fmu.component

    def _set_values(self, var: Variable, values: list[Any], what: str) -> None:
        kind = var.kind
        fn = {REAL: self.fmu.setReal, INTEGER: self.fmu.setInteger, BOOLEAN: self.fmu.setBoolean,
              STRING: self.fmu.setString}[kind]
        values = [str(v) for v in values] if kind == STRING else [_number(kind, v) for v in values]
        self._guard(f"fmi2Set{kind} ({what})", fn, [var.vr], values)

    def enter_initialization(self, start: float, stop: float) -> None:
        self.time = start
        self._guard("fmi2SetupExperiment", self.fmu.setupExperiment, None, start, stop)
        self._guard("fmi2EnterInitializationMode", self.fmu.enterInitializationMode)

    def _exchange_name(self, direction: str, b: _Buffers) -> str:
        return f"fmi2{direction}{b.kind}"

    def _exchange_args(self, b: _Buffers) -> tuple:
        return self._c, b.vrs, b.n, b.values

    def _set_text(self, b: _Buffers) -> None:
        self._guard("fmi2SetString", self.fmu.setString, list(b.vrs), [str(s) for s in b.values])

    def _get_text(self, b: _Buffers) -> None:
        got = self._guard("fmi2GetString", self.fmu.getString, list(b.vrs))
        b.values[:] = [(s or b"").decode("utf-8", "replace") if isinstance(s, bytes) else (s or "") for s in got]



class FMI2CoSimulation(_CoSimulation, _FMI2):
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
        from fmpy.fmi2 import fmi2LastSuccessfulTime, fmi2Terminated

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


class FMI2ModelExchange(_MEMixin, _FMI2):
    """FMI 2.0 model exchange, integrated by the master (see :class:`_MEMixin`)."""

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


# --------------------------------------------------------------------------- FMI 3.0

_CTYPE3 = {"Float64": c_double, "Float32": ctypes.c_float, "Int8": ctypes.c_int8, "Int16": ctypes.c_int16,
           "Int32": c_int32, "Int64": c_int64, "UInt8": ctypes.c_uint8, "UInt16": ctypes.c_uint16,
           "UInt32": c_uint32, "UInt64": ctypes.c_uint64, "Boolean": ctypes.c_bool, "Enumeration": c_int64}
# FMI 3.0 accessor per declared type (Enumeration values travel as Int64)
_ACCESSOR3 = {**{t: t for t in _CTYPE3}, "Enumeration": "Int64", "String": "String", "Binary": "Binary"}


class _FMI3(_Base):
    fmi = 3

    def _group(self, variables: Iterable[Variable]) -> list[_Buffers]:
        # FMI 3.0 getters are per declared type, so group by accessor (kind kept for conversions)
        by_type: dict[str, list[Variable]] = {}
        for v in variables:
            by_type.setdefault(_ACCESSOR3[v.fmi_type], []).append(v)
        return [_Buffers(vs[0].kind, t, vs, _CTYPE3.get(t)) for t, vs in by_type.items()]

    def _make(self) -> Any:
        from fmpy.fmi3 import FMU3Model, FMU3Slave

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
        _KEEP_ALIVE.append((logger, self.fmu))
        what = "fmi3InstantiateModelExchange" if self.model_exchange else "fmi3InstantiateCoSimulation"
        # loggingOn: pythonfmu3 (like pythonfmu) reports the exceptions of its Python code only then
        self._guard(what, lambda: self.fmu.instantiate(loggingOn=True, logMessage=logger))
        self._instantiated = True
        self._c = self.fmu.component

    def _exchange_name(self, direction: str, b: _Buffers) -> str:
        return f"fmi3{direction}{b.fmi_type}"

    def _exchange_args(self, b: _Buffers) -> tuple:
        return self._c, b.vrs, b.n, b.values, b.size

    def _set_values(self, var: Variable, values: list[Any], what: str) -> None:
        t = _ACCESSOR3[var.fmi_type]
        if var.kind == STRING:
            values = [str(v) for v in values]
        elif var.kind == BINARY:
            values = [_binary(v, var.name) for v in values]
        else:
            values = [_number(var.kind, v) for v in values]
        self._guard(f"fmi3Set{t} ({what})", self._py_set, t, [var.vr], values)

    def _py_set(self, accessor: str, vrs: list[int], values: list[Any]) -> None:
        """fmi3Set<accessor> for any element count (fmpy's setters pass nValues = len(values))."""
        getattr(self.fmu, f"set{accessor}")(vrs, values)

    def enter_initialization(self, start: float, stop: float) -> None:
        self.time = start
        self._guard("fmi3EnterInitializationMode", self.fmu.enterInitializationMode, None, start, stop)

    def _set_text(self, b: _Buffers) -> None:
        self._guard(f"fmi3Set{b.fmi_type}", self._py_set, b.fmi_type, list(b.vrs), list(b.values))

    def _get_text(self, b: _Buffers) -> None:
        """Strings and binaries: copied out of the FMU's memory (valid only until its next call)."""
        c = self._c
        if b.kind == STRING:
            raw = (ctypes.c_char_p * b.size)()
            self._check(self.fmu.dll.fmi3GetString(c, b.vrs, b.n, raw, b.size), "fmi3GetString")
            b.values[:] = [(s or b"").decode("utf-8", "replace") for s in raw]
        else:
            from fmpy.fmi3 import fmi3Binary

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
        raise ScenarioError(f"{name}: a Binary value is given as hexadecimal digits, got {value!r}") from None


class FMI3CoSimulation(_CoSimulation, _FMI3):
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


class FMI3ModelExchange(_MEMixin, _FMI3):
    """FMI 3.0 model exchange, integrated by the master (see :class:`_MEMixin`)."""

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


def make_slave(name: str, info: FMUInfo, interface: str = "auto", rtol: float = 1e-6, solver: str = "cvode",
               max_step: float | None = None) -> Slave:
    """The wrapper for ``info``'s FMI version and the requested interface (auto: co-simulation first).

    ``rtol``, ``solver`` and ``max_step`` (s; None: unbounded but for the communication step) apply
    to model exchange.
    """
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
        slave.solver = solver
        slave.max_step = math.inf if max_step is None else max_step
    return slave
