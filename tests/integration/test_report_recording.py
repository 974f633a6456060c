"""``python -m cosim report RUN.mcap --recording RECORDING --map RUN=REC ...``: the run drawn against a robot recording
(per mapped signal the overlay and the residual), on the golden helix log and a SYNTHETIC ROS 2 bag made from it
(tests/recording_helpers.py: 250 Hz, noise 1e-6 m, joint names, an offset of 0.2137 s), and a CSV exported from the
log. The numbers the report prints and records are those ``compare`` computes for the same inputs (its function is
called here, not its numbers copied); bad input is one line, exit 2, and nothing written. The report without a
recording: tests/integration/test_report.py."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from figure_checks import check_png  # noqa: E402
from recording_helpers import synthetic_plant_bag  # noqa: E402

from cosim.analysis.recording_compare import compare_recording  # noqa: E402
from cosim.analysis.recording_figures import figure_key  # noqa: E402
from cosim.cli import main  # noqa: E402
from cosim.io.recordings.export import export_csv  # noqa: E402

pytestmark = pytest.mark.integration

RUN = Path(__file__).resolve().parents[1] / "golden" / "helix_ctc.mcap"  # linear delta, q in m, every 20 ms, 10 s
OFFSET_S = 0.2137  # the synthetic bag starts this long before the run (53.425 samples of 4 ms)
SIGNALS = [f"plant.q[{i}]" for i in (1, 2, 3)]
BAG_MAPS = {s: f"/joint_states.position[delta_joint_{i}]" for i, s in enumerate(SIGNALS, 1)}
STANDARD = {"path_3d", "position", "errors", "joints", "efforts"}  # the report's figures without a recording
# Figures are drawn at 120 dpi on 9 x 5.8 in: anything smaller is a broken save, anything far larger a wrong dpi.
# The text output prints RMSE and max |e| as %.4e: rounding is at most 5e-5 relative.
PRINTED_RTOL = 5e-5
# report.md prints them as %.6e: at most 5e-7 relative.
MARKDOWN_RTOL = 5e-7


def _maps_args(maps: dict[str, str]) -> list[str]:
    return [f"--map={k}={v}" for k, v in maps.items()]


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    return synthetic_plant_bag(tmp_path_factory.mktemp("bag") / "synthetic_delta", RUN, offset_s=OFFSET_S)


@pytest.fixture(scope="module")
def csv(tmp_path_factory) -> Path:
    """The golden log's plant exported as CSV (``export --csv``): a recording equal to the run."""
    out = tmp_path_factory.mktemp("csv")
    export_csv(RUN, out)
    return out / "plant.csv"


def _cosim(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    got = capsys.readouterr()
    return code, got.out, got.err


def _no_leftovers(folder: Path) -> None:
    left = [p.name for p in folder.rglob("*") if p.name.endswith(".tmp")]
    assert not left, f"temporary files left in {folder}: {left}"


def test_aligned_report_draws_each_signal_with_the_residual_compare_computes(bag, tmp_path, capsys):
    out = tmp_path / "rep"
    code, stdout, err = _cosim(capsys, "report", RUN, "--out", out, "--recording", bag, *_maps_args(BAG_MAPS),
                               "--align", "--json")
    assert code == 0, err
    rep = json.loads(stdout)
    want = {figure_key(s) for s in SIGNALS} | STANDARD
    assert set(rep["figures"]) == want, f"figures {sorted(rep['figures'])}, expected {sorted(want)}"
    for key in want:
        path = Path(rep["figures"][key])
        assert path.parent == out, f"{path} not in {out}"
        check_png(path)
    cmp = compare_recording(RUN, bag, BAG_MAPS, align=True)
    assert rep["recording"] == json.loads(json.dumps(cmp.as_dict())), \
        f"report's comparison {rep['recording']}\ncompare's {cmp.as_dict()}"
    assert abs(cmp.offset - OFFSET_S) < 20e-6, f"the offset estimated: {cmp.offset} s vs {OFFSET_S} s made"
    assert all(d.rmse > 0 for d in cmp.diffs), f"a noisy recording leaves a residual: {cmp.text()}"
    md = (out / "report.md").read_text()
    assert "## Against a recording" in md, md
    for d in cmp.diffs:
        row = next(line for line in md.splitlines() if line.startswith(f"| {d.name} | {d.reference} |"))
        rmse, peak = (float(x) for x in row.split("|")[4:6])
        assert rmse == pytest.approx(d.rmse, rel=MARKDOWN_RTOL) and peak == pytest.approx(d.max_error,
                                                                                         rel=MARKDOWN_RTOL), \
            f"report.md row {row!r} vs compare's RMSE {d.rmse}, max {d.max_error}"
        file = Path(rep["figures"][figure_key(d.name)]).name
        assert f"]({file})" in md, f"report.md does not list {file}"
    _no_leftovers(out)


def test_a_given_offset_shifts_the_recording_and_the_printed_numbers_are_compares(bag, tmp_path, capsys):
    out = tmp_path / "rep"
    code, stdout, err = _cosim(capsys, "report", RUN, "--out", out, "--recording", bag, *_maps_args(BAG_MAPS),
                               "--offset", OFFSET_S)
    assert code == 0, err
    cmp = compare_recording(RUN, bag, BAG_MAPS, offset=OFFSET_S)
    assert f"offset (recording - run) {OFFSET_S:.9g} s, given" in stdout, stdout
    for d in cmp.diffs:
        m = re.search(rf"{re.escape(d.name)} - {re.escape(d.reference)}: RMSE (\S+) m, max \|e\| (\S+) m", stdout)
        assert m, f"no line for {d.name} in:\n{stdout}"
        assert float(m[1]) == pytest.approx(d.rmse, rel=PRINTED_RTOL), f"printed RMSE {m[1]} vs compare's {d.rmse}"
        assert float(m[2]) == pytest.approx(d.max_error, rel=PRINTED_RTOL), f"printed {m[2]} vs {d.max_error}"
        check_png(out / f"recording_{d.name.replace('[', '_').rstrip(']')}.png")
    unshifted = compare_recording(RUN, bag, BAG_MAPS)
    worst = max(d.rmse for d in unshifted.diffs)
    assert worst > 100 * max(d.rmse for d in cmp.diffs), \
        f"the offset matters: RMSE {worst} unshifted vs {max(d.rmse for d in cmp.diffs)} shifted"


def test_a_csv_exported_from_the_run_leaves_a_zero_residual(csv, tmp_path, capsys):
    maps = {"plant.q[2]": "q[2]"}
    code, stdout, err = _cosim(capsys, "report", RUN, "--out", tmp_path / "rep", "--recording", csv,
                               *_maps_args(maps), "--json")
    assert code == 0, err
    signals = json.loads(stdout)["recording"]["signals"]
    assert [(s["rmse"], s["max_abs"]) for s in signals] == [(0.0, 0.0)], signals


def test_without_a_recording_the_report_is_as_before(tmp_path, capsys):
    code, stdout, err = _cosim(capsys, "report", RUN, "--out", tmp_path / "rep", "--json")
    assert code == 0, err
    rep = json.loads(stdout)
    assert "recording" not in rep and set(rep["figures"]) == STANDARD, sorted(rep)
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "recording" not in md.lower(), "report.md mentions a recording it was not given"


@pytest.mark.parametrize("argv, says", [
    (["--recording", "missing.csv", "--map=plant.q[1]=q[1]"], "missing.csv: no such file"),
    (["--recording", "{csv}", "--map=plant.q[9]=q[1]"], "no signal 'plant.q[9]'"),
    (["--recording", "{csv}", "--map=plant.q[1]=q9"], "no column 'q9'"),
    (["--recording", "{bag}", "--map=plant.q[1]=/joint_states.position[joint9]"], "no joint named 'joint9'"),
    (["--recording", "{csv}", "--map=plant.q[1]=q[1]", "--unit=plant.q[1]=deg"], "does not convert"),
    (["--recording", "{csv}", "--map=plant.q[1]=q[1]", "--offset", "100"], "no overlap"),
    (["--recording", "{csv}"], "needs --map"),
    (["--map=plant.q[1]=q[1]"], "--map: only with --recording"),
    (["--align", "--offset", "0.1"], "--align, --offset: only with --recording"),
], ids=["missing", "run-signal", "csv-column", "joint", "unit", "overlap", "no-map", "map-alone", "align-alone"])
def test_bad_input_is_one_line_exit_2_and_nothing_written(argv, says, bag, csv, tmp_path, capsys):
    out = tmp_path / "rep"
    argv = [a.format(csv=csv, bag=bag) for a in argv]
    code, stdout, err = _cosim(capsys, "report", RUN, "--out", out, *argv)
    assert code == 2 and says in err and err.count("\n") == 1 and err.startswith("error: "), \
        f"exit {code}, stderr {err!r}, expected one line with {says!r}"
    assert not out.exists(), f"{out} was made: {sorted(p.name for p in out.iterdir())}"
    _no_leftovers(tmp_path)
