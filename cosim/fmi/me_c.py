"""A model-exchange FMU's integration between communication points in C: the integrators ``dopri5`` and
``cvode`` of :mod:`cosim.fmi.integrators` when the helper ``me_loop.c`` (beside this module) can be built.

The Python integrators cross from Python into the FMU for every right-hand side: with SciPy stepping one
step at a time, about 15 us per evaluation, 130 001 of them in 10 s of helix_ctc_me. Here one call from
Python integrates to the next communication point (or to a state event): the right-hand side, the event
indicators and the completed-integrator-step call are made from C on the FMU's own C functions. Python is
entered once per advance; the event iteration stays in Python (:class:`cosim.fmi.model_exchange.ModelExchange`).

- :class:`DOPRI5` is the explicit Dormand-Prince 5(4) pair written in ``me_loop.c`` (adaptive step, the
  4th-order dense output, state events located on it by bisection to ``100 * eps * (|t| + |h|)``). Its
  Python fallback is SciPy's ``RK45``, the same pair (:class:`cosim.fmi.integrators.SciPyIntegrator`).
- :class:`CVode` is SUNDIALS CVode from the libraries fmpy ships (``fmpy/sundials``), the maintained build
  the Python path already uses: the same solver and version whether or not a compiler is there. CVode's
  memory is made from Python through fmpy's ctypes bindings, with ``cosim_cv_rhs`` and ``cosim_cv_roots``
  (C) as right-hand side and root function; the few SUNDIALS functions the loop calls (CVode,
  CVodeReInit, CVodeSetStopTime, N_VGetArrayPointer) are resolved in Python from fmpy's loaded libraries
  and handed to C as pointers in the ``Cv`` struct. So ``me_loop.c`` needs no SUNDIALS header (none is
  installed with fmpy, nor on the CI machine) and calls exactly the library instance fmpy loaded, with
  the signatures fmpy's bindings declare for that version (SUNDIALS 7).

A failing FMI call ends the advance; the ``Fmu`` struct says which call, its status and the time, and
:meth:`cosim.fmi.model_exchange.ModelExchange.c_failed` raises as the same call made from Python raises.
Without a compiler (or when the build fails) :func:`make_c_integrator` returns None and
:mod:`cosim.fmi.integrators` uses its Python integrators; :func:`unavailable` says why.
"""

from __future__ import annotations

import ctypes
from ctypes import POINTER, c_char, c_double, c_int, c_long, c_size_t, c_void_p
from pathlib import Path
from typing import Any

from ..cbuild import Library
from .integrators import CVodeIntegrator, IntegratorError
from .turn import Exchange, Finite, Turn  # the one Python definition of the exchanges' and turns' layouts

__all__ = ["Fmu", "DOPRI5", "CVode", "MacroStep", "make_c_integrator", "unavailable", "C_SOLVERS", "CALL_NAMES"]

C_SOLVERS = ("cvode", "dopri5")
REACHED, STATE_EVENT, FAILED = 0, 1, 2  # an advance's return value
# Fmu.call: what ended an advance (me_loop.c's CALL_*)
(SET_TIME, SET_X, GET_DX, NONFINITE, GET_Z, GET_X, GET_NOMINALS, COMPLETED, TOO_MANY_STEPS, STEP_TOO_SMALL,
 SOLVER) = range(1, 12)
CALL_NAMES = {SET_TIME: "set_time", SET_X: "set_x", GET_DX: "get_dx", GET_Z: "get_z", GET_X: "get_x",
              GET_NOMINALS: "get_nominals", COMPLETED: "completed"}  # keys of ModelExchange.c_functions


class Fmu(ctypes.Structure):
    """The FMU's functions and what ended an advance (``Fmu`` in me_loop.c)."""

    _fields_ = [("fmi", c_int), ("instance", c_void_p),
                ("set_time", c_void_p), ("get_x", c_void_p), ("set_x", c_void_p), ("get_dx", c_void_p),
                ("get_z", c_void_p), ("get_nominals", c_void_p), ("completed", c_void_p),
                ("needs_completed", c_int), ("nx", c_size_t), ("nz", c_size_t), ("bad", POINTER(c_double)),
                ("call", c_int), ("status", c_int), ("t_fail", c_double),
                ("step_event", c_int), ("terminate", c_int), ("evaluations", c_long), ("t_set", c_double),
                ("t_now", c_double)]


class _Dopri(ctypes.Structure):
    _fields_ = [("fmu", POINTER(Fmu)), ("rtol", c_double), ("max_step", c_double), ("max_steps", c_long),
                ("restart", c_int), ("t", c_double), ("h", c_double), ("facold", c_double), ("t_reached", c_double),
                ("inputs", c_int),
                *((name, POINTER(c_double)) for name in ("x", "xnew", "xs", "atol", "k", "dense", "z_prev", "z",
                                                         "z_mid")),
                ("hit", POINTER(c_char))]


class _Cv(ctypes.Structure):
    _fields_ = [("fmu", POINTER(Fmu)), ("mem", c_void_p), ("y", c_void_p),
                ("cvode", c_void_p), ("reinit", c_void_p), ("set_stop", c_void_p), ("get_array", c_void_p),
                ("restart", c_int), ("t", c_double), ("t_reached", c_double), ("flag", c_int)]


_LIBRARY = Library(Path(__file__).with_name("me_loop.c"))


def unavailable() -> str | None:
    """Why :func:`make_c_integrator` returned None (None: it did not, or was not asked yet)."""
    return _LIBRARY.reason


def _address(f: Any) -> int:
    return ctypes.cast(f, c_void_p).value


def make_c_integrator(name: str, model: Any, t0: float, rtol: float, max_step: float) -> Any:
    """The C integrator ``name`` (one of :data:`C_SOLVERS`) for ``model`` (a ModelExchange after its initial
    event iteration), or None when the helper cannot be built here or the model offers no C functions."""
    functions = getattr(model, "c_functions", lambda: None)()
    if name not in C_SOLVERS or functions is None:
        return None
    lib = _LIBRARY.get()
    if lib is None:
        return None
    cls = DOPRI5 if name == "dopri5" else CVode
    return cls(lib, functions, model, t0, rtol, max_step)


class _CIntegrator:
    """What both C integrators share: the Fmu struct, the advance call, its failures raised."""

    completes = True  # advance() makes the completedIntegratorStep call: step_event and terminate say its result

    def __init__(self, functions: dict, model: Any) -> None:
        self.model = model
        nx, nz = model.nx, model.nz
        self._bad = (c_double * max(nx, 1))()
        self.fmu = Fmu(fmi=functions["fmi"], instance=functions["instance"],
                       needs_completed=int(functions["needs_completed"]), nx=nx, nz=nz, bad=self._bad,
                       **{k: functions[k] or 0 for k in CALL_NAMES.values()})
        self._prototype = functions["prototype"]
        self.step_event = self.terminate = False

    def _bind(self, f: Any, state: Any) -> None:
        call = self._prototype(f)
        call.argtypes, call.restype = [c_void_p, c_double], c_int
        self._call, self._address = call, ctypes.addressof(state)

    @property
    def evaluations(self) -> int:
        """Right-hand sides evaluated so far (FMI derivative calls)."""
        return self.fmu.evaluations

    def advance(self, t_stop: float) -> tuple[float, bool]:
        return self.result(self._call(self._address, t_stop))

    def result(self, ended: int) -> tuple[float, bool]:
        """(time reached, state event found) of an advance that returned ``ended``; raises for a failed one."""
        fmu = self.fmu
        if ended == FAILED:
            self._failed(fmu)
        self.step_event, self.terminate = fmu.step_event != 0, fmu.terminate != 0
        return self._state.t_reached, ended == STATE_EVENT

    def _failed(self, fmu: Fmu) -> None:
        call = fmu.call
        if call in CALL_NAMES or call == NONFINITE:
            self.model.c_failed(CALL_NAMES.get(call, "get_dx"), fmu.status, fmu.t_fail, self._bad)
        raise IntegratorError(self._why(call, fmu.t_fail))

    def _why(self, call: int, t: float) -> str:
        raise NotImplementedError


class DOPRI5(_CIntegrator):
    """Dormand-Prince 5(4) in C (``cosim_dopri5_advance``), with its dense output for event location."""

    MAX_NUM_STEPS = 10_000  # steps per advance (one never passes a communication point; a healthy one takes few)

    def __init__(self, lib: Any, functions: dict, model: Any, t0: float, rtol: float, max_step: float) -> None:
        super().__init__(functions, model)
        n, nz = max(model.nx, 1), max(model.nz, 1)
        self._arrays = {name: (c_double * (size * n))() for name, size in
                        (("x", 1), ("xnew", 1), ("xs", 1), ("atol", 1), ("k", 7), ("dense", 5))}
        self._arrays.update({name: (c_double * nz)() for name in ("z_prev", "z", "z_mid")})
        self._hit = (c_char * nz)()
        self._state = _Dopri(fmu=ctypes.pointer(self.fmu), rtol=rtol, max_step=max_step,
                             max_steps=self.MAX_NUM_STEPS, restart=1, t=t0, h=0.0, facold=1e-4,
                             hit=ctypes.cast(self._hit, POINTER(c_char)), **self._arrays)
        self._bind(lib.cosim_dopri5_advance, self._state)

    def reset(self, t: float) -> None:
        self._state.t = t
        self._state.restart = 1

    def forget(self) -> None:
        """Start the next advance as a new integrator does: no step size proposed, the controller's memory cleared
        (a checkpoint: the resumed run's integrator is new)."""
        self._state.h, self._state.facold = 0.0, 1e-4

    def _why(self, call: int, t: float) -> str:
        if call == TOO_MANY_STEPS:
            return (f"DOPRI5 took {self.MAX_NUM_STEPS} steps without reaching the stop time (at t = {t:.9g} s, step "
                    f"{self._state.h:.3g} s): the model is stiff or diverging (solver: cvode handles stiff models)")
        return f"DOPRI5 failed at t = {t:.9g} s: the step size fell below the time's resolution"


class CVode(_CIntegrator):
    """SUNDIALS CVode (fmpy's libraries) with a C right-hand side and root function (``cosim_cv_advance``)."""

    def __init__(self, lib: Any, functions: dict, model: Any, t0: float, rtol: float, max_step: float) -> None:
        from fmpy.sundials.cvode import CVRhsFn, CVRootFn  # lazy: --help loads this module without it
        from fmpy.sundials.libraries import sundials_core, sundials_cvode  # lazy, as above

        super().__init__(functions, model)
        rhs, roots = CVRhsFn(_address(lib.cosim_cv_rhs)), CVRootFn(_address(lib.cosim_cv_roots))
        # the Python integrator's set-up (memory, tolerances, linear solver, error handler), with the C callbacks
        self._cv = cv = CVodeIntegrator(model, t0, rtol, max_step, rhs=rhs, roots=roots)
        self._state = _Cv(fmu=ctypes.pointer(self.fmu), mem=cv.mem, y=ctypes.cast(cv.x, c_void_p), restart=0, t=t0,
                          cvode=_address(sundials_cvode.CVode), reinit=_address(sundials_cvode.CVodeReInit),
                          set_stop=_address(sundials_cvode.CVodeSetStopTime),
                          get_array=_address(sundials_core.N_VGetArrayPointer))
        set_user_data = sundials_cvode.CVodeSetUserData
        set_user_data.argtypes, set_user_data.restype = [c_void_p, c_void_p], c_int
        cv._ok(set_user_data(cv.mem, ctypes.addressof(self._state)), "CVodeSetUserData")
        self._bind(lib.cosim_cv_advance, self._state)

    def reset(self, t: float) -> None:
        self._state.t = t
        self._state.restart = 1

    def _why(self, call: int, t: float) -> str:
        return f"CVode failed (flag {self._state.flag}) at t = {t:.9g} s: {self._cv.message}"


# --------------------------------------------------------------------------- the macro step

STEP_OK, STEP_SET, STEP_ADVANCE, STEP_EVENT, STEP_GET, STEP_NONFINITE = range(6)  # cosim_me_step's return value


class _MeStep(ctypes.Structure):
    _fields_ = [("fmu", POINTER(Fmu)), ("cvode", c_int), ("integrator", c_void_p),
                ("n_set", c_size_t), ("n_get", c_size_t), ("n_finite", c_size_t),
                ("sets", c_void_p), ("applied", POINTER(c_void_p)), ("bytes", POINTER(c_size_t)),
                ("gets", c_void_p), ("finite", c_void_p), ("index", c_int), ("changed", c_int), ("ended", c_int)]


class MacroStep:
    """A model-exchange FMU's macro step in one C call (``cosim_me_step``): the inputs that changed set (the
    integrator re-started), the advance to the step's end, the outputs read and checked for NaN. For an FMU
    whose inputs are all continuous reals and whose exchanges are numbers only, with no time event inside the
    step (:class:`cosim.fmi.model_exchange.ModelExchange` checks); anything else, and any event, is the Python
    loop's.

    ``sets`` and ``gets`` are :class:`cosim.fmi.turn.Exchange` s (the layout ``me_loop.c`` declares again),
    ``finite`` :class:`cosim.fmi.turn.Finite` s, ``sizes`` the bytes of each input buffer. :attr:`applied`
    holds each input buffer's values as last set (ctypes byte arrays, the C step's bookkeeping of what
    changed); the caller copies them to and from its own where the Python path takes over.
    """

    def __init__(self, integrator: Any, sets: list, gets: list, finite: list, sizes: list[int]) -> None:
        self.integrator = integrator
        self.applied = [(ctypes.c_ubyte * max(size, 1))() for size in sizes]
        self._keep = (sets := (Exchange * max(1, len(sets)))(*sets), gets := (Exchange * max(1, len(gets)))(*gets),
                      finite := (Finite * max(1, len(finite)))(*finite),
                      applied := (c_void_p * max(1, len(sizes)))(*[ctypes.addressof(a) for a in self.applied]),
                      size := (c_size_t * max(1, len(sizes)))(*sizes))
        self.state = _MeStep(fmu=ctypes.pointer(integrator.fmu), cvode=int(isinstance(integrator, CVode)),
                             integrator=ctypes.addressof(integrator._state), n_set=len(sizes), n_get=len(gets),
                             n_finite=len(finite), sets=ctypes.addressof(sets), applied=applied, bytes=size,
                             gets=ctypes.addressof(gets), finite=ctypes.addressof(finite))
        call = integrator._prototype(_LIBRARY.get().cosim_me_step)
        call.argtypes, call.restype = [c_void_p, c_double, c_double], c_int
        self._call, self._address = call, ctypes.addressof(self.state)
        self._turn: Turn | None = None

    def turn(self) -> Turn:
        """The step as a :class:`cosim.fmi.turn.Turn` without exchanges whose doStep is ``cosim_me_do_step``
        (FMI 2.0's signature; the instance is this step's state), for a loop in C that calls turns
        (``cosim_steps``); after a turn that failed, :attr:`state` ``ended`` says how."""
        if self._turn is None:
            self._t, self._h = c_double(), c_double()
            empty = (Exchange * 1)()
            self._turn = Turn(fmi=2, instance=self._address, do_step=_address(_LIBRARY.get().cosim_me_do_step),
                              t=ctypes.pointer(self._t), h=ctypes.pointer(self._h), n_set=0, n_get=0, n_finite=0,
                              sets=empty, gets=empty, finite=(Finite * 1)())
        return self._turn

    def __call__(self, t: float, t_end: float) -> int:
        """One macro step from ``t`` to ``t_end``: STEP_OK or what ended it (:attr:`state` ``index`` says which
        buffer; STEP_EVENT: ``index`` is the advance's result, the integrator's flags say the rest)."""
        return self._call(self._address, t, t_end)
