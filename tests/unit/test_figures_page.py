"""docs/figures.md's generated tables are what benchmarks/results/*.json render (``python benchmarks/figures.py
--check``), and a benchmark's ``--json`` output carries its command, date, machine and revision."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "figures.py"
sys.path.insert(0, str(ROOT / "benchmarks"))

import record  # noqa: E402


def _figures(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *args], cwd=ROOT, capture_output=True, text=True,
                          check=False)


def test_page_is_what_its_json_renders():
    proc = _figures("--check")
    assert proc.returncode == 0, f"docs/figures.md is not what benchmarks/results renders:\n{proc.stderr}"


@pytest.fixture()
def copy(tmp_path):
    """The page and the results, copied where a test may change them."""
    shutil.copy(ROOT / "docs" / "figures.md", tmp_path / "figures.md")
    shutil.copytree(ROOT / "benchmarks" / "results", tmp_path / "results")
    return tmp_path


def _check(copy: Path) -> subprocess.CompletedProcess:
    return _figures("--check", "--page", str(copy / "figures.md"), "--results", str(copy / "results"))


def test_check_fails_on_a_figure_edited_by_hand(copy):
    page = copy / "figures.md"
    text = page.read_text(encoding="utf-8")
    cell = "| 2026-11-26, transcribed |"
    assert cell in text, "no transcribed row dated 2026-11-26 in docs/figures.md to edit"
    page.write_text(text.replace(cell, "| 2026-11-29, transcribed |", 1), encoding="utf-8")
    proc = _check(copy)
    assert proc.returncode == 1, f"--check passed a page edited by hand: {proc.returncode}, {proc.stderr}"
    assert "differs" in proc.stderr, proc.stderr


def test_check_fails_on_a_json_changed_without_rendering(copy):
    path = copy / "results" / "master_overhead.json"
    doc = json.loads(path.read_text(encoding="utf-8"))
    if doc["source"] == "measured":
        doc["figures"] = {k: v * 2 if isinstance(v, float) else v for k, v in doc["figures"].items()}
    else:
        doc["date"] = "2020-01-01"
        for row in doc["rows"].values():
            row["date"] = "2020-01-01"
    path.write_text(json.dumps(doc), encoding="utf-8")
    proc = _check(copy)
    assert proc.returncode == 1, f"--check passed a changed JSON: {proc.returncode}, {proc.stderr}"


def test_rendering_rewrites_only_the_marked_tables(copy):
    page = copy / "figures.md"
    before = page.read_text(encoding="utf-8")
    start = before.index("<!-- figures: speed")
    end = before.index("<!-- /figures: speed -->")
    page.write_text(before[:start] + before[start:end].replace("| 2x |", "| 3x |") + before[end:] + "\nprose\n",
                    encoding="utf-8")
    proc = _figures("--page", str(page), "--results", str(copy / "results"))
    assert proc.returncode == 0, proc.stderr
    assert page.read_text(encoding="utf-8") == before + "\nprose\n", "rendering changed the hand-written text"


def test_a_bad_json_is_a_one_line_error(copy):
    (copy / "results" / "broken.json").write_text('{"source": "measured", "command": "x"}', encoding="utf-8")
    proc = _check(copy)
    assert proc.returncode == 2 and "broken.json: missing date, machine, figures" in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr, proc.stderr


def test_a_missing_marker_is_named(copy):
    page = copy / "figures.md"
    page.write_text(page.read_text(encoding="utf-8").replace("<!-- /figures: sweeps -->", ""), encoding="utf-8")
    proc = _check(copy)
    assert proc.returncode == 2 and "no <!-- /figures: sweeps -->" in proc.stderr, proc.stderr


class _Args:
    record = False

    def __init__(self, json_path):
        self.json = json_path


def test_recording_carries_command_date_machine_and_revision(tmp_path):
    out = tmp_path / "bench.json"
    with record.Recording(_Args(out), "bench") as rec:
        rec.put("loop_s", 0.25)
        print("a printed figure")
    doc = json.loads(out.read_text(encoding="utf-8"))
    assert doc["figures"] == {"loop_s": 0.25}, doc["figures"]
    assert doc["source"] == "measured" and doc["command"].startswith("python "), doc["command"]
    assert doc["date"].endswith("Z") and doc["machine"]["cores"] >= 1, doc
    assert len(doc["machine"]["load_start"]) == 3 and len(doc["machine"]["load_end"]) == 3, doc["machine"]
    assert "a printed figure" in doc["printed"], doc["printed"]
    assert len(doc["revision"]["commit"] or "") == 40, doc["revision"]


def test_a_failed_benchmark_writes_nothing(tmp_path):
    out = tmp_path / "bench.json"
    with pytest.raises(RuntimeError), record.Recording(_Args(out), "bench") as rec:
        rec.put("loop_s", 0.25)
        raise RuntimeError("the benchmark failed")
    assert not out.exists() and list(tmp_path.iterdir()) == [], list(tmp_path.iterdir())


def test_logged_run_json_plugs_into_its_row(copy):
    """benchmarks/logged_run.py --json writes a flat JSON of its own: it renders into the row it will replace."""
    figures = {"loop logged s (median)": 0.25, "loop unlogged s (median)": 0.025, "ratio min": 9.5, "ratio max": 10.5,
               "ratio median": 10.0, "whole call logged s (median)": 0.5, "whole call unlogged s (median)": 0.3,
               "master logging work us/step (median)": 4.0, "blocked on writer pipe us/step (median)": 12.0,
               "writer process us/step": 14.5, "command": "python benchmarks/logged_run.py --json x.json",
               "date": "2026-11-30T01:00:00+00:00", "load": "before (1.0, 1.0, 1.0); after (1.2, 1.0, 1.0)"}
    (copy / "results" / "logged_run.json").write_text(json.dumps(figures), encoding="utf-8")
    page = copy / "figures.md"
    proc = _figures("--page", str(page), "--results", str(copy / "results"))
    assert proc.returncode == 0, proc.stderr
    row = next(line for line in page.read_text(encoding="utf-8").splitlines()
               if line.startswith("| helix_ctc_analytic on native FMUs, every signal logged"))
    assert "**not met**: 10.0x (rounds 9.5-10.5x): the loop 0.250 s logged against 0.025 s" in row, row
    assert "`python benchmarks/logged_run.py --json x.json` | 2026-11-30, before (1.0, 1.0, 1.0)" in row, row
    figures["master logging work us/step (median)"] = None  # not measured that time: printed as "-"
    (copy / "results" / "logged_run.json").write_text(json.dumps(figures), encoding="utf-8")
    proc = _figures("--page", str(page), "--results", str(copy / "results"))
    assert proc.returncode == 0, proc.stderr
    assert "the master's own logging work - us and 12.0 us blocked" in page.read_text(encoding="utf-8"), proc.stdout


def test_a_json_into_a_missing_folder_is_refused_before_the_run(tmp_path):
    out = tmp_path / "nowhere" / "bench.json"
    with pytest.raises(SystemExit) as exc:
        record.Recording(_Args(out), "bench")
    assert f"--json {out}: the folder {out.parent} does not exist" in str(exc.value), str(exc.value)


def test_a_json_no_row_renders_is_named(copy):
    doc = {"source": "measured", "command": "python benchmarks/x.py", "date": "2026-11-29T00:00:00Z",
           "machine": {"cores": 2, "load_start": [1, 1, 1], "load_end": [1, 1, 1]}, "figures": {"x": 1.0}}
    (copy / "results" / "unrendered.json").write_text(json.dumps(doc), encoding="utf-8")
    proc = _check(copy)
    assert proc.returncode == 2 and "unrendered.json: no row of benchmarks/figures_spec.py renders it" in proc.stderr, \
        proc.stderr
