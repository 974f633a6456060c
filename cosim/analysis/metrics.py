"""Summary metrics of a run (the columns of a sweep's table and of the API's ``Result.metrics``)."""

from __future__ import annotations

import math

from ..engine.schema import Scenario
from ..engine.structure import SystemStructure
from ..run import RunResult

__all__ = ["metric_names", "metrics"]


def metric_names(system: SystemStructure | Scenario) -> list[str]:
    """Names of :func:`metrics`, in order: ``rmse_<axis>``..., ``max_error_<axis>``..., then the totals."""
    axes = _axes(system)
    return ([f"rmse_{a}" for a in axes] + [f"max_error_{a}" for a in axes]
            + ["rmse", "max_error", "peak_effort", "sim_time_s", "steps", "wall_time_s"])


def _axes(system: SystemStructure | Scenario) -> list[str]:
    tracking = (system if isinstance(system, SystemStructure) else system.structure()).tracking
    if tracking is None:
        return []
    actual = list(tracking.actual)
    short = [a.rsplit(".", 1)[-1] for a in actual]
    return short if len(set(short)) == len(short) else actual


def metrics(system: SystemStructure | Scenario, result: RunResult, peak: float) -> dict[str, float]:
    """Summary metrics of a run of ``system`` (a structure, or a scenario: its structure): per-axis RMSE and largest
    error of its tracked pairs (a scenario's ``compare``, signal units), their largest over the axes, the peak
    |effort| (N or N*m), simulated and wall time (s), steps."""
    out: dict[str, float] = {}
    axes = _axes(system)
    for a, e in zip(axes, result.errors):
        out[f"rmse_{a}"] = e.rmse
    for a, e in zip(axes, result.errors):
        out[f"max_error_{a}"] = e.max_error
    out["rmse"] = max((e.rmse for e in result.errors), default=math.nan)
    out["max_error"] = max((e.max_error for e in result.errors), default=math.nan)
    out["peak_effort"] = peak
    out["sim_time_s"] = result.sim_time
    out["steps"] = result.steps
    out["wall_time_s"] = result.wall_time
    return out
