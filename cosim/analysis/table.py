"""The controller table: RMSE per axis of each run, in thesis Table 5's layout, with the thesis's rows when the runs
are the thesis helix (``python -m cosim table``)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from delta.paper_data import THESIS_TABLE_5_M
from fmus import registry

from ..io.runlog import AXES, RunLog
from .tracking import ReportError, scenario_doc, tracking

__all__ = ["Table", "TableRow", "controller_table"]

_THESIS_ROBOT = "linear_delta_thesis"
_THESIS_SOURCE = "thesis Table 5 (MATLAB controller, ADAMS prototype)"


@dataclass(frozen=True)
class TableRow:
    """One row: a run's RMSE per axis (m), or the thesis's (``source`` says which)."""

    label: str
    controller: str
    plant: str
    rmse: tuple[float, float, float]  # m, x y z
    source: str  # the log's path, or _THESIS_SOURCE
    samples: int = 0

    @property
    def from_thesis(self) -> bool:
        return self.source == _THESIS_SOURCE


def _fmt_m(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{x:.3e}"


def _fmt_um(x: float) -> str:
    if not math.isfinite(x):
        return "-"
    v = x * 1e6
    return f"{v:.0f}" if v >= 100 else f"{v:.1f}" if v >= 10 else f"{v:.2f}" if v >= 0.1 else f"{v:.3g}"


@dataclass
class Table:
    """RMSE per axis per run (thesis Table 5 layout: rows = runs, columns x, y, z)."""

    rows: list[TableRow]

    def markdown(self, units: Sequence[str] = ("m", "um")) -> str:
        """The table in markdown; ``units`` picks the column groups, any of ``"m"`` and ``"um"``."""
        bad = [u for u in units if u not in ("m", "um")]
        if bad or not units:
            # Refused (correctness): a unit we do not know: the column would be a guess
            raise ReportError(f"table units must be among m, um; got {', '.join(bad) or 'none'}")
        head = ["run", "controller", "plant"] + [f"{a} ({u})" for u in units for a in AXES]
        out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for r in self.rows:
            cells = [f"**{r.label}**" if r.from_thesis else r.label, r.controller, r.plant]
            for u in units:  # the thesis's values as printed there; ours to 4 significant digits
                fmt = (lambda v: f"{v:g}") if r.from_thesis and u == "m" else _fmt_m if u == "m" else _fmt_um
                cells += [fmt(v) for v in r.rmse]
            out.append("| " + " | ".join(cells) + " |")
        notes = ["", "RMSE of the platform position, actual - reference, over the start sample and every step "
                     "of each run (as in the run's summary)."]
        if any(r.from_thesis for r in self.rows):
            notes.append(f"Rows in bold are not computed here: they are the values printed in {_THESIS_SOURCE}.")
        return "\n".join(out + notes)

    def as_dict(self) -> dict[str, Any]:
        return {"rows": [{"label": r.label, "controller": r.controller, "plant": r.plant, "source": r.source,
                          "from_thesis": r.from_thesis, "samples": r.samples,
                          "rmse_m": dict(zip(AXES, r.rmse))} for r in self.rows]}


def _describe(run: RunLog, actual_component: str) -> tuple[str, str, bool]:
    """(controller, plant, is the thesis helix) from the attached scenario."""
    _, doc = scenario_doc(run)
    comps = doc.get("components") or {}
    controller, plant, default_helix = "-", actual_component, False
    for name, c in comps.items():
        if not isinstance(c, dict):
            continue
        fmu = str(c.get("fmu") or (Path(c["path"]).name if c.get("path") else ""))  # a path: its file name
        entry = registry.REGISTRY.get(fmu)
        if entry is not None and entry.role == "controller":
            controller = entry.label
        if name == actual_component and fmu:
            fidelity = (c.get("parameters") or {}).get("model.fidelity")
            plant = fmu + (f" ({fidelity})" if fidelity else "")
        if fmu == "helix" and not c.get("parameters"):
            default_helix = True
    return controller, plant, default_helix and run.robot == _THESIS_ROBOT


def controller_table(paths: Sequence[str | Path | RunLog], thesis: bool | None = None) -> Table:
    """RMSE per axis of each run (platform position vs reference), in thesis Table 5's layout.

    Parameters
    ----------
    paths
        Run logs (paths or :class:`RunLog`), one row each, in order.
    thesis
        Append the thesis's Table 5 rows for the controllers among the thesis-helix runs (all
        three when none of them is PD, PID or CTC). ``None`` (default): when at least one run is
        the thesis helix (the default helix on ``linear_delta_thesis``).

    Raises
    ------
    CosimError
        A log cannot be read or lacks its compared signals; ReportError when a run's compared
        signals are not a platform vector x, y, z.
    """

    if not paths:
        # Refused (correctness): nothing to tabulate
        raise ReportError("controller table: no run logs given")
    rows: list[TableRow] = []
    helix_controllers: list[str] = []
    for item in paths:
        tr = tracking(item)
        if not tr.is_platform:
            # Refused (correctness): the table's columns are a platform's x, y, z: others would be mislabelled
            raise ReportError(f"{tr.run.path}: the table needs a platform vector x, y, z; the run compares "
                              f"{', '.join(tr.position.actual_names)}")
        controller, plant, is_helix = _describe(tr.run, tr.position.actual_names[0].split(".", 1)[0])
        if is_helix:
            helix_controllers.append(controller)
        st = tr.position_stats()
        rows.append(TableRow(tr.run.name, controller, plant, tuple(s.rmse for s in st), str(tr.run.path),
                             st[0].samples))
    if thesis is None:
        thesis = bool(helix_controllers)
    if thesis:
        labels = {e.variant: e.label for e in registry.find("controller") if e.variant in THESIS_TABLE_5_M}
        wanted = [k for k, label in labels.items() if label in helix_controllers]
        for key in wanted or list(labels):
            rows.append(TableRow(f"thesis Table 5, {labels[key]}", labels[key], "ADAMS prototype",
                                 tuple(THESIS_TABLE_5_M[key]), _THESIS_SOURCE))
    return Table(rows)
