"""The one place an execution is put together: a plan's components on its time grid, run by its algorithm, each
component's FMU access made (:func:`cosim.fmi.make_slave`: bound to the plan's buffers, not instantiated yet).

The run and ``check`` (:mod:`cosim.run`), the parallel offload's worker (:mod:`cosim.engine.offload`) and a warm
sweep's check of a checkpoint (:mod:`cosim.analysis.sweep`) all assemble theirs here."""

from __future__ import annotations

from typing import Sequence

from ..fmi import make_slave
from .execution import Execution
from .schema import Scenario
from .supervision import Record
from .system import SystemPlan

__all__ = ["Kind", "assemble", "assemble_scenario", "kinds_of"]

Kind = tuple[str | None, float | None, str | None, float | None]
"""How the master drives a component: (interface: co-simulation or model exchange, None for the FMU's choice;
the model-exchange integrator's rtol, solver and max_step, None for their defaults)."""


def assemble(plan: SystemPlan, grid_ns: tuple[int, int, int], multiples: Sequence[int], algorithm: str,
             kinds: Sequence[Kind], record: Record | None = None) -> Execution:
    """An execution of ``plan`` on the grid ``(start_ns, stop_ns, step_ns)``, ``multiples`` its components' step
    multiples, ``algorithm`` a registered name, ``kinds`` how each component is driven (:data:`Kind`), ``record``
    what a supervisor reads of the run (None: unsupervised). Its components are not instantiated yet."""
    ex = Execution(plan, *grid_ns, multiples, algorithm, record)
    for name, info, (interface, rtol, solver, max_step) in zip(plan.names, plan.infos, kinds):
        ex.add_slave(make_slave(name, info, interface, rtol, solver, max_step))
    return ex


def kinds_of(scenario: Scenario, names: Sequence[str]) -> list[Kind]:
    """How ``scenario`` drives its components ``names`` (:data:`Kind` each)."""
    comps = scenario.components
    return [(comps[n].interface, comps[n].rtol, comps[n].solver, comps[n].max_step) for n in names]


def assemble_scenario(plan: SystemPlan, scenario: Scenario, record: Record | None = None) -> Execution:
    """:func:`assemble` with ``scenario``'s time grid, step multiples, algorithm and component settings."""
    t = scenario.time
    return assemble(plan, (t.start_ns, t.stop_ns, t.step_ns), [scenario.components[n].step_multiple for n in plan.names],
                    scenario.algorithm, kinds_of(scenario, plan.names), record)
