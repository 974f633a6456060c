"""``cosim report`` / ``cosim table``: figures and markdown of a run, RMSE table as thesis Table 5.

One short run (1 s of the thesis helix under CTC on the analytic plant) is shared by the
tests; its own summary (``cosim.observers.recorders.ErrorObserver``, accumulated while it ran) is the
reference the numbers read back from the log must reproduce.
"""

from __future__ import annotations

import argparse
import json
import math
import re
from pathlib import Path

import pytest
from figure_checks import check_png

from cosim.errors import CosimError
from cosim.analysis.report import make_report
from cosim.analysis.table import controller_table
from cosim.analysis.tracking import ReportError
from cosim.cli.report import register
from cosim.run import run_scenario
from cosim.io.runlog import write_baseline
from cosim.engine.overrides import apply_overrides
from delta.paper_data import THESIS_TABLE_5_M

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
STOP_S = 1.0
# The log holds the same float64 samples the summary accumulated (orjson round-trips floats
# exactly); only the order of summation differs (sequential vs numpy's pairwise), which
# changes a sum of 1001 squares by a few ulps.
SUMMATION_RTOL = 1e-12
# report.md prints RMSE as %.6e (7 significant digits): rounding is at most 5e-7 relative.
MARKDOWN_RTOL = 5e-7
FIGURES = {"path_3d", "position", "errors", "joints", "efforts"}
# Figures are drawn at 120 dpi on 7.5 x 6 in and larger canvases: anything smaller is a
# broken save, anything far larger a wrong dpi.


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """(log path, RunResult) of the thesis helix under CTC on the analytic plant, 1 s."""
    out = tmp_path_factory.mktemp("run") / "helix_ctc_analytic.mcap"
    result = run_scenario(ROOT / "scenarios" / "helix_ctc_analytic.yaml", out=out,
                          overrides=apply_overrides([], STOP_S))
    assert result.status == "completed" and len(result.errors) == 3, result.as_dict()
    return out, result


def _cli(*argv: str) -> int:
    parser = argparse.ArgumentParser(prog="cosim")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(list(argv))
    return args.handler(args)


def test_report_writes_figures_and_markdown_with_the_run_summary_rmse(run, tmp_path):
    log, result = run
    rep = make_report(log, tmp_path / "rep")
    assert set(rep.figures) == FIGURES, f"figures {sorted(rep.figures)}, expected {sorted(FIGURES)}"
    for path in rep.figures.values():
        assert path.parent == tmp_path / "rep", f"{path} not in the requested directory"
        check_png(path)
    assert rep.status == "completed" and rep.robot == "linear_delta_thesis", (rep.status, rep.robot)
    assert rep.duration == pytest.approx(STOP_S, abs=1e-12), f"duration {rep.duration} s vs {STOP_S} s"
    assert len(rep.velocity) == 3, "plant.v vs traj.v_ref are logged: velocity errors expected"
    # joint space: the plant's q[i] against the IK's q_ref[i] output (preferred to the controller's input)
    assert [(j.actual, j.reference, j.unit) for j in rep.joints] == \
        [(f"plant.q[{i}]", f"ik.q_ref[{i}]", "m") for i in (1, 2, 3)], rep.joints

    text = rep.markdown.read_text()
    for fig in rep.figures.values():
        assert f"]({fig.name})" in text, f"{fig.name} not embedded in report.md"
    for ours, theirs in zip(rep.position, result.errors):
        assert (ours.actual, ours.reference) == (theirs.actual, theirs.reference)
        assert ours.samples == theirs.samples, f"{ours.name}: {ours.samples} samples vs the summary's {theirs.samples}"
        assert math.isclose(ours.rmse, theirs.rmse, rel_tol=SUMMATION_RTOL), \
            f"{ours.name}: RMSE from the log {ours.rmse!r} m vs the run's summary {theirs.rmse!r} m"
        assert ours.max_error == theirs.max_error, \
            f"{ours.name}: max error from the log {ours.max_error!r} m vs the summary {theirs.max_error!r} m"
        row = re.search(rf"^\| {ours.name} \| {re.escape(ours.actual)} - {re.escape(ours.reference)} \| "
                        r"([0-9.e+-]+) \|", text, re.M)
        assert row, f"no position row for axis {ours.name} in report.md:\n{text}"
        assert math.isclose(float(row.group(1)), theirs.rmse, rel_tol=MARKDOWN_RTOL), \
            f"{ours.name}: report.md says {row.group(1)} m, the run's summary {theirs.rmse!r} m"


def test_report_defaults_to_a_directory_next_to_the_log(run, tmp_path, capsys):
    log, _ = run
    copy = tmp_path / "copy.mcap"
    copy.write_bytes(log.read_bytes())
    assert _cli("report", str(copy), "--json") == 0
    payload = json.loads(capsys.readouterr().out)
    assert Path(payload["out_dir"]) == tmp_path / "copy_report", payload["out_dir"]
    assert (tmp_path / "copy_report" / "report.md").is_file()
    assert [a["axis"] for a in payload["position"]] == ["x", "y", "z"], payload["position"]


def test_table_rows_equal_the_run_summary_and_thesis_rows_are_labelled(run, capsys):
    log, result = run
    table = controller_table([log])
    ours, *thesis = table.rows
    assert (ours.controller, ours.plant, ours.from_thesis) == ("CTC", "linear_analytic_plant", False), ours
    for axis, got, want in zip("xyz", ours.rmse, result.errors):
        assert math.isclose(got, want.rmse, rel_tol=SUMMATION_RTOL), \
            f"{axis}: table RMSE {got!r} m vs the run's summary {want.rmse!r} m"
    # the run is the thesis helix under CTC: the thesis's CTC row comes along, marked as the thesis's
    assert [(r.label, r.from_thesis) for r in thesis] == [("thesis Table 5, CTC", True)], thesis
    assert thesis[0].rmse == THESIS_TABLE_5_M["ctc"], f"{thesis[0].rmse} vs {THESIS_TABLE_5_M['ctc']}"
    assert len(controller_table([log], thesis=False).rows) == 1

    assert _cli("table", str(log), "--units", "um") == 0
    text = capsys.readouterr().out
    assert "| x (um) | y (um) | z (um) |" in text and "x (m)" not in text, text
    assert "**thesis Table 5, CTC**" in text and "values printed in thesis Table 5" in text, text
    cells = next(line for line in text.splitlines() if line.startswith(f"| {ours.label} |")).split("|")[4:7]
    for axis, cell, want in zip("xyz", cells, result.errors):
        # 3 significant digits in the um columns
        assert math.isclose(float(cell), want.rmse * 1e6, rel_tol=5e-3), f"{axis}: {cell} um vs {want.rmse * 1e6} um"


def test_bad_inputs_give_one_line_errors_naming_the_file(run, tmp_path):
    log, _ = run
    missing = tmp_path / "nope.mcap"
    with pytest.raises(CosimError, match=re.escape(str(missing))):
        make_report(missing)
    junk = tmp_path / "junk.mcap"
    junk.write_text("not an mcap file\n")
    with pytest.raises(CosimError, match="cannot read the MCAP log"):
        _cli("table", str(junk))

    # a log without the plant channel: the scenario's compare section names plant.p
    only_traj, _ = write_baseline(log, tmp_path / "traj_only.mcap", period=0.1, components=["traj"])
    with pytest.raises(ReportError) as err:
        make_report(only_traj, tmp_path / "rep")
    text = str(err.value)
    assert "\n" not in text and str(only_traj) in text and "'plant.p.x'" in text and "actual" in text, text
    with pytest.raises(CosimError):
        _cli("report", str(only_traj), "--out", str(tmp_path / "rep"))
    with pytest.raises(ReportError, match="no run logs"):
        controller_table([])


def test_units_read_plainly_from_millimetres_to_femtometres_and_degrees():
    import numpy as np

    from cosim.analysis.figures import _scaled_unit

    # the rotary z-steps run: x and y errors at rounding level (1.6e-14 m) read as 15.7 fm, not 1.57e-5 nm
    for peak, unit, want in ((0.3, "m", "mm"), (1.6e-4, "m", "µm"), (7.5e-9, "m", "nm"), (5.5e-10, "m/s", "pm/s"),
                             (1.57e-14, "m", "fm"), (0.66, "rad", "deg"), (7.9e-4, "rad", "mdeg"), (2.0, "N", "N")):
        f, u = _scaled_unit(np.array([peak, -peak / 2]), unit)
        assert u == want and (unit == "N" or 1.0 <= peak * f < 1000.0), f"{peak} {unit}: x{f} {u}, expected {want}"
