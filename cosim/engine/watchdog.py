"""Watchdog: a stalled component or an unanswered stop signal ends the run, named, with the log finished.

The master calls components synchronously, so a component that never returns from a call
(an ODE solver taking ever smaller steps, a C FMU in an endless loop) stops the run loop, and
with it the between-steps check of SIGINT / SIGTERM. A daemon thread watches the run's progress
(``ex.k_done``, one macro step) and the signals:

- a step (or the initialization) that makes no progress for ``budget`` wall-clock seconds, or a
  stop signal that the run loop has not answered within ``grace`` seconds, is *fired*: the
  thread names the component and the simulation time (from the record the execution keeps of
  the component with the turn, :attr:`~cosim.engine.execution.Execution.current`) and raises an
  exception in the main thread (``PyThreadState_SetAsyncExc``). Python code, such as our pythonfmu FMUs and SciPy's
  integrators, unwinds from it at its next bytecode; the run then ends through its usual path
  (log finished and marked, worker stopped, FMUs freed), with the error replaced by the
  watchdog's (:class:`~cosim.errors.StallError`, or :class:`~cosim.errors.Interrupted`);
- code that does not return to Python (a C FMU looping inside one call) cannot be interrupted
  from Python. If the main thread has not unwound ``grace`` seconds later, the thread runs the
  ``abort`` callback: it finishes the log from this thread, stops the worker, says what
  happened and exits the process. The stuck call is abandoned, never freed.

Signals reach the thread through :func:`signal.set_wakeup_fd`, whose byte the C-level handler
writes even while the main thread is inside a C call and cannot run Python handlers.
"""

from __future__ import annotations

import ctypes
import os
import select
import signal
import sys
import threading
import time
from typing import Any, Callable

from .. import procs
from ..errors import Interrupted, StallError, exit_now, exit_status, exit_text
from . import supervision
from .offload import Proxy
from .supervision import MASTER, PHASES, WAITING

__all__ = ["Watchdog", "GRACE_S"]

GRACE_S = 2.0  # s a fired watchdog or a stop signal waits for the main thread before the hard abort


class _Abort(BaseException):
    """Raised asynchronously in the main thread; replaced by the watchdog's error when caught."""


class Watchdog:
    """Watches ``rt`` from a daemon thread (see the module docstring); use as a context manager
    in the main thread around initialization and the run loop.

    ``budget``: wall-clock seconds a step may take (None: no stall check, signals only);
    ``stop``: the run's :class:`~cosim.engine.execution.StopRequest`; ``abort(error)``: the hard
    shutdown, called from the watchdog's thread when the main thread does not unwind.
    """

    def __init__(self, rt: Any, budget: float | None, stop: Any, abort: Callable[[BaseException], None],
                 grace: float = GRACE_S):
        self.ex = rt
        self.budget = budget
        self.stop = stop
        self.abort = abort
        self.grace = grace
        self.error: BaseException | None = None  # set when fired
        self.acknowledged = threading.Event()  # the main thread caught the injected exception
        self._done = threading.Event()
        self._thread: threading.Thread | None = None
        self._main = threading.main_thread().ident
        self._rfd = self._wfd = -1
        self._previous_fd = -1
        self.lost = False  # its pipe was closed behind its back (by a component): the run says so at its end

    # -- main thread
    def __enter__(self) -> "Watchdog":
        if threading.current_thread() is not threading.main_thread():
            return self  # signals and async exceptions belong to the main thread: nothing to watch from here
        self._rfd, self._wfd = os.pipe()
        os.set_blocking(self._wfd, False)
        try:
            self._previous_fd = signal.set_wakeup_fd(self._wfd, warn_on_full_buffer=False)
        except ValueError:
            self._previous_fd = -1
        self._thread = procs.thread(self._watch, name="cosim-watchdog")
        return self

    def __exit__(self, *exc) -> None:
        self._done.set()
        self.acknowledged.set()  # the main thread runs Python again: no hard abort from here on
        if self._thread is not None:
            if self._thread is not threading.current_thread():
                try:
                    os.write(self._wfd, b"\0")  # wake its select now rather than at its next tick (up to 0.25 s)
                except OSError:  # full pipe: it is awake anyway
                    pass
                self._thread.join(1.0)
            signal.set_wakeup_fd(self._previous_fd)
            closed = [fd for fd in (self._rfd, self._wfd) if not procs.close_fd(fd)]
            self.lost = self.lost or bool(closed)
            self._thread = None

    def translate(self, exc: BaseException) -> BaseException:
        """The error to report for ``exc`` caught in the main thread: the watchdog's, once fired."""
        if self.error is None:
            return exc
        self.acknowledged.set()
        return self.error

    # -- watchdog thread
    def _watch(self) -> None:
        tick = 0.05 if self.budget is None else min(0.25, max(0.01, self.budget / 20))
        last_k, since = self.ex.k_done, time.monotonic()
        signum: int | None = None
        signalled_at = 0.0
        while not self._done.is_set():
            try:
                ready, _, _ = select.select([self._rfd], [], [], tick)
            except (OSError, ValueError):  # its pipe closed behind its back by a component: said at the run's end
                self.lost = True
                return
            now = time.monotonic()
            if ready:
                try:
                    data = os.read(self._rfd, 64)
                except OSError:  # closed by __exit__
                    return
                for b in data:
                    if b in self.stop.SIGNALS and signum is None:
                        signum, signalled_at = b, now
            if self._done.is_set():
                return
            k = self.ex.k_done
            if k != last_k or self.ex.current[2] == WAITING:  # a step done, or a wait on purpose (run --live-wait)
                last_k, since = k, now
            if signum is not None and now - signalled_at > self.grace and now - since > self.grace:
                component, t, where = self._where()
                self._fire(Interrupted(signum, f"component {component!r}{where} did not return from its step "
                                               f"at t = {t:.6g} s within {self.grace:g} s"))
                return
            if self.budget is not None and now - since > self.budget:
                component, t, where = self._where()
                self._fire(StallError(component, t, self.budget, where))
                return

    def _where(self) -> tuple[str, float, str]:
        """(component, simulation time, where it runs) of the call the main thread is in, as the execution
        records it (:attr:`~cosim.engine.execution.Execution.current`): the component with the turn and its
        own time, or the master between turns (in the initialization, or at the macro step's time)."""
        c, _, phase, steps = self.ex.current.tolist()[:4]
        c = int(c)
        if c == MASTER:  # the macro step's time: the grid's point of the steps done
            return ("(initialization)" if PHASES[int(phase)] == "initialization" else "(master)"), \
                self.ex.grid.time(min(int(steps), self.ex.n_steps)), ""
        slave = self.ex.slaves[c]
        t = self.ex.current[1] if getattr(self.ex, "in_c", False) else slave.time  # a loop in C records its time
        return slave.name, float(t), " (in the worker process)" if isinstance(slave, Proxy) else ""

    def _fire(self, error: BaseException) -> None:
        self.error = error
        ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(self._main), ctypes.py_object(_Abort))
        if self.acknowledged.wait(self.grace) or self._done.is_set():
            return
        self.abort(error)  # the main thread is stuck outside Python: finish here and leave


def hard_exit(error: BaseException, lines: list[str]) -> None:
    """Leave the process from the watchdog's thread after ``abort`` finished what it could: the error
    on stderr as the command line says it (:func:`cosim.errors.exit_status`; exit code 2 for a stall,
    128 + signal), then ``lines``; no interpreter finalisation (the main thread is still inside a
    component's call)."""
    message, kind, code = exit_status(error)
    for line in [exit_text(message, kind), *lines]:
        print(line, file=sys.stderr)
    supervision.finished(message)  # our own exit, said: the supervisor passes its code on
    exit_now(code)
