"""Model exchange: the master integrates the FMU (one continuous integration across communication points,
re-started only after an event or an input change; time, state and step events; event iteration; termination),
as FMPy's and OMSimulator's loops do it; the numerics live in :mod:`cosim.fmi.integrators`."""

from __future__ import annotations

import ctypes
import math
from ctypes import c_double
from typing import Any, Callable

from ..errors import FMIError
from .integrators import make_integrator
from .slave import Terminated
from .turn import DERIVATIVES, STATES, TIME, make_rhs

isfinite = math.isfinite  # a module global: one lookup less per output buffer in the hot path


# --------------------------------------------------------------------------- model exchange


class ModelExchange:
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

    def _bind_me(self, prefix: str, derivatives: str, nominals: str = "GetNominalsOfContinuousStates") -> None:
        dll = self.fmu.dll
        fn = self._hot_function
        self._name_get_x, self._name_set_x = f"{prefix}GetContinuousStates", f"{prefix}SetContinuousStates"
        self._name_get_dx, self._name_get_z = f"{prefix}{derivatives}", f"{prefix}GetEventIndicators"
        self._name_get_nom, self._name_set_time = f"{prefix}{nominals}", f"{prefix}SetTime"
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

    # -- state: the FMU's, and the master's event bookkeeping beside it (cosim.fmi.slave.Base.save_state)
    def _extra_state(self) -> dict:
        return {"next_event": self.next_event, "events": self.events,
                "applied": [b.applied.hex() if isinstance(b.applied, bytes) else b.applied for b in self.in_bufs]}

    def _restore_extra(self, extra: dict) -> None:
        """After the FMU's state is back: its event bookkeeping, and the integrator re-started at the restored
        time on the next step (its multistep history belongs to the abandoned future)."""
        self.next_event = extra["next_event"]
        self.events = extra["events"]
        for b, applied in zip(self.in_bufs, extra["applied"]):
            b.applied = bytes.fromhex(applied) if isinstance(applied, str) else applied
        self.event_log.clear()
        self._restart = True

    def restart(self) -> None:
        """Re-start the integrator at the next step: a run that writes a checkpoint does, as the run resumed from it
        must (an integrator's multistep history is not part of the FMU's state), so the two continue alike."""
        self._restart = True

    def set_values(self, values) -> None:
        """An event's changes between steps, in event mode (FMI: tunable parameters and discrete inputs change
        there), followed by the event iteration; the integrator re-starts at the next step."""
        self._enter_event_mode()
        for var, flat in values.items():
            self._set_values(var, flat, f"set {var.name} at an event")
        self.events += 1
        self.event_log.append((self.time, "input"))
        self._event_iteration()
        self._enter_continuous_mode()
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
