"""Model exchange: the master integrates the FMU (one continuous integration across communication points,
re-started only after an event or an input change; time, state and step events; event iteration; termination),
as FMPy's and OMSimulator's loops do it; the numerics live in :mod:`cosim.fmi.integrators` and, in C,
:mod:`cosim.fmi.me_c`.

This module owns the protocol. With a C integrator (``cvode``, ``dopri5`` where a compiler is) each advance is one
C call that makes every FMU call of the integration (derivatives, event indicators, completedIntegratorStep) and
returns the time reached and whether a state event or a step event stopped it; the events are handled here, in
Python. Where the inputs are all continuous reals and no time event falls in the step, the whole macro step is
one C call (:class:`~cosim.fmi.me_c.MacroStep`: inputs that changed, advance, outputs), and where no event can
arise in it at all, it is a turn of the master's loop in C (:meth:`ModelExchange.c_turn`). Python is then entered
once per macro step, or not at all, plus once per event."""

from __future__ import annotations

import ctypes
import math
from ctypes import c_double
from typing import Any, Callable

from ..errors import CosimError, FMIError
from .integrators import make_integrator
from .me_c import FAILED, STEP_ADVANCE, STEP_EVENT, STEP_GET, STEP_SET, MacroStep, make_c_integrator
from .slave import Terminated
from .turn import DERIVATIVES, STATES, TIME, Exchange, Finite, make_rhs

QUIET_COMPLETERS = ("delta-cosim fmus.native",)  # generationTool prefixes: completedIntegratorStep never asks for
# event mode (ModelExchange.c_turn); a string of the FMU's model description, no import of the FMU builder
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
    _c_step: Any = None  # the C macro step (cosim.fmi.me_c.MacroStep; None: the Python loop)
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

    def c_functions(self) -> dict:
        """The FMU's functions for the C integrators of :mod:`cosim.fmi.me_c` (addresses), as :meth:`rhs`,
        :meth:`get_z` and :meth:`_completed_step` call them, and the ctypes prototype to call C through (the
        GIL handling of the FMU's other calls)."""
        dll = self.fmu.dll

        def address(name: str) -> int:
            return ctypes.cast(getattr(dll, name), ctypes.c_void_p).value

        return {"fmi": self.fmi, "instance": self._c, "needs_completed": self._needs_completed,
                "set_time": address(self._name_set_time), "get_x": address(self._name_get_x),
                "set_x": address(self._name_set_x), "get_dx": address(self._name_get_dx),
                "get_z": address(self._name_get_z) if self.nz else None,
                "get_nominals": address(self._name_get_nom),
                "completed": address(self._completed_name) if self._needs_completed else None,
                "prototype": lambda f: self._prototype(f, None)}

    def c_failed(self, call: str, status: int, t: float, dx) -> None:
        """Raise for the FMI call (a key of :meth:`c_functions`) that ended a C integrator's advance at time
        ``t``, as the same call made from Python raises; ``dx``: the derivatives when they were not finite."""
        self.time = t
        if call == "get_dx" and status <= 1:
            self._non_finite_dx(dx)
        names = {"set_time": self._name_set_time, "get_x": self._name_get_x, "set_x": self._name_set_x,
                 "get_dx": self._name_get_dx, "get_z": self._name_get_z, "get_nominals": self._name_get_nom,
                 "completed": self._completed_name}
        self._check(max(status, 2), names[call])

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
        self.integrator = make_c_integrator(self.solver, self, self.time, self.rtol, self.max_step) or \
            make_integrator(self.solver, self, self.time, self.rtol, self.max_step)
        self._bind_step()

    def set_inputs(self) -> None:
        if not self._continuous:
            super().set_inputs()  # initialization mode: plain setting
            return
        self._pull_applied()
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
        self._push_applied()
        self._restart = True

    # -- state: the FMU's, and the master's event bookkeeping beside it (cosim.fmi.slave.Base.save_state)
    def _extra_state(self) -> dict:
        self._pull_applied()
        return {"next_event": self.next_event, "events": self.events,
                "applied": [b.applied.hex() if isinstance(b.applied, bytes) else b.applied for b in self.in_bufs]}

    def _restore_extra(self, extra: dict) -> None:
        """After the FMU's state is back: its event bookkeeping, and the integrator re-started at the restored
        time on the next step (its multistep history belongs to the abandoned future)."""
        self.next_event = extra["next_event"]
        self.events = extra["events"]
        for b, applied in zip(self.in_bufs, extra["applied"]):
            b.applied = bytes.fromhex(applied) if isinstance(applied, str) else applied
        self._push_applied()
        self.event_log.clear()
        self.restart()

    def restart(self) -> None:
        """Re-start the integrator at the next step: a run that writes a checkpoint does, as the run resumed from it
        must (an integrator's multistep history is not part of the FMU's state), so the two continue alike. (A C
        integrator is told at once, a loop in C steps it without this class's Python; it forgets its step size,
        as a resumed run's new one has none.)"""
        self._restart = True
        if self._c_step is not None:
            self.integrator.reset(self.time)
        forget = getattr(getattr(self, "integrator", None), "forget", None)
        if forget is not None:
            forget()

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

    # -- the macro step in one C call (cosim.fmi.me_c.MacroStep), where the integrator is a C one
    def bind(self, inputs, outputs) -> None:
        super().bind(inputs, outputs)
        self._c_step = None  # it points into the buffers: bound again after initialization

    def _bind_step(self) -> None:
        """After the integrator is made: the C macro step, for an FMU whose inputs are all continuous reals and
        whose exchanges are numbers only (any other input change is an event, or goes through fmpy)."""
        self._c_step = None
        bufs = (*self.in_bufs, *self.out_bufs)
        if not getattr(self.integrator, "completes", False) or any(b.ctype_free for b in bufs) or \
                any(v.variability != "continuous" for b in self.in_bufs for v in b.variables):
            return
        dll = self.fmu.dll

        def exchanges(bufs: list, direction: str) -> list:
            return [Exchange(ctypes.cast(getattr(dll, b.function), ctypes.c_void_p).value, ctypes.addressof(b.vrs),
                             b.n, ctypes.addressof(b.values), b.size) for b in self._bound(bufs, direction)]

        finite = [Finite(ctypes.addressof(b.values), b.size, b.fmi_type == "Float32") for b in self._finite_bufs]
        self._c_step = MacroStep(self.integrator, exchanges(self.in_bufs, "Set"), exchanges(self.out_bufs, "Get"),
                                 finite, [ctypes.sizeof(b.values) for b in self.in_bufs])
        self._push_applied()

    def _pull_applied(self) -> None:
        """The C macro step's record of the inputs last set into the buffers' (the Python path reads those)."""
        if self._c_step is not None:
            for b, applied in zip(self.in_bufs, self._c_step.applied):
                b.applied = bytes(applied)[: ctypes.sizeof(b.values)]

    def _push_applied(self) -> None:
        """The buffers' record of the inputs last set into the C macro step's."""
        if self._c_step is not None:
            for b, applied in zip(self.in_bufs, self._c_step.applied):
                ctypes.memmove(applied, b.applied, len(b.applied))

    def set_step_get(self, t: float, h: float) -> None:
        """One Gauss-Seidel turn: in one C call where the FMU has a C macro step and no time event falls inside
        the step (an event met on the way is handled here, from the time it was met), else as the base class."""
        c_step = self._c_step
        t_end = t + h
        tol = 100.0 * 2.220446049250313e-16 * max(1.0, abs(t_end))  # as step()
        t_next = self.next_event
        if c_step is None or not self._continuous or (t_next is not None and t_next <= t_end + tol):
            super().set_step_get(t, h)
            return
        if self._restart or abs(self.time - t) > tol:
            self.time = t
            self.integrator.reset(t)
            self._restart = False
        ended = c_step(t, t_end)
        if ended:
            self._step_ended(ended, t, t_end, tol)
        self.time = t_end

    def c_turn(self) -> tuple[Any, bool] | None:
        """For a loop in C (``cosim.engine.cloop``): the C macro step as a turn, and whether its calls run Python
        (a PythonFMU: called with the Python lock held); None where an event could arise in the step (event
        indicators, a pending time event, a completedIntegratorStep that may ask for event mode): a loop in C
        cannot stop inside a macro step for an event iteration, so those take the Python loop.
        terminateSimulation from completedIntegratorStep ends the run as in the Python loop."""
        if self._c_step is None or not self._continuous or self.nz or self.next_event is not None or \
                self._needs_completed and not self._completes_quietly:
            return None
        fmu = self.integrator.fmu  # the time the FMU's log messages are stamped with in a loop in C (Base._on_log)
        self._t = c_double.from_address(ctypes.addressof(fmu) + type(fmu).t_now.offset)
        self._t.value = self.time
        return self._c_step.turn(), self._pythonfmu

    @property
    def _completes_quietly(self) -> bool:
        """Whether the FMU's completedIntegratorStep is known never to ask for event mode: the native build of
        this project (its generationTool; its completedIntegratorStep only checks the accepted state). Any other
        FMU that needs the call may ask (a step event) and takes the Python loop, which handles it."""
        return (self.info.md.generationTool or "").startswith(QUIET_COMPLETERS)

    def turn_failed(self, ended: int, t: float, h: float) -> None:
        """Raise for a C turn (:meth:`c_turn`) from ``t`` over ``h`` that a loop in C ran and that ended early, as
        :meth:`set_step_get` raises."""
        t_end = t + h
        how = self._c_step.state.ended
        fmu = self.integrator.fmu
        if how == STEP_EVENT and not fmu.terminate:  # c_turn offers no turn where an event could arise
            raise CosimError(f"{self.name}: {self._completed_name} asked for event mode at t = {t_end} s in the "
                             "master's loop in C, which cannot stop inside a macro step: its generationTool promised "
                             "it never would")
        self._step_ended(how, t, t_end, 100.0 * 2.220446049250313e-16 * max(1.0, abs(t_end)))

    def _step_ended(self, ended: int, t: float, t_end: float, tol: float) -> None:
        """Go on from a C macro step that ended early: raise as the Python path raises, or handle the event met
        and integrate on in Python."""
        index = self._c_step.state.index
        status = self.integrator.fmu.status
        if ended == STEP_SET:
            self.time = t
            self._check(status, self.in_bufs[index].function)
        if ended in (STEP_ADVANCE, STEP_EVENT):
            reached = self._advance(t_end, FAILED if ended == STEP_ADVANCE else index)
            self._integrate(t_end, tol, reached)
            self.time = t_end
            self.get_outputs()
            return
        self.time = t_end
        if ended == STEP_GET:
            self._check(status, self.out_bufs[index].function)
        self._check_finite()  # STEP_NONFINITE

    MAX_EVENTS_AT_ONE_TIME = 1000  # event iterations at one instant before the FMU is called stuck

    def step(self, t: float, h: float) -> None:
        t_end = t + h
        tol = 100.0 * 2.220446049250313e-16 * max(1.0, abs(t_end))  # times closer than this coincide
        if self._restart or abs(self.time - t) > tol:
            self.time = t
            self.integrator.reset(t)
            self._restart = False
        self._integrate(t_end, tol)
        self.time = t_end

    def _advance(self, t_stop: float, ended: int | None = None) -> tuple[float, bool]:
        """The integrator's advance to ``t_stop`` (``ended``: the result of one the C macro step made); an
        integrator giving up is an FMIError naming the solver."""
        try:
            if ended is None:
                t_reached, state_event = self.integrator.advance(t_stop)
            else:
                t_reached, state_event = self.integrator.result(ended)
        except (FMIError, Terminated):
            raise
        except Exception as exc:  # the integrator gave up
            raise FMIError(self.name, f"{self.solver} integration", self.time, None, str(exc)) from None
        self.time = t_reached
        return t_reached, state_event

    def _integrate(self, t_end: float, tol: float, reached: tuple[float, bool] | None = None) -> None:
        """Integrate to ``t_end`` handling the events on the way; ``reached``: (time reached, state event) of an
        advance already made (the C macro step's, its completedIntegratorStep call included)."""
        integ = self.integrator
        completed = self._needs_completed
        completes = getattr(integ, "completes", False)  # its advance makes the completedIntegratorStep call
        same_instant = 0
        while True:
            t_next = self.next_event
            state_event = advanced = False
            if reached is not None:
                (t_reached, state_event), reached, advanced = reached, None, True
                time_event = t_next is not None and t_reached >= t_next - tol
            else:
                time_event = t_next is not None and t_next <= self.time + tol
            if not time_event and not advanced:
                if self.time >= t_end - tol:
                    break
                t_reached, state_event = self._advance(t_end if t_next is None or t_next >= t_end - tol else t_next)
                same_instant, advanced = 0, True
                time_event = t_next is not None and t_reached >= t_next - tol
            step_event = False
            if completed:
                step_event, terminate = (integ.step_event, integ.terminate) if advanced and completes \
                    else self._completed_step()
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
