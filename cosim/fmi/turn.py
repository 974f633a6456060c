"""The master's per-step FMI calls in one C call each: a co-simulation component's turn of a macro step
(set inputs, doStep, get outputs, NaN check) and a model-exchange FMU's right-hand side (set time, set
states, get derivatives, NaN check).

The master calls an FMU's C functions through ctypes, and each crossing from Python into C costs about
0.6 us in its loop (0.35 us in a tight micro-benchmark), whatever the function does. A Gauss-Seidel
turn makes three or more of them (fmiXSet<Type> per input buffer, fmiXDoStep, fmiXGet<Type> per output
buffer) and then sums the real outputs in Python to catch a NaN. ``cosim_turn`` (``turn.c``, beside this
module) makes the same calls in the same order from C, checks the outputs there, and returns which call
failed, if one did: one crossing per component and step. On helix_ctc_analytic with native FMUs that
takes a component from 2.1-3.4 us to 0.9-1.6 us per step (``benchmarks/master_native.py``).

A whole system whose components all have C turns can go further: ``cosim_steps`` runs a run of macro
steps in one call, the link copies, every turn in the algorithm's order, the record the watchdog reads and
the tracked errors' sums included (:mod:`cosim.engine.cloop`); Python is entered once per block of steps.

A model-exchange FMU's right-hand side, which the master's integrator evaluates many times per step
(fmiXSetTime, fmiXSetContinuousStates, fmiXGetDerivatives or fmi3GetContinuousStateDerivatives, then the
derivatives checked for NaN), is one crossing the same way: ``cosim_rhs``, through :func:`make_rhs`
(:meth:`cosim.fmi.model_exchange.ModelExchange.rhs`).

The helper is compiled at first use (:mod:`cosim.cbuild`: the system C compiler, the user's cache, once
per version of its source). Without a compiler, or when the
build fails, :func:`helper` and :func:`rhs_helper` return None, :func:`unavailable` says why, and the
master makes the same calls from Python one by one (:meth:`cosim.fmi.slave.CoSimulation.set_step_get`,
:meth:`cosim.fmi.model_exchange.ModelExchange.rhs`).
"""

from __future__ import annotations

import ctypes
from ctypes import POINTER, c_bool, c_double, c_int, c_int64, c_size_t, c_void_p
from functools import partial
from pathlib import Path
from typing import Any, Callable, Sequence

from ..cbuild import Library

__all__ = ["Exchange", "Finite", "Turn", "Rhs", "Move", "Steps", "helper", "rhs_helper", "steps_helper",
           "unavailable", "make_turn", "make_rhs", "SET", "STEP", "GET", "NONFINITE", "TIME", "STATES", "DERIVATIVES"]

SET, STEP, GET, NONFINITE = 1, 2, 3, 4  # what ended a turn (cosim_turn's return value; 0: completed)
TIME, STATES, DERIVATIVES = 1, 2, 3  # what ended a right-hand side (cosim_rhs's return value, or NONFINITE; 0: done)


class Exchange(ctypes.Structure):
    """One fmiXSet<Type> / fmiXGet<Type> call of a whole buffer (``Exchange`` in turn.c)."""

    _fields_ = [("function", c_void_p), ("vrs", c_void_p), ("n", c_size_t), ("values", c_void_p), ("size", c_size_t)]


class Finite(ctypes.Structure):
    """A real output buffer checked for NaN and infinity (``Finite`` in turn.c)."""

    _fields_ = [("values", c_void_p), ("size", c_size_t), ("single", c_int)]


class Turn(ctypes.Structure):
    """A component's turn (``Turn`` in turn.c); ``status`` and ``index`` say which call ended it."""

    _fields_ = [("fmi", c_int), ("instance", c_void_p), ("do_step", c_void_p),
                ("t", POINTER(c_double)), ("h", POINTER(c_double)),
                ("event", POINTER(c_bool)), ("terminate", POINTER(c_bool)), ("early", POINTER(c_bool)),
                ("last", POINTER(c_double)),
                ("n_set", c_size_t), ("n_get", c_size_t), ("n_finite", c_size_t),
                ("sets", POINTER(Exchange)), ("gets", POINTER(Exchange)), ("finite", POINTER(Finite)),
                ("status", c_int), ("index", c_size_t)]


class Rhs(ctypes.Structure):
    """A model-exchange FMU's right-hand side (``Rhs`` in turn.c); ``status`` says how the call that ended
    it failed."""

    _fields_ = [("instance", c_void_p), ("set_time", c_void_p), ("set_states", c_void_p),
                ("get_derivatives", c_void_p), ("nx", c_size_t), ("t", POINTER(c_double)), ("status", c_int)]


class Move(ctypes.Structure):
    """A link's values copied as bytes from an output buffer into an input buffer (``Move`` in turn.c)."""

    _fields_ = [("dst", c_void_p), ("src", c_void_p), ("bytes", c_size_t)]


class Steps(ctypes.Structure):
    """Macro steps of a whole system of C turns (``Steps`` in turn.c; built by :mod:`cosim.engine.cloop`)."""

    _fields_ = [("n", c_size_t), ("turns", POINTER(POINTER(Turn))), ("comp", POINTER(c_size_t)),
                ("first", POINTER(c_size_t)), ("moves", POINTER(Move)), ("jacobi", c_int),
                ("wall", POINTER(c_double)), ("record", c_void_p), ("master", c_double),
                ("times", POINTER(c_double)), ("steps", POINTER(c_double)), ("ends", POINTER(c_int64)),
                ("n_pairs", c_size_t), ("actual", POINTER(c_void_p)), ("reference", POINTER(c_void_p)),
                ("sq", POINTER(c_double)), ("mx", POINTER(c_double)), ("t_mx", POINTER(c_int64)),
                ("budget", c_double), ("failed", c_size_t), ("ended", c_int),
                ("n_copies", c_size_t), ("copies", POINTER(Move)), ("row_count", c_void_p), ("row_stamps", c_void_p),
                ("rows", c_void_p), ("row_width", c_size_t), ("row_cap", c_size_t)]


_LIBRARY = Library(Path(__file__).with_name("turn.c"))


def _build() -> Any:
    """The helper's library: from the cache, else compiled into it. Raises OSError or RuntimeError."""
    return _LIBRARY.build()


def _library() -> Any:
    """The helper's loaded library, or None when it cannot be built here."""
    return _LIBRARY.get()


def helper() -> Any:
    """The compiled ``cosim_turn`` (a ctypes function), or None when it cannot be built here."""
    lib = _library()
    return None if lib is None else lib.cosim_turn


def rhs_helper() -> Any:
    """The compiled ``cosim_rhs`` (a ctypes function), or None when it cannot be built here."""
    lib = _library()
    return None if lib is None else lib.cosim_rhs


def steps_helper() -> Any:
    """The compiled ``cosim_steps`` (a ctypes function), or None when it cannot be built here."""
    lib = _library()
    return None if lib is None else lib.cosim_steps


def unavailable() -> str | None:
    """Why :func:`helper` and :func:`rhs_helper` returned None (None: they did not, or were not asked yet)."""
    return _LIBRARY.reason


def make_turn(fmi: int, instance: int, do_step: int, t: c_double, h: c_double, sets: Sequence[Exchange],
              gets: Sequence[Exchange], finite: Sequence[Finite], flags: Sequence[Any] | None,
              prototype: Callable[[Any], Any]) -> tuple[Callable[[], int], Turn] | None:
    """A component's turn as a call without arguments returning 0 or what ended it (SET, STEP, GET or
    NONFINITE; the :class:`Turn` says which call and its status), and the Turn. None when the helper is
    unavailable.

    ``instance`` and ``do_step`` are addresses; ``t`` and ``h`` the ``c_double`` s the caller writes the
    communication point and step size into before each call; ``flags`` FMI 3 doStep's outputs
    (eventHandlingNeeded, terminateSimulation, earlyReturn as ``c_bool``, lastSuccessfulTime as
    ``c_double``), None for FMI 1 and 2; ``fmi`` 1, 2 or 3 (FMI 1 and 2 share the exchange signature,
    their doStep's last argument is a ``char`` and an ``int``); ``prototype(f)`` the ctypes prototype ``f`` is called through (the GIL
    handling of the FMU's other calls). The Turn keeps the arrays and values it points to alive (ctypes
    holds them in its ``_objects``), but not the buffers the exchanges name by address: their owner must
    outlive the call.
    """
    f = helper()
    if f is None:
        return None
    u = Turn(fmi=fmi, instance=instance, do_step=do_step, t=ctypes.pointer(t), h=ctypes.pointer(h),
             n_set=len(sets), n_get=len(gets), n_finite=len(finite),
             sets=(Exchange * max(1, len(sets)))(*sets), gets=(Exchange * max(1, len(gets)))(*gets),
             finite=(Finite * max(1, len(finite)))(*finite))
    if flags is not None:
        u.event, u.terminate, u.early, u.last = (ctypes.pointer(x) for x in flags)
    return partial(prototype(f), ctypes.byref(u)), u


def make_rhs(instance: int, set_time: int, set_states: int, get_derivatives: int, nx: int, t: c_double,
             prototype: Callable[[Any], Any]) -> tuple[Callable[[Any, Any], int], Rhs] | None:
    """A model-exchange FMU's right-hand side as a call ``(x, dx)`` returning 0 or what ended it (TIME,
    STATES, DERIVATIVES or NONFINITE; the :class:`Rhs`'s ``status`` says how the FMI call failed), and the
    Rhs. None when the helper is unavailable.

    ``instance`` and the three FMI functions (fmiXSetTime, fmiXSetContinuousStates, fmi2GetDerivatives or
    fmi3GetContinuousStateDerivatives) are addresses, ``nx`` the number of continuous states, ``t`` the
    ``c_double`` the caller writes the time into before each call; ``x`` and ``dx`` are ``c_double`` arrays
    or pointers of ``nx`` values (passed as they are: no argument types are declared, which saves their
    conversions, 0.7 us a call). ``prototype(f)`` is the ctypes prototype ``f`` is called through (the GIL
    handling of the FMU's other calls). The call keeps the Rhs alive, and the Rhs ``t``.
    """
    f = rhs_helper()
    if f is None:
        return None
    r = Rhs(instance=instance, set_time=set_time, set_states=set_states, get_derivatives=get_derivatives, nx=nx,
            t=ctypes.pointer(t))
    return partial(prototype(f), ctypes.byref(r)), r
