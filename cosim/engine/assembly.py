"""The one place an execution is put together: a plan's components on its time grid, run by its algorithm, each
component's FMU access made (:func:`cosim.fmi.make_slave`: bound to the plan's buffers, not instantiated yet), or a
recording component's replay (its description's ``slave(name)``).

The run and ``check`` (:mod:`cosim.run`), the parallel offload's worker (:mod:`cosim.engine.offload`) and a warm
sweep's check of a checkpoint (:mod:`cosim.analysis.sweep`) all assemble theirs here."""

from __future__ import annotations

from typing import Sequence

from ..fmi import make_slave
from .execution import Execution
from .structure import SystemStructure
from .supervision import Record
from .system import SystemPlan

__all__ = ["Kind", "assemble", "assemble_structure"]

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
        replayed = getattr(info, "slave", None)  # no FMU: a recording's replay (cosim.engine.plugins.recording_source)
        ex.add_slave(replayed(name) if replayed is not None else make_slave(name, info, interface, rtol, solver,
                                                                            max_step))
    return ex


def assemble_structure(plan: SystemPlan, structure: SystemStructure, record: Record | None = None) -> Execution:
    """:func:`assemble` with ``structure``'s time grid, step multiples, algorithm and component settings."""
    comps = [structure.components[n] for n in plan.names]
    return assemble(plan, (structure.start_ns, structure.stop_ns, structure.step_ns),
                    [c.step_multiple for c in comps], structure.algorithm,
                    [(c.interface, c.rtol, c.solver, c.max_step) for c in comps], record)
