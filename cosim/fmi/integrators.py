"""ODE integrators for model-exchange FMUs: one continuous integration between events.

The master integrates a model-exchange FMU itself. :class:`~cosim.fmi.model_exchange.ModelExchange` owns the
FMI protocol (event mode, event iteration, time events, step events, termination); an
integrator here owns only the numerics: it advances the FMU's continuous states towards a
stop time it must not pass, locates state events (a sign change of an event indicator) to
its own tolerance, and leaves the FMU at the time and states it reached. It is re-started
(:meth:`reset`) only after an event or when an input changed, as FMPy and OMSimulator do.

Three integrators behind one protocol, chosen per component in the scenario (``solver:``):

- ``cvode`` (the default): SUNDIALS CVode from fmpy's bundled libraries, BDF with a dense
  direct linear solver: the solver FMPy's ``simulate_fmu`` uses, robust for the stiff models
  third-party tools export. Its root finding locates state events to about
  ``100 * eps * (|t| + |h|)``. A multistep method restarts at order one: when an input changes
  at every communication step (a plant fed by a controller), every step restarts it.
- ``dopri5``: the explicit Dormand-Prince 5(4) pair with its dense output, state events located
  on the dense output by bisection to ``100 * eps * (|t| + |h|)``, as CVode does. A one-step
  method restarts for free: the choice for non-stiff models whose inputs change at every
  communication step.
- ``dop853``: SciPy's explicit Runge-Kutta of order 8(5,3) stepped one step at a time
  (``scipy.integrate.DOP853``), events located the same way (Python only).

``cvode`` and ``dopri5`` run in C where the helper ``me_loop.c`` can be built (:mod:`cosim.fmi.me_c`: one
call from Python per advance, every FMU call of the integration made from C; the master asks there first).
Without a C compiler they fall back to the Python integrators here (:func:`make_integrator`): CVode through fmpy's ctypes bindings with Python callbacks
(:class:`CVodeIntegrator`), and SciPy's ``RK45``, the same Dormand-Prince pair, stepped like ``dop853``
(:class:`SciPyIntegrator`). The results of the two paths agree to the integrator's tolerance (CVode: the
same library, bit for bit; DOPRI5: two implementations of one method).

All keep any exception raised by the model inside a solver callback (an FMI status check)
and re-raise it from :meth:`advance`, so a failing FMU call is reported as itself.
"""

from __future__ import annotations

from ctypes import byref, c_double, c_int, c_void_p
from typing import Any, Protocol

import numpy as np

from ..errors import CosimError, SettingError


__all__ = ["OdeModel", "Integrator", "make_integrator", "SOLVERS", "IntegratorError"]

SOLVERS = ("cvode", "dop853", "dopri5")


class IntegratorError(CosimError, RuntimeError):
    """The integrator gave up (too many steps, step size underflow, repeated test failures)."""


class OdeModel(Protocol):
    """What an integrator needs from a model-exchange FMU (pointers are ``c_double`` arrays)."""

    nx: int
    nz: int

    def rhs(self, t: float, x: Any, dx: Any) -> None:
        """The derivatives ``dx`` at time ``t`` and states ``x``: set_time, set_x, get_dx in one."""
    def set_time(self, t: float) -> None: ...
    def get_x(self, x: Any) -> None: ...
    def set_x(self, x: Any) -> None: ...
    def get_dx(self, dx: Any) -> None: ...
    def get_z(self, z: Any) -> None: ...
    def get_nominals(self, x: Any) -> None: ...


class Integrator(Protocol):
    completes: bool  # optional (absent: False): advance() itself makes the completedIntegratorStep call
    step_event: bool  # when it does: the call's enterEventMode, of the last advance
    terminate: bool  # and its terminateSimulation

    def reset(self, t: float) -> None:
        """Restart at time ``t`` from the model's current continuous states."""

    def advance(self, t_stop: float) -> tuple[float, bool]:
        """Integrate towards ``t_stop`` (never past it); return (time reached, state event found).

        On return the model's time and continuous states are those of the time reached.
        """


def make_integrator(name: str, model: OdeModel, t0: float, rtol: float, max_step: float) -> Integrator:
    """The Python integrator ``name`` (one of :data:`SOLVERS`) for ``model`` starting at ``t0`` (the C ones:
    :func:`cosim.fmi.me_c.make_c_integrator`, tried first by the master)."""
    if name not in SOLVERS:
        raise SettingError(f"unknown solver {name!r}; valid: {', '.join(SOLVERS)}")
    if name == "cvode":
        return CVodeIntegrator(model, t0, rtol, max_step)
    return SciPyIntegrator(model, t0, rtol, max_step, "RK45" if name == "dopri5" else "DOP853")


def _root_tolerance(t: float, h: float) -> float:
    """CVode's root-location tolerance: ``100 * unit roundoff * (|t| + |h|)``."""
    return 100.0 * np.finfo(float).eps * (abs(t) + abs(h))


def _crossed(z0: np.ndarray, z1: np.ndarray) -> np.ndarray:
    """Indicators that changed sign from ``z0`` to ``z1`` (FMI: from > 0 to <= 0 or < 0 to >= 0)."""
    return ((z0 > 0) & (z1 <= 0)) | ((z0 < 0) & (z1 >= 0))


# --------------------------------------------------------------------------- CVode


class CVodeIntegrator:
    """CVode (BDF, dense Jacobian by finite differences) driven through fmpy's SUNDIALS bindings."""

    MAX_NUM_STEPS = 100_000  # internal steps allowed per call (one call never passes a communication point)

    def __init__(self, model: OdeModel, t0: float, rtol: float, max_step: float, rhs: Any = None,
                 roots: Any = None) -> None:
        """``rhs`` and ``roots``: a CVRhsFn and a CVRootFn to use instead of this class's Python callbacks (the C
        ones of :class:`cosim.fmi.me_c.CVode`, which then also sets the user data and drives the solver)."""
        from fmpy.sundials import (  # lazy: --help loads this module without it
            CV_BDF,
            NV_DATA_S,
            SUN_COMM_NULL,
            N_VNew_Serial,
            SUNContext,
            SUNContext_Create,
            SUNContext_PushErrHandler,
            SUNDenseMatrix,
            SUNErrHandlerFn,
            SUNLinSol_Dense,
        )
        from fmpy.sundials.cvode import (  # lazy: --help loads this module without it
            CV_NORMAL,
            CVode,
            CVodeCreate,
            CVodeInit,
            CVodeReInit,
            CVodeRootInit,
            CVodeSetMaxNumSteps,
            CVodeSetMaxStep,
            CVodeSetNoInactiveRootWarn,
            CVodeSVtolerances,
            CVRhsFn,
            CVRootFn,
        )
        from fmpy.sundials.cvode_ls import CVodeSetLinearSolver  # lazy: --help loads this module without it
        from fmpy.sundials.libraries import sundials_cvode  # lazy: --help loads this module without it

        self.model = model
        self.rtol = rtol
        self.discrete = model.nx == 0  # no continuous state: a dummy one (CVode needs one to find roots)
        self.n = max(model.nx, 1)
        self.error: BaseException | None = None
        self.message = ""
        self._NV_DATA_S = NV_DATA_S
        self.ctx = SUNContext()
        self._ok(SUNContext_Create(SUN_COMM_NULL, byref(self.ctx)), "SUNContext_Create")
        self.x = N_VNew_Serial(self.n, self.ctx)
        self.abstol = N_VNew_Serial(self.n, self.ctx)
        self.px = NV_DATA_S(self.x)
        self.pabstol = NV_DATA_S(self.abstol)
        self.mem = CVodeCreate(CV_BDF, self.ctx)
        self._f = CVRhsFn(self._rhs) if rhs is None else rhs
        self._g = CVRootFn(self._roots) if roots is None else roots
        self._eh = SUNErrHandlerFn(self._on_error)
        self._read_state()
        self._ok(CVodeInit(self.mem, self._f, t0, self.x), "CVodeInit")
        self._ok(CVodeSVtolerances(self.mem, rtol, self.abstol), "CVodeSVtolerances")
        if model.nz:
            self._ok(CVodeRootInit(self.mem, model.nz, self._g), "CVodeRootInit")
        self.A = SUNDenseMatrix(self.n, self.n, self.ctx)
        self.LS = SUNLinSol_Dense(self.x, self.A, self.ctx)
        self._ok(CVodeSetLinearSolver(self.mem, self.LS, self.A), "CVodeSetLinearSolver")
        self._ok(CVodeSetMaxStep(self.mem, max_step), "CVodeSetMaxStep")
        self._ok(CVodeSetMaxNumSteps(self.mem, self.MAX_NUM_STEPS), "CVodeSetMaxNumSteps")
        self._ok(CVodeSetNoInactiveRootWarn(self.mem), "CVodeSetNoInactiveRootWarn")
        self._ok(SUNContext_PushErrHandler(self.ctx, self._eh, None), "SUNContext_PushErrHandler")
        # functions fmpy does not bind
        self._set_stop = sundials_cvode.CVodeSetStopTime
        self._set_stop.argtypes, self._set_stop.restype = [c_void_p, c_double], c_int
        self._cvode, self._normal, self._reinit = CVode, CV_NORMAL, CVodeReInit
        self._tret = c_double()

    @staticmethod
    def _ok(flag: int, function: str) -> None:
        if flag not in (0, None):
            raise IntegratorError(f"{function} failed with flag {flag}")

    def _on_error(self, line, func, file, msg, err_code, err_user_data, sunctx) -> None:
        self.message = (msg or b"").decode("utf-8", "replace")

    def _read_state(self) -> None:
        """Copy the model's states into CVode's vector and set absolute tolerances rtol * nominal."""
        if self.discrete:
            self.px[0] = 0.0
            self.pabstol[0] = self.rtol
            return
        self.model.get_x(self.px)
        self.model.get_nominals(self.pabstol)
        for i in range(self.n):
            self.pabstol[i] = self.rtol * abs(self.pabstol[i])

    def _rhs(self, t: float, y: Any, ydot: Any, user_data: Any) -> int:
        try:
            if self.discrete:
                self.model.set_time(t)
                self._NV_DATA_S(ydot)[0] = 0.0
            else:
                self.model.rhs(t, self._NV_DATA_S(y), self._NV_DATA_S(ydot))
            return 0
        except BaseException as exc:  # noqa: BLE001 - kept and raised from advance()
            self.error = self.error or exc
            return -1  # unrecoverable: CVode stops at once

    def _roots(self, t: float, y: Any, gout: Any, user_data: Any) -> int:
        try:
            self.model.set_time(t)
            if not self.discrete:
                self.model.set_x(self._NV_DATA_S(y))
            self.model.get_z(gout)
            return 0
        except BaseException as exc:  # noqa: BLE001
            self.error = self.error or exc
            return -1

    def reset(self, t: float) -> None:
        self._read_state()
        self._ok(self._reinit(self.mem, t, self.x), "CVodeReInit")

    def advance(self, t_stop: float) -> tuple[float, bool]:
        self._set_stop(self.mem, t_stop)
        flag = self._cvode(self.mem, t_stop, self.x, byref(self._tret), self._normal)
        if self.error is not None:
            err, self.error = self.error, None
            raise err
        if flag < 0:
            raise IntegratorError(f"CVode failed (flag {flag}): {self.message}")
        t = self._tret.value
        self.model.set_time(t)
        if not self.discrete:
            self.model.set_x(self.px)
        return t, flag == 2  # CV_ROOT_RETURN


# --------------------------------------------------------------------------- SciPy's DOP853 and RK45


class SciPyIntegrator:
    """SciPy's ``DOP853`` or ``RK45`` (``method``), one step at a time, with state events located on its dense
    output."""

    MAX_NUM_STEPS = 10_000  # steps per call (one call never passes a communication point; a healthy one takes 1-2)

    def __init__(self, model: OdeModel, t0: float, rtol: float, max_step: float, method: str = "DOP853") -> None:
        self.method = method
        self.label = "DOPRI5 (SciPy's RK45)" if method == "RK45" else method  # in its messages
        self.model = model
        self.rtol = rtol
        self.max_step = max_step
        self.n = model.nx
        self.error: BaseException | None = None
        self._x = np.zeros(self.n)
        self._dx = (c_double * max(self.n, 1))()
        self._dx_np = np.ctypeslib.as_array(self._dx)[: self.n]
        self._xbuf = (c_double * max(self.n, 1))()  # states handed to the model (a copy: cheaper than a pointer)
        self._xbuf_np = np.ctypeslib.as_array(self._xbuf)[: self.n]
        self._nom = (c_double * max(self.n, 1))()
        self._z = (c_double * max(model.nz, 1))()
        self._z_np = np.ctypeslib.as_array(self._z)[: model.nz]
        self._h_last: float | None = None
        self.reset(t0)

    def _fun(self, t: float, x: np.ndarray) -> np.ndarray:
        self._xbuf_np[:] = x
        self.model.rhs(t, self._xbuf, self._dx)
        return self._dx_np.copy()

    def _indicators(self, t: float, x: np.ndarray) -> np.ndarray:
        m = self.model
        m.set_time(t)
        if self.n:
            self._xbuf_np[:] = x
            m.set_x(self._xbuf)
        m.get_z(self._z)
        return self._z_np.copy()

    def reset(self, t: float) -> None:
        self.t = t
        if self.n:
            buf = (c_double * self.n)()
            self.model.get_x(buf)
            self._x = np.array(buf[:], dtype=float)
            self.model.get_nominals(self._nom)
            self._atol = self.rtol * np.abs(np.array(self._nom[: self.n]))
        self._solver = None  # built lazily: its bound is the next stop time
        self._z_prev = self._indicators(t, self._x) if self.model.nz else None

    def _start(self, t_stop: float) -> None:
        import scipy.integrate  # lazy: --help loads this module without it

        first = None if self._h_last is None else min(self._h_last, t_stop - self.t)
        self._solver = getattr(scipy.integrate, self.method)(self._fun, self.t, self._x, t_stop, rtol=self.rtol, atol=self._atol,
                              max_step=self.max_step, first_step=first)

    def advance(self, t_stop: float) -> tuple[float, bool]:
        if self.n == 0:
            return self._advance_discrete(t_stop)
        s = self._solver
        if s is None or s.t_bound != t_stop:
            if s is not None:  # continue the same integration towards a new bound
                self.t, self._x = s.t, s.y
            self._start(t_stop)
            s = self._solver
        steps = 0
        while s.t < t_stop:
            t_old = s.t
            msg = s.step()
            if s.status == "failed":
                raise IntegratorError(f"{self.label} failed at t = {t_old:.9g} s: {msg}")
            steps += 1
            if steps > self.MAX_NUM_STEPS:
                raise IntegratorError(
                    f"{self.label} took {self.MAX_NUM_STEPS} steps without reaching t = {t_stop:.9g} s (at t = {s.t:.9g} s, "
                    f"step {s.step_size:.3g} s): the model is stiff or diverging (solver: cvode handles stiff models)")
            self._h_last = s.h_abs  # the step size it proposes next: where the next start begins
            if self.model.nz:
                z = self._indicators(s.t, s.y)
                zero = self._z_prev == 0
                if zero.any():  # an indicator sitting on zero (just after its event): its sign is the one it
                    # takes when it leaves zero, as in CVode, probed just after the step's start
                    t_probe = t_old + max(1e-6 * (s.t - t_old), _root_tolerance(s.t, s.t - t_old))
                    probe = self._indicators(t_probe, s.dense_output()(t_probe))
                    self._z_prev = np.where(zero, probe, self._z_prev)
                hit = _crossed(self._z_prev, z)
                if hit.any():
                    t_event = self._locate(s.dense_output(), t_old, s.t, hit)
                    x_event = s.dense_output()(t_event)
                    self._finish(t_event, x_event)
                    return float(t_event), True
                self._z_prev = z
        self._finish(s.t, s.y)
        return float(s.t), False

    def _advance_discrete(self, t_stop: float) -> tuple[float, bool]:
        """No continuous state: indicators depend on time (and held inputs) only."""
        if self.model.nz:
            z = self._indicators(t_stop, self._x)
            hit = _crossed(self._z_prev, z)
            if hit.any():
                t_event = self._locate(lambda t: self._x, self.t, t_stop, hit)
                self._finish(t_event, self._x)
                return float(t_event), True
            self._z_prev = z
        self._finish(t_stop, self._x)
        return t_stop, False

    def _locate(self, dense, t_lo: float, t_hi: float, hit: np.ndarray) -> float:
        """Earliest time in (t_lo, t_hi] where an indicator in ``hit`` has crossed, by bisection.

        Returns the right end of the final bracket (the indicator has crossed there), like CVode.
        """
        z_lo = self._z_prev
        tol = _root_tolerance(t_hi, t_hi - t_lo)
        while t_hi - t_lo > tol:
            t_mid = 0.5 * (t_lo + t_hi)
            if t_mid <= t_lo or t_mid >= t_hi:
                break
            z_mid = self._indicators(t_mid, dense(t_mid))
            if (_crossed(z_lo, z_mid) & hit).any():
                t_hi = t_mid
            else:
                t_lo, z_lo = t_mid, z_mid
        return t_hi

    def _finish(self, t: float, x: np.ndarray) -> None:
        self.t = t
        self._x = np.array(x, dtype=float)
        m = self.model
        m.set_time(t)
        if self.n:
            self._xbuf_np[:] = self._x
            m.set_x(self._xbuf)
        if self._solver is not None and (self._solver.t != t):
            self._solver = None  # stopped inside a step (an event): restart from here
        if self.model.nz:
            self._z_prev = self._indicators(t, self._x)

