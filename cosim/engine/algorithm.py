"""Master algorithms: one protocol, found by name in :data:`ALGORITHMS` (the scenario's ``algorithm`` choices).

An algorithm decides, for one macro step, in which order the active components read their inputs, step
and publish their outputs; the :class:`~cosim.engine.execution.Execution` owns everything around it (the
integer time grid, the multi-rate schedule, observers, stop requests, termination). Multi-rate is part of
the schedule every algorithm gets: a component with step multiple ``m`` is active at base steps ``k`` with
``k % m == 0`` and steps ``m`` base steps at once (as libcosim's decimation factors).

- :class:`GaussSeidel` (default): components run in the plan's order (sorted by the direct-feedthrough
  graph of their ModelStructure); each reads the latest outputs, those already advanced in this macro
  step included. An algebraic loop through direct feedthrough cannot be ordered: refused when planned.
- :class:`Jacobi`: every active component reads the outputs of the previous macro step (all links copied
  first, then each component's turn). Any order works; no loop check.

Adding an algorithm: a class with the three members of :class:`Algorithm`, registered in
:data:`ALGORITHMS`; the scenario schema, the plan's ordering and the error messages follow.
"""

from __future__ import annotations

import time as _time
from typing import Any, Callable, ClassVar, Protocol, Sequence


class Execution(Protocol):
    """What an algorithm uses of the run it steps (:class:`cosim.engine.execution.Execution` is one): declared
    here so that the algorithms depend on this and not on the execution, which depends on them."""

    slaves: list[Any]  # the components' FMU instances, by index
    grid: Any  # the time grid (:class:`cosim.engine.grid.Grid`)
    current: Any  # the macro step being taken
    comp_time: list[float]  # wall-clock seconds each component spent in its calls

    def turns(self) -> Any:
        """The hyper-period's turns: which components step at each of its substeps."""

    def pull(self, c: int) -> None:
        """Set component ``c``'s inputs from the outputs they are connected to."""


__all__ = ["Algorithm", "GaussSeidel", "Jacobi", "ALGORITHMS", "DEFAULT"]

MacroStep = Callable[[int, float, float], None]
"""Runs base step ``k`` (at time ``t`` s, the grid's double; ``h`` the grid's base step size from it) of the
execution: the turns of its active components, a multi-rate one's step size from the grid
(:meth:`~cosim.engine.grid.Grid.step_size`)."""


class Algorithm(Protocol):
    """What the execution needs from a master algorithm."""

    name: ClassVar[str]
    reads_this_step: ClassVar[bool]
    """A component reads outputs produced in the same macro step: the plan orders the components by
    direct feedthrough and refuses an algebraic loop."""

    def macro_step(self, ex: Execution) -> MacroStep:
        """The function that runs one macro step of ``ex`` (built once per run: the hot loop calls it).

        It records the component whose turn it is in ``ex.current`` (for the watchdog) and adds each
        component's wall time to ``ex.comp_time``."""
        ...

    def read_after_termination(self, active: Sequence[int], c_term: int) -> list[int]:
        """The components whose outputs are read when ``c_term`` ended the simulation inside a macro step
        whose active components were ``active`` (in order)."""
        ...

    def span(self, ex: Execution, active: Sequence[int], t: float, ends: Sequence[float]) -> None:
        """Part of a macro step (an event cuts it): the ``active`` components, each from ``t`` to its own
        ``ends[i]``, in this algorithm's order of exchange. Slower than :meth:`macro_step`'s loop; used only
        around events and while one is located."""
        ...


def _loop_state(ex: Execution) -> tuple[list, int, list[float], Any, Callable[[], float],
                                          Callable[[int, int, float], float]]:
    """What a macro step's loop reads, as locals: the turns of the hyper-period (:meth:`Execution.turns`), its
    length, the per-component wall times, the record of the component with the turn, the clock, the step size
    of a component from base step ``k`` at ``t`` over its multiple (:meth:`~cosim.engine.grid.Grid.step_size`)."""
    turns = ex.turns()
    return turns, len(turns), ex.comp_time, ex.current, _time.perf_counter, ex.grid.step_size


class GaussSeidel:
    """Sequential: set inputs, step, get outputs, component after component, in the plan's order."""

    name: ClassVar[str] = "gauss_seidel"
    reads_this_step: ClassVar[bool] = True

    def macro_step(self, ex: Execution) -> MacroStep:
        turns, period, ctime, current, clock, step_size = _loop_state(ex)
        turns = [[(c, moves, copies, s.set_step_get, m) for c, moves, copies, s, m in turn] for turn in turns]

        def step(k: int, t: float, h: float) -> None:
            t_prev = clock()
            for c, moves, copies, set_step_get, m in turns[k % period]:
                current[0] = c
                for d, src in moves:
                    d[:] = src
                for dv, di, sv, si in copies:
                    dv[di] = sv[si]
                set_step_get(t, h if m == 1 else step_size(k, m, t))
                now = clock()
                ctime[c] += now - t_prev
                t_prev = now

        return step

    def read_after_termination(self, active: Sequence[int], c_term: int) -> list[int]:
        return [c_term]  # those before it were read after their turn; those after it did not step

    def span(self, ex: Execution, active: Sequence[int], t: float, ends: Sequence[float]) -> None:
        current, ctime, clock = ex.current, ex.comp_time, _time.perf_counter
        t_prev = clock()
        for c, t_end in zip(active, ends):
            current[0] = c
            ex.pull(c)
            ex.slaves[c].set_step_get(t, t_end - t)
            now = clock()
            ctime[c] += now - t_prev
            t_prev = now


class Jacobi:
    """Parallel in principle: every active component reads the outputs of the previous macro step.

    The macro step first copies the previous step's outputs into every active component's input buffers
    (the links), then gives each its Gauss-Seidel turn (set its inputs, step, get its outputs: one C call,
    :meth:`~cosim.fmi.slave.CoSimulation.set_step_get`). A component's outputs read in its turn land in its
    own buffers, which no other component reads before the next macro step's copies: the values every FMU
    sees are those of "all set, all step, all read", in one call per component instead of three. The link
    copies are the master's time, not a component's."""

    name: ClassVar[str] = "jacobi"
    reads_this_step: ClassVar[bool] = False

    def macro_step(self, ex: Execution) -> MacroStep:
        turns, period, ctime, current, clock, step_size = _loop_state(ex)
        turns = [[(c, moves, copies, s.set_step_get, m) for c, moves, copies, s, m in turn] for turn in turns]

        def step(k: int, t: float, h: float) -> None:
            turn = turns[k % period]
            for _, moves, copies, _, _ in turn:  # every input from the previous step's outputs, before any turn
                for d, src in moves:
                    d[:] = src
                for dv, di, sv, si in copies:
                    dv[di] = sv[si]
            t_prev = clock()
            for c, _, _, set_step_get, m in turn:
                current[0] = c
                set_step_get(t, h if m == 1 else step_size(k, m, t))
                now = clock()
                ctime[c] += now - t_prev
                t_prev = now

        return step

    def read_after_termination(self, active: Sequence[int], c_term: int) -> list[int]:
        return list(active[: active.index(c_term) + 1]) if c_term in active else [c_term]

    def span(self, ex: Execution, active: Sequence[int], t: float, ends: Sequence[float]) -> None:
        current, slaves = ex.current, ex.slaves
        for c in active:
            current[0] = c
            ex.pull(c)
            slaves[c].set_inputs()
        for c, t_end in zip(active, ends):
            current[0] = c
            slaves[c].step(t, t_end - t)
        for c in active:
            current[0] = c
            slaves[c].get_outputs()


ALGORITHMS: dict[str, type[Algorithm]] = {a.name: a for a in (GaussSeidel, Jacobi)}
DEFAULT = GaussSeidel.name
