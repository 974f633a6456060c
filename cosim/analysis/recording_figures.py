"""The figures of a run against a robot recording (``report --recording``, :mod:`cosim.analysis.report`): one PNG per
mapped signal, the run's signal and the recording's on one time axis (the recording shifted by the offset, so both
read in run time) above the residual, run - recording, as ``compare`` computes it
(:func:`cosim.analysis.recording_compare.compared_traces`), with its RMSE, largest value and the offset."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from .compare import Comparison
from .figures import _auto, _error_column, _fig, _mark_events, _plain, _pretty_unit, _save
from .recording_compare import Trace
from .tracking import Pair, Tracking

__all__ = ["recording_figures", "figure_key"]


def figure_key(name: str) -> str:
    """The key of the figure of run signal ``name`` in a report's figures (``recording plant.q[1]``)."""
    return f"recording {name}"


def _file_name(name: str, taken: set[str]) -> str:
    """``plant.q[1]`` -> ``recording_plant.q_1.png`` (a second signal of the same file name gets ``_2``)."""
    stem = "recording_" + re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_")
    file, k = f"{stem}.png", 1
    while file in taken:
        k += 1
        file = f"{stem}_{k}.png"
    taken.add(file)
    return file


def recording_figures(tr: Tracking, cmp: Comparison, traces: list[Trace], title: str, out: Path
                      ) -> dict[str, Path]:
    """One figure per trace, written into ``out``: :func:`figure_key` -> PNG path. ``cmp`` is the comparison the
    traces belong to (its statistics, offset and how it was found, the recording's path)."""
    written, taken = {}, set()
    for trace, stats in zip(traces, cmp.diffs):
        written[figure_key(trace.name)] = _plot(tr, cmp, trace, stats, title, out / _file_name(trace.name, taken))
    return written


def _values_scale(unit: str) -> tuple[float, str]:
    """Signal values as the report's joint figures show them: m in mm, rad in deg, other units as logged."""
    return {"m": (1e3, "mm"), "rad": (180.0 / math.pi, "deg")}.get(unit, (1.0, _pretty_unit(unit)))


def _plot(tr: Tracking, cmp: Comparison, trace: Trace, stats, title: str, path: Path) -> Path:
    offset = float(cmp.offset or 0.0) + 0.0  # not -0
    how = cmp.offset_how.split(":", 1)[0]  # "given", or "estimated" (the details are in report.md)
    fig = _fig(9, 5.8)
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    f, unit = _values_scale(trace.unit)
    top.plot(trace.t_rec - offset, trace.y_rec * f, color="tab:blue", lw=2.5, alpha=0.45,
             label=f"recording: {trace.spec} (at t + {offset:.6g} s)")
    top.plot(trace.t_run, trace.y_run * f, color="tab:red", lw=0.9, label=f"run: {trace.name}")
    top.set_xlim(float(trace.t_run[0]), float(trace.t_run[-1]))
    top.set_ylabel(f"{trace.name} ({unit})")
    top.legend(loc="best", fontsize=8)
    _plain(top)
    top.grid(True, alpha=0.3)
    top.set_title(f"offset (recording - run) {offset:.6g} s, {how}", fontsize=9)

    # the residual drawn as the report's error figures draw an error (a start transient far above the rest off scale)
    zero = np.zeros((len(trace.t), 1))
    _error_column([bottom], Pair([trace.name], [trace.spec], trace.unit, trace.t, trace.e[:, None], zero), [stats],
                  [trace.name], "residual (run - recording)")
    tol = "" if stats.tolerance is None else (f"; tolerance {_auto(stats.tolerance, trace.unit)}: "
                                              + ("ok" if stats.ok else "exceeded"))
    bottom.set_title(f"{bottom.get_title()}; {stats.samples} run stamps{tol}", fontsize=9)
    bottom.set_xlabel("run time (s)")
    _mark_events(tr, [top, bottom])
    fig.suptitle(f"{title}: {trace.name} against the recording {Path(cmp.b).name}", fontsize=11)
    return _save(fig, path)
