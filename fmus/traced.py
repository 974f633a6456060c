"""The python build's step: what an FMU's native model computes, evaluated by CasADi's virtual machine.

One definition of each FMU of ours: its python adapter declares the interface (:mod:`fmus.adapters`), its native
model (:mod:`fmus.native.models`) says what each FMI call computes, as calls of the :mod:`delta` formulas. The native
build traces the model's functions on symbols and writes them as C (:mod:`fmus.native.generate`); the python build
takes the very same traced functions (:class:`TracedModel`: the generator's functions, with what depends on the
parameters alone hoisted into a constants function, as in the C) and evaluates them here, through CasADi's
numeric buffers (about 0.3 us of overhead a call), under a runtime that does what the C runtime does
(``fmus/native/c/runtime.c``): the start, the refresh of the outputs, the advance in substeps of at most the
model's ``max_step``, the checks (an error fails the call with its reason; a warning is logged when it starts
failing), the constants computed again when a parameter may have changed. Both builds are the same operations on
the same numbers.

A python FMU carries its traced model in its resources (:data:`FILE`, written by :mod:`fmus.builder`); an adapter
made in Python for its declarations (:meth:`fmus.definition.FmuDefinition.python_class`) traces it when it is first
started. This module imports CasADi when a traced model is first made or read, not before.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from delta.dynamics import substeps
from delta.errors import DeltaError

__all__ = ["FILE", "FORMAT", "CALLS", "ModelCheckError", "Call", "TracedModel", "Runtime", "TracedCS", "TracedME",
           "first_values", "load", "loader"]

FILE = "traced.json"
"""The traced model's file in a python FMU's ``resources/``."""
FORMAT = 1
CALLS = ("start", "refresh", "advance", "derivatives", "accept")


class ModelCheckError(DeltaError, ValueError):
    """An error check of the model failed: the message is its reason, as the native build logs it."""


@dataclass(frozen=True)
class Call:
    """One traced function: ``function(t, h, values, state, constants) -> (values set, new state, checks, check
    values)``; ``sets`` the value indices it writes (in its output order), ``checks`` (reason, is an error, number
    of values its reason prints), ``sets_state`` whether its new state is kept."""

    function: Any
    sets: tuple[int, ...]
    checks: tuple[tuple[str, bool, int], ...]
    sets_state: bool



def first_values(checks) -> list[int]:  # noqa: ANN001
    """Where each check's printed values begin among its function's check values (``checks``: (reason, is an error,
    number of values) each): the python runtime's and the generated C's (``first_value``) offsets."""
    out, at = [], 0
    for _, _, n in checks:
        out.append(at)
        at += n
    return out


@dataclass(frozen=True)
class TracedModel:
    """The traced functions of one FMU's native model and what the runtime needs around them, by value index
    (index 0 is the time): ``variables`` (name, type, start, choices of a String), the internal state's size and
    start, the index of the parameter that bounds one advance (0: none), the model-exchange flags of
    :class:`fmus.native.models.NativeModel`, the ``constants`` function (values -> what depends on parameters only)
    and the ``calls``."""

    name: str
    variables: tuple[tuple[str, str, float, tuple[str, ...]], ...]
    n_state: int
    initial_state: tuple[float, ...]
    max_step: int
    me_advances: bool
    me_accepts: bool
    me_outputs: bool
    constants: Any
    calls: dict[str, Call] = field(repr=False)

    def dumps(self) -> str:
        """The traced model as JSON (CasADi's own serialization of each function inside)."""
        return json.dumps({
            "format": FORMAT, "name": self.name, "variables": [list(v[:3]) + [list(v[3])] for v in self.variables],
            "n_state": self.n_state, "initial_state": list(self.initial_state), "max_step": self.max_step,
            "me": [self.me_advances, self.me_accepts, self.me_outputs], "constants": self.constants.serialize(),
            "calls": {k: {"function": c.function.serialize(), "sets": list(c.sets),
                          "checks": [list(x) for x in c.checks], "sets_state": c.sets_state}
                      for k, c in self.calls.items()}})

    @classmethod
    def loads(cls, text: str) -> TracedModel:
        import casadi as ca  # lazy: only a traced model's runtime evaluates with it

        data = json.loads(text)
        if data.get("format") != FORMAT:
            raise ModelCheckError(f"traced model of format {data.get('format')!r}; this runtime reads {FORMAT}")
        me = data["me"]
        return cls(data["name"], tuple((n, t, float(s), tuple(c)) for n, t, s, c in data["variables"]),
                   data["n_state"], tuple(data["initial_state"]), data["max_step"], *me,
                   ca.Function.deserialize(data["constants"]),
                   {k: Call(ca.Function.deserialize(c["function"]), tuple(c["sets"]),
                            tuple((r, bool(e), n) for r, e, n in c["checks"]), c["sets_state"])
                    for k, c in data["calls"].items()})


def load(resources: str | Path) -> TracedModel:
    """The traced model a python FMU carries in its ``resources`` folder."""
    return TracedModel.loads((Path(resources) / FILE).read_text())


def loader(resources: str | Path) -> Callable[[], TracedModel]:
    """A function giving the traced model of the FMU whose ``resources`` folder is given, read once (the
    ``TRACED`` of an FMU's generated module)."""
    read: list[TracedModel] = []

    def traced() -> TracedModel:
        if not read:
            read.append(load(resources))
        return read[0]
    return traced


class _Bound:
    """A call's CasADi function bound to the runtime's arrays (its numeric buffer): ``run()`` evaluates it."""

    def __init__(self, call: Call, t: np.ndarray, h: np.ndarray, values: np.ndarray, state: np.ndarray,
                 constants: np.ndarray) -> None:
        fn = call.function
        self.call = call
        self.out = np.zeros(max(fn.nnz_out(0), 1))
        self.new_state = np.zeros(max(fn.nnz_out(1), 1))
        self.ok = np.zeros(max(fn.nnz_out(2), 1))
        self.details = np.zeros(max(fn.nnz_out(3), 1))
        self.firsts = first_values(call.checks)
        self.sets = np.array(call.sets, dtype=np.intp)  # where the values it sets go
        self.buffer, self.run = fn.buffer()
        for i, a in enumerate((t, h, values, state, constants)):
            self.buffer.set_arg(i, memoryview(a))
        for i, a in enumerate((self.out, self.new_state, self.ok, self.details)):
            self.buffer.set_res(i, memoryview(a))


class Runtime:
    """One instance's evaluation of a :class:`TracedModel`: the values array (the C runtime's ``values``), the
    internal state, the constants and which check each function reported last (a warning is logged when its
    function did not report it on its last call, as ``check`` in the C runtime)."""

    def __init__(self, model: TracedModel, warn: Callable[[str], None]) -> None:
        self.model, self.warn = model, warn
        self.values = np.array([v[2] for v in model.variables], dtype=float)
        self.state = np.zeros(max(model.n_state, 1))
        self.state[:model.n_state] = model.initial_state
        self.constants = np.zeros(max(model.constants.nnz_out(0), 1))
        self.t, self.h = np.zeros(1), np.zeros(1)
        self._constants_buffer, self._constants_run = model.constants.buffer()
        self._constants_buffer.set_arg(0, memoryview(self.values))
        self._constants_buffer.set_res(0, memoryview(self.constants))
        self.constants_stale = True
        self.bound = {k: _Bound(c, self.t, self.h, self.values, self.state, self.constants)
                      for k, c in model.calls.items()}
        self.last = dict.fromkeys(CALLS, -1)  # the check each call reported last (-1: none)

    def run(self, which: str, t: float, h: float = 0.0) -> None:
        """Evaluate function ``which`` at time ``t`` (an advance over ``h``): its values and state are kept, its
        first failed check (an error before any warning) raises (:class:`ModelCheckError`) or is logged."""
        self.values[0] = t  # the time variable, as the C runtime's set_time
        if self.constants_stale:
            self._constants_run()
            self.constants_stale = False
        b = self.bound[which]
        self.t[0], self.h[0] = t, h
        b.run()
        call = b.call
        if len(b.sets):
            self.values[b.sets] = b.out[:len(b.sets)]
        if which == "start":
            self.state[:self.model.n_state] = self.model.initial_state
        if call.sets_state:
            self.state[:self.model.n_state] = b.new_state[:self.model.n_state]
        failed = self._first_failed(b)
        reported = self.last[which] == failed  # each check belongs to one function: reported by its last call
        self.last[which] = failed
        if failed < 0:
            return
        reason, error, n = call.checks[failed]
        if n:
            first = b.firsts[failed]
            reason = reason % tuple(float(x) for x in b.details[first:first + n])
        if error:
            raise ModelCheckError(f"t = {t:.9g} s: {reason}")
        if not reported:
            self.warn(f"t = {t:.9g} s: {reason}")

    @staticmethod
    def _first_failed(b: _Bound) -> int:
        checks = b.call.checks
        if not checks:
            return -1
        ok = b.ok
        warning = -1
        for k in np.flatnonzero(ok[:len(checks)] == 0.0):
            if checks[k][1]:
                return int(k)
            if warning < 0:
                warning = int(k)
        return warning

    def substeps(self, h: float) -> int:
        """Into how many equal advances a step of ``h`` is split (:func:`delta.dynamics.substeps`, as the C
        runtime's ``rt_substeps``), with the C runtime's refusals."""
        if not self.model.max_step:
            return 1
        name = self.model.variables[self.model.max_step][0]
        max_step = float(self.values[self.model.max_step])
        if not (max_step > 0.0 and math.isfinite(max_step)):
            raise ModelCheckError(f"{name} must be a time > 0 s, got {max_step!r}")
        if not -((-h) // max_step) <= 9007199254740992.0:  # 2**53: more substeps than a double counts
            raise ModelCheckError(f"a step of {h!r} s in substeps of {name} = {max_step!r} s is too many substeps")
        return substeps(h, max_step)


def _number(kind: str, choices: tuple[str, ...], name: str) -> Callable[[Any], float]:
    """The value array's number of an adapter's value of variable ``name``: a String is the index of its choice."""
    if kind != "string":
        return float
    index = {c: float(i) for i, c in enumerate(choices)}

    def choice(text: Any) -> float:
        try:
            return index[text]
        except (KeyError, TypeError):
            # Refused (correctness): a value the traced formulas have no branch for
            raise ModelCheckError(f'"{text}" is not a value of "{name}"; valid values: '
                                  + ", ".join(f'"{c}"' for c in choices)) from None
    return choice


_BACK = {"real": float, "boolean": bool, "integer": lambda x: int(round(x))}


class Traced:
    """The step of an adapter of :mod:`fmus.adapters` that has a native model: its traced functions, run by a
    :class:`Runtime` on the adapter's ``values`` (a mixin before the adapter's FMI layer, :class:`fmus.export2.Adapter`
    or :class:`fmus.export3.AdapterME`). ``TRACED`` is a function giving the :class:`TracedModel` (set by the FMU's
    generated module, or by :meth:`fmus.definition.FmuDefinition.python_class`)."""

    TRACED: Callable[[], TracedModel] | None = None

    def _runtime(self) -> Runtime:
        """A new runtime of this FMU's traced model, and the copies between it and ``values``."""
        if self.TRACED is None:
            raise ModelCheckError(f"{type(self).__name__}: no traced model (made neither by a build nor by its "
                                  "FmuDefinition)")
        model = self.TRACED()
        rt = Runtime(model, lambda message: self.log(message, self._STATUS_WARNING))
        mine = self.values
        self._pull = [(i, n, _number(kind, choices, n)) for i, (n, kind, _, choices) in enumerate(model.variables)
                      if n in mine and n != "time"]
        self._push = {which: [(i, model.variables[i][0], _BACK.get(model.variables[i][1], float)) for i in c.sets
                              if model.variables[i][0] in mine] for which, c in model.calls.items()}
        return rt

    def _sync_in(self) -> None:
        values, arr = self.values, self._rt.values
        for i, name, number in self._pull:
            arr[i] = number(values[name])

    def _sync_out(self, which: str) -> None:
        values, arr = self.values, self._rt.values
        for i, name, back in self._push[which]:
            values[name] = back(arr[i])

    def _run(self, which: str, t: float, h: float = 0.0) -> None:
        self._sync_in()
        self._rt.run(which, t, h)
        self._sync_out(which)

    # -- the adapter's hooks
    def start(self) -> None:
        """The model's start (initial state, start outputs) from the current parameters: a new runtime."""
        self._rt = self._runtime()
        self._run("start", self.time)

    def refresh(self) -> None:
        self._run("refresh", self.time)

    def advance(self, t: float, h: float) -> None:
        """The internal state over the step, in substeps of at most ``max_step``; then the outputs at ``t + h``, so
        that a failed check there fails the step (as the C runtime's ``rt_do_step``)."""
        self._sync_in()
        rt = self._rt
        n = rt.substeps(h)
        dt = h / n
        for k in range(n):
            rt.run("advance", t + k * dt, dt)
        self._sync_out("advance")
        self.time = t + h
        rt.run("refresh", self.time)
        self._sync_out("refresh")

    def retune(self, names: tuple[str, ...]) -> None:
        """Tunable parameters changed: the constants are computed again at the next call."""
        self._rt.constants_stale = True

    def internal_state(self) -> dict:
        rt = self._rt
        return {"state": rt.state[:rt.model.n_state].tolist(), "last": dict(rt.last)}

    def restore_internal(self, state: dict) -> None:
        rt = self._rt
        rt.state[:rt.model.n_state] = state["state"]
        rt.last.update(state["last"])
        rt.constants_stale = True


class TracedCS(Traced):
    """A co-simulation adapter's step (before :class:`fmus.export2.Adapter` in its bases)."""

    def do_step(self, current_time: float, step_size: float) -> bool:
        ok = super().do_step(current_time, step_size)
        if ok:
            self._dirty = False  # advance computed the outputs at the step's end
        return ok

    def _step_failure(self, t: float, h: float, exc: Exception) -> str:
        """A failed check logs its reason at its time, as the native build's (``t = 0.021 s: PD.kp must be ...``)."""
        return str(exc) if isinstance(exc, ModelCheckError) else super()._step_failure(t, h, exc)


class TracedME(Traced):
    """A model-exchange adapter's step (before :class:`fmus.export3.AdapterME` in its bases): the derivatives of the
    states and inputs; the outputs, with the checks of the state (``accept``), where the importer reads them."""

    def derivatives(self) -> None:
        self._run("derivatives", self.time)

    def outputs(self) -> None:
        self._run("accept" if self._rt.model.me_accepts else "refresh", self.time)
