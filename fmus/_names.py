"""Variable-name helpers, unit definitions and the FMU state shared by the FMI 2 and FMI 3 layers (no exporter
imports)."""

from __future__ import annotations

import ctypes
import hashlib
import json
import math
import sys
import threading
from functools import cached_property
from pathlib import Path
from typing import Any, NoReturn
from urllib.parse import unquote, urlparse
from xml.etree.ElementTree import ParseError, iterparse

from delta.errors import DeltaError, ParameterError

__all__ = ["XYZ", "UNITS", "joint_names", "axis_names", "component", "compensate_exporter_refcount", "ValueAccess", "writer",
           "initial_knowns", "STATE_MAGIC", "STATE_FORMAT", "FmuStateError", "fmu_guid", "encode_state",
           "decode_state", "is_plain", "identical", "spare_wrapper_references", "StateAccess"]

XYZ = ("x", "y", "z")

# SI base-unit exponents of every unit used in the FMUs (FMI 2.0 UnitDefinitions).
UNITS: dict[str, dict[str, int]] = {
    "1": {},
    "s": {"s": 1},
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "rad": {"rad": 1},
    "rad/s": {"rad": 1, "s": -1},
    "rad/s2": {"rad": 1, "s": -2},
    "kg": {"kg": 1},
    "kg.m2": {"kg": 1, "m": 2},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "N/m": {"kg": 1, "s": -2},
    "N.s/m": {"kg": 1, "s": -1},
    "N.m/rad": {"kg": 1, "m": 2, "s": -2, "rad": -1},
    "N.m.s/rad": {"kg": 1, "m": 2, "s": -1, "rad": -1},
    "N.m/(rad.s)": {"kg": 1, "m": 2, "s": -3, "rad": -1},
    "N/(m.s)": {"kg": 1, "s": -3},
    "1/s": {"s": -1},
    "1/s2": {"s": -2},
    "1/s3": {"s": -3},
}


def initial_knowns(depends, inputs, parameters) -> set:
    """What an InitialUnknown depends on (FMI 2.0 2.2.8, FMI 3.0 2.4.8), from the knowns ``depends`` it
    depends on in a step (inputs, and states for model exchange): in initialization mode the knowns are
    the inputs and the variables with initial="exact", here the ``parameters``, which also fix the
    initial states. So: the inputs among ``depends`` plus every parameter (parameters are not tracked
    per unknown, an over-approximation the standard allows). The one rule of every build (python FMI 2
    and 3, native): an InitialUnknown written without ``dependencies`` depends on every known, every
    input included, and an importer that sorts initialization by these (OMSimulator) then sees an
    algebraic loop through each feedback connection (plant q -> controller u -> plant u)."""
    return {d for d in depends if d in inputs} | set(parameters)


def joint_names(prefix: str) -> list[str]:
    """``prefix[1] prefix[2] prefix[3]`` (conventions.md: 1-based joint indices)."""
    return [f"{prefix}[{i}]" for i in (1, 2, 3)]


def axis_names(prefix: str) -> list[str]:
    """``prefix.x prefix.y prefix.z``."""
    return [f"{prefix}.{a}" for a in XYZ]


def component(name: str, index: int) -> str:
    """Which element of a vector variable ``name`` is, for its description: the axis of ``prefix.x`` (``x``), else
    the leg of element ``index`` (0-based: ``leg 1``)."""
    return name.rsplit(".", 1)[-1] if name.endswith(XYZ) and "." in name else f"leg {index + 1}"


def writer(*groups):
    """A function ``write(values, seq_1, ..., seq_n)`` storing ``seq_i[j]`` under ``groups[i][j]``.

    The per-step stores of the adapters (fmi2SetReal, refreshed outputs) as one compiled
    unpacking assignment per group: about half the time of ``values.update(zip(...))``,
    and a sequence of the wrong length raises ``ValueError``. The names are written into
    the generated source with ``repr``, so any string is safe.
    """
    groups = [tuple(g) for g in groups]
    if not groups or not all(groups) or not all(isinstance(n, str) for g in groups for n in g):
        raise ValueError(f"writer needs non-empty groups of variable names, got {groups!r}")
    args = [f"s{i}" for i in range(len(groups))]
    lines = [f"    {', '.join(f'values[{n!r}]' for n in g)}, = {a}" for g, a in zip(groups, args)]
    namespace: dict = {}
    exec(f"def write(values, {', '.join(args)}):\n" + "\n".join(lines) + "\n", namespace)  # noqa: S102
    return namespace["write"]


def compensate_exporter_refcount(slave_class: type) -> None:
    """Give back the reference pythonfmu's loader takes from the slave module's globals.

    pythonfmu 0.7 (and pythonfmu3) look the slave class up with a C++ ``findClass``
    that calls ``Py_DECREF`` on the module's ``__dict__``, a *borrowed* reference,
    once per instantiation, before the instance exists. Our generated slave modules
    hold no functions (whose ``__globals__`` would keep extra references), so the
    dict would be freed during the first lookup and its memory reused: a second
    instance in the same process then fails with "module has no attribute" or the
    interpreter crashes during garbage collection. The generated module keeps one
    spare reference to its globals (``fmus.builder``) and every instance gives back
    the one the lookup took; a leaked reference when an adapter is created outside
    the C++ loader (builder, direct use) is harmless.
    """
    module = sys.modules.get(slave_class.__module__)
    if module is not None:
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(vars(module)))


class ValueAccess:
    """Vector access to an adapter's ``values`` dict, shared by the FMI 2 and FMI 3 bases."""

    values: dict

    def vec(self, names):
        """Values of ``names`` as a float array."""
        import numpy as np

        return np.array([self.values[n] for n in names], dtype=float)

    def vec3(self, names) -> tuple[float, float, float]:
        """Values of three ``names`` as a tuple of floats (the per-step path; :meth:`vec` gives arrays)."""
        a, b, c = names
        v = self.values
        return v[a], v[b], v[c]

    def put(self, names, values) -> None:
        """Store ``values`` (floats, a tuple or an array) under ``names``; an array goes through one
        ``tolist`` instead of a ``float()`` per numpy scalar."""
        if hasattr(values, "tolist"):
            values = values.tolist()
        self.values.update(zip(names, map(float, values)))


# ----------------------------------------------------------------------------- FMU state

STATE_MAGIC = b"delta-cosim FMU state\n"
"""First line of a serialized FMU state (:func:`encode_state`)."""

STATE_FORMAT = 1
"""Version of the serialized layout; a state of another version is refused."""


class FmuStateError(DeltaError, ValueError):
    """An FMU state was refused (another FMU's or build's, damaged bytes) or could not be taken or set; the message
    says which FMU, which guids and why."""


def fmu_guid(resources: str | None, fallback: str) -> str:
    """The guid (FMI 2.0) or instantiationToken (FMI 3.0) of the FMU whose ``resources`` folder an instance was given.

    The exporter writes a new guid into modelDescription.xml at every build and hands the running instance only
    its resources folder (pythonfmu and pythonfmu3 pass neither the guid nor the token on), so it is read from the
    modelDescription.xml beside that folder, once per instance. ``resources`` is the path the wrapper passes (a
    ``file:`` URI is accepted too); ``fallback`` when there is no such file (an adapter made in Python, not by an
    FMU's binary)."""
    for folder in _resource_folders(resources):
        token = _description_token(folder.parent / "modelDescription.xml")
        if token:
            return token
    return fallback


def _resource_folders(resources: str | None) -> list[Path]:
    if not resources:
        return []
    text = str(resources)
    if text.startswith("file:"):
        text = urlparse(text).path
    return [Path(text), Path(unquote(text))]


def _description_token(path: Path) -> str | None:
    """The root element's ``guid`` / ``instantiationToken`` (only the root's start tag is parsed), or None."""
    if not path.is_file():
        return None
    try:
        for _, root in iterparse(str(path), events=("start",)):
            return root.get("guid") or root.get("instantiationToken")
    except (OSError, ParseError):
        return None
    return None


def encode_state(state: dict) -> bytes:
    """The bytes of an FMU state: a versioned, self-describing text of plain values, never pickle (a checkpoint
    file is user input, and unpickling runs code).

    Layout: the line ``delta-cosim FMU state``; a one-line JSON header ``{"format", "fmu", "guid", "sha256"}``
    (the FMU's name and its guid / instantiationToken); the body, one JSON document (the state, see
    :class:`StateAccess`). ``sha256`` is the hex SHA-256 of the header without it (sorted keys) + newline + body,
    so any byte changed after the first line is detected. Floats are written with Python's ``repr``, which reads
    back to the same double; non-finite ones as ``{"$float": "nan" | "inf" | "-inf"}`` (JSON has no NaN).
    Never raises (pythonfmu calls it on the class, where an exception would release the calling instance): a
    state that cannot be written becomes one that is refused when read back, saying why."""
    try:
        return _encode(state)
    except Exception as exc:  # noqa: BLE001 - see the docstring
        return _encode({"refused": f"the FMU state could not be serialized: {type(exc).__name__}: {exc}"})


def _encode(state: dict) -> bytes:
    header = {"format": state.get("format", STATE_FORMAT), "fmu": state.get("fmu"), "guid": state.get("guid")}
    body = json.dumps(_to_json({k: v for k, v in state.items() if k not in header}), separators=(",", ":"),
                      allow_nan=False).encode()
    header["sha256"] = _digest(header, body)
    return STATE_MAGIC + json.dumps(header, sort_keys=True, separators=(",", ":")).encode() + b"\n" + body


def decode_state(data: bytes) -> dict:
    """The FMU state of :func:`encode_state` bytes; bytes that are not one (no magic, another format version, a
    checksum that does not match: truncated, padded or corrupted) give ``{"refused": reason}``, which
    :meth:`StateAccess._set_fmu_state` refuses with that reason. Never raises (see :func:`encode_state`); whose state
    it is (its guid) is checked when it is set, where the instance is known."""
    try:
        return _decode(bytes(data))
    except Exception as exc:  # noqa: BLE001 - a checkpoint is user input
        return {"refused": f"unreadable FMU state ({len(data)} bytes): {type(exc).__name__}: {exc}"}


def _decode(data: bytes) -> dict:
    if not data.startswith(STATE_MAGIC):
        return {"refused": f"not a delta-cosim FMU state: it starts with {data[:len(STATE_MAGIC)]!r}, "
                           f"expected {STATE_MAGIC!r}"}
    head, newline, body = data[len(STATE_MAGIC):].partition(b"\n")
    if not newline:
        return {"refused": f"truncated: {len(data)} bytes end inside the header"}
    header = json.loads(head)
    if not isinstance(header, dict):
        return {"refused": "damaged: the header is not a JSON object"}
    version = header.get("format")
    if version != STATE_FORMAT:
        return {"refused": f"format version {version!r}; this FMU reads format version {STATE_FORMAT}"}
    digest = header.pop("sha256", None)
    if digest != _digest(header, body):
        return {"refused": f"checksum mismatch: the {len(data)} bytes are truncated, padded or corrupted"}
    document = json.loads(body, object_hook=_from_json)
    if not isinstance(document, dict):
        return {"refused": "damaged: the body is not a JSON object"}
    return {**document, "format": version, "fmu": header.get("fmu"), "guid": header.get("guid")}


def _digest(header: dict, body: bytes) -> str:
    return hashlib.sha256(json.dumps(header, sort_keys=True, separators=(",", ":")).encode() + b"\n" + body).hexdigest()


_NON_FINITE = {"nan": float("nan"), "inf": float("inf"), "-inf": float("-inf")}


def _to_json(value):  # noqa: ANN001, ANN202
    """``value`` with its non-finite floats as ``{"$float": name}``."""
    if isinstance(value, float):
        if value - value == 0.0:  # finite
            return value
        return {"$float": "nan" if value != value else ("inf" if value > 0 else "-inf")}
    if isinstance(value, dict):
        return {k: _to_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_to_json(v) for v in value]
    return value


def _from_json(obj: dict):  # noqa: ANN202
    if len(obj) == 1 and "$float" in obj:
        return _NON_FINITE[obj["$float"]]
    return obj


def is_plain(value) -> bool:  # noqa: ANN001
    """Whether ``value`` is plain data an FMU state may hold: None, bool, int, float, str, and lists and
    str-keyed dicts of them (no numpy, no tuples, no objects)."""
    if value is None or type(value) in (bool, int, float, str):
        return True
    if type(value) is list:
        return all(is_plain(v) for v in value)
    if type(value) is dict:
        return all(type(k) is str and is_plain(v) for k, v in value.items())
    return False


def identical(a, b) -> bool:  # noqa: ANN001
    """Whether two variable values are the same, bit for bit (-0.0 is not 0.0, NaN is NaN, 1 is not 1.0)."""
    if type(a) is not type(b):
        return False
    if type(a) is not float:
        return a == b
    if a == b:
        return a != 0.0 or math.copysign(1.0, a) == math.copysign(1.0, b)
    return a != a and b != b


def spare_wrapper_references(instance) -> None:  # noqa: ANN001
    """Before an exception leaves a method that pythonfmu's (or pythonfmu3's) binary called on ``instance``.

    The binary turns any Python exception into fmi2Fatal / fmi3Fatal (it has no other failing status for Python
    code: a refused state or parameter cannot be an fmi2Error) and on the way releases the three references it
    holds (``cleanPyObject``: the slave class, the instance, its log queue) without forgetting them; it releases
    them again when the instance is freed, so the instance would be freed under the host and the second release
    would crash it. One more reference to each, taken here, keeps the counts right: the instance stays valid, and
    freeing it later releases it once. Only for an instance the binary made (``StateAccess._hosted``): one made
    in Python would be kept alive by these references."""
    for obj in (type(instance), instance, instance.log_queue):
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(obj))


_THREAD = threading.local()


def hold_thread_state() -> None:
    """Keep this OS thread's Python thread state for good, the first time one of our FMUs is entered on it.

    FMI lets a host call an instance from any thread, one call at a time (libcosim steps every FMU in its worker
    threads, not the thread that loaded it). On a thread Python did not start, pythonfmu's binary takes a Python
    thread state for each FMI call (``PyGILState_Ensure``) and deletes it when the call returns. Exudyn calls our
    solver callbacks (the plant's ``FinishStep``, the restored Newton matrix) through pybind11, which on such a
    thread then took the GIL under a thread state other than the one the thread already held it with, and waited
    for itself for ever (gdb: ``PyEval_AcquireThread`` in ``pybind11::gil_scoped_acquire`` inside
    ``SolveSteps``; libcosim's main thread waiting in ``fixed_step_algorithm``). One more ``PyGILState_Ensure``,
    never released, keeps the thread's state alive across calls, as a thread Python started has it: every call
    and every callback on the thread then runs under the one state. A thread-local marker lives in that state, so
    a new thread that reuses an old thread's id is held again. Costs one attribute read per call once held."""
    if getattr(_THREAD, "held", False):
        return
    ctypes.pythonapi.PyGILState_Ensure()
    _THREAD.held = True


class StateAccess:
    """FMU state (get, set, free, serialize, deserialize) for the FMI 2 and FMI 3 layers, through pythonfmu's hooks:
    the binary calls ``_get_fmu_state`` and ``_set_fmu_state`` on the instance, frees a state by releasing the
    object, and calls ``_fmu_state_to_bytes`` / ``_fmu_state_from_bytes`` on the class.

    A state is a dict of plain data (:func:`is_plain`): ``format``, ``fmu`` (the model name), ``guid`` (this
    build's, :func:`fmu_guid`) and ``state``: the simulation ``time``, every variable's value (``values``:
    parameters, inputs, outputs as last computed), the layer's ``flags`` (outputs stale, core objects built,
    initialized, failed) and, when the core objects are built, the adapter's ``internal`` state
    (:meth:`internal_state`: integrators, a PID's integral, held references; the Exudyn plant's whole solver state).
    Everything that determines later outputs is in it, so stepping on from a restored state repeats the original
    bit for bit. Setting a state refuses (an FMI fatal status with the reason logged, the instance unharmed: see
    :func:`spare_wrapper_references`) one that is not this build's (its guid), damaged bytes
    (:func:`decode_state`), or something else; it rebuilds the core objects only when a fixed parameter differs
    (:meth:`retune` when only tunable ones do) and otherwise restores them in place.

    The layer provides ``values``, ``time``, ``_built``, ``_initialized``, ``_hosted`` (the binary made the
    instance), ``_parameters`` (names), ``_fixed`` (the fixed ones), ``_flags`` / ``_restore_flags``, ``start``
    and ``log`` with ``_STATUS_ERROR``.
    """

    _STATUS_ERROR: Any = None

    # -- per adapter
    def internal_state(self) -> dict:
        """The core objects' state that the variable values do not hold, as fresh plain data (:func:`is_plain`);
        called only when they are built."""
        return {}

    def restore_internal(self, state: dict) -> None:
        """Put back :meth:`internal_state` into core objects built from the same parameter values."""

    def retune(self, names: tuple[str, ...]) -> None:
        """Tunable parameters ``names`` changed after initialization (values already stored): make the core objects
        follow them, keeping the motion state. Default: nothing (the adapter reads them when it computes)."""

    def _broken(self, reason: str) -> None:
        """Setting a state failed half way (the layer refuses to continue if it can)."""

    # -- pythonfmu's hooks
    @cached_property
    def fmu_guid(self) -> str:
        """This build's guid / instantiationToken (:func:`fmu_guid`)."""
        return fmu_guid(getattr(self, "resources", None), f"unbuilt:{type(self).__module__}.{type(self).__qualname__}")

    def _get_fmu_state(self) -> dict:
        hold_thread_state()
        try:
            snapshot = {"time": self.time, "values": dict(self.values), "flags": self._flags(),
                        "internal": self.internal_state() if self._built else None}
        except Exception as exc:  # noqa: BLE001 - reported through the FMI logger (a fatal status, see _raise)
            self._raise(FmuStateError(f"{self.modelName} at t = {self.time!r} s: the FMU state could not be taken: "
                                      f"{type(exc).__name__}: {exc}"))
        return {"format": STATE_FORMAT, "fmu": self.modelName, "guid": self.fmu_guid, "state": snapshot}

    def _set_fmu_state(self, state) -> None:  # noqa: ANN001
        hold_thread_state()
        reason = self._refusal(state)
        if reason is not None:
            self._raise(FmuStateError(f"{self.modelName} at t = {self.time!r} s: FMU state refused: {reason}"))
        try:
            self._restore(state["state"])
        except Exception as exc:  # noqa: BLE001 - reported through the FMI logger
            reason = (f"{self.modelName}: setting the FMU state of t = {state['state']['time']!r} s failed, the "
                      f"instance is in an undefined state: {type(exc).__name__}: {exc}")
            self._broken(reason)
            self._raise(FmuStateError(reason))

    _fmu_state_to_bytes = staticmethod(encode_state)
    _fmu_state_from_bytes = staticmethod(decode_state)

    # -- helpers
    def _refusal(self, state) -> str | None:  # noqa: ANN001
        """Why ``state`` cannot be set into this instance, or None."""
        if type(state) is not dict:
            return f"not an FMU state of this FMU but a {type(state).__name__}"
        if "refused" in state:
            return str(state["refused"])
        if state.get("format") != STATE_FORMAT:
            return f"format version {state.get('format')!r}; this FMU reads format version {STATE_FORMAT}"
        if state.get("guid") != self.fmu_guid:
            return (f"it is a state of FMU {state.get('fmu')!r} with guid {state.get('guid')}, this is FMU "
                    f"{self.modelName!r} with guid {self.fmu_guid}: a state fits only the build that took it")
        body = state.get("state")
        values = body.get("values") if type(body) is dict else None
        if type(values) is not dict or values.keys() != self.values.keys():
            return "damaged: its variables are not this FMU's"
        return None

    def _restore(self, state: dict) -> None:
        values = state["values"]
        was_built = self._built
        changed = tuple(n for n in self._parameters if not identical(values[n], self.values[n]))
        self.values.update(values)
        self.time = state["time"]
        flags = state["flags"]
        if flags["built"]:
            if not was_built or not self._fixed.isdisjoint(changed):
                self.start()  # the core objects of the state's parameters, at its time
                self.values.update(values)  # start() may have stored initial outputs or states
            elif changed:
                self.retune(changed)
            self.restore_internal(state["internal"])
        self._restore_flags(flags)

    def _refuse_fixed(self, names) -> None:  # noqa: ANN001
        """After initialization: refuse to set any fixed parameter among ``names`` (nothing is stored)."""
        fixed = [n for n in names if n in self._fixed]
        if fixed:
            tunable = sorted(set(self._parameters) - self._fixed)
            self._raise(ParameterError(
                f'{self.modelName} at t = {self.time!r} s: parameter "{fixed[0]}" is fixed: it cannot change after '
                f"initialization (tunable parameters: {', '.join(tunable) or 'none'})"))

    def _retune_changed(self, before: dict) -> None:
        """Parameters stored after initialization, ``before``: their previous values. Retune those that changed;
        if that fails (an invalid value: retune changes nothing then), put the old values back and refuse."""
        changed = tuple(n for n, old in before.items() if not identical(old, self.values[n]))
        if not changed or not self._built:
            return
        try:
            self.retune(changed)
        except Exception as exc:  # noqa: BLE001 - reported through the FMI logger
            self.values.update(before)
            self._raise(ParameterError(f"{self.modelName} at t = {self.time!r} s: {', '.join(changed)} refused, the "
                                       f"previous values are kept: {type(exc).__name__}: {exc}"))

    def _raise(self, exc: Exception) -> NoReturn:
        """Log ``exc`` (status error) and raise it, keeping the instance valid for the binary that called
        (:func:`spare_wrapper_references`)."""
        self.log(str(exc), self._STATUS_ERROR)
        if self._hosted:
            spare_wrapper_references(self)
        raise exc
