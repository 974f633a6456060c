"""Number-like text (YAML 1.1 reads ``1e3`` as a string) reaches each FMU variable as its type says:
a String variable gets the text as written, a Real or an Integer the number it denotes. From
``--set``, from the scenario file and from a sweep's ``--grid``.

The FMU is the FMI 2 Feedthrough C model of ``tests/cfmus``: every ``X_output`` copies ``X_input``,
so the log shows what each input received. Values are compared exactly: 1e3 and 2e1 are exact
doubles, and text is text.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from cfmus import build
from cli_helpers import cosim

from cosim.engine.prepare import prepare
from cosim.io.runlog import read_run
from cosim.engine.overrides import apply_overrides, dotted_overrides
from cosim.engine.scenario import load_scenario
from cosim.analysis.cases import Case, parse_grid

pytestmark = pytest.mark.integration


def _scenario(tmp_path: Path, parameters: str = "{}") -> Path:
    path = tmp_path / "strings.yaml"
    path.write_text(f"""name: strings
components:
  a:
    path: "{build("Feedthrough", 2)}"
    parameters: {parameters}
time: {{stop: 0.02, step: 0.01}}
logging: {{signals: all}}
""")
    return path


def test_set_gives_a_string_input_the_text_and_numbers_the_number(tmp_path):
    out = tmp_path / "run.mcap"
    r = cosim("run", _scenario(tmp_path), "--out", out, "--quiet", "--set", "a.String_input=1e3",
              "--set", "a.Real_input=1e3", "--set", "a.Integer_input=2e1")
    assert r.returncode == 0, r.stderr
    log = read_run(out)
    for name, want in (("String", "1e3"), ("Real", 1000.0), ("Integer", 20)):
        got = log.signal(f"a.{name}_output").y[-1]
        assert got == want, f"a.{name}_output: {got!r}, expected {want!r}"


def test_scenario_file_and_set_values_as_the_variable_types_them(tmp_path):
    """A parameter written ``1e3`` in the file, or set with ``--set``, is typed by its variable."""
    path = _scenario(tmp_path, "{String_parameter: 1e3, Real_parameter: 1e3}")
    plan, _ = prepare(load_scenario(path, apply_overrides(["a.String_input=2.5e3", "a.Integer_parameter=2e1"])).structure())
    got = plan.start_values[0]
    want = {"String_parameter": "1e3", "Real_parameter": 1000.0, "String_input": "2.5e3", "Integer_parameter": 20}
    assert got == want, f"start values {got}, expected {want}"
    assert all(type(got[k]) is type(v) for k, v in want.items()), f"types of {got} vs {want}"


def test_sweep_grid_value_reaches_a_string_as_written_with_the_case_id_of_the_number(tmp_path):
    """A sweep's case (--grid, parsed as --set) is typed by the variable like --set; its id, and its
    row in results.csv, are those of the number, as before (a sweep resumed across versions)."""
    grid = parse_grid(["a.String_input=1e3", "a.Real_input=2e1"])
    case = Case({name: values[0] for name, values in grid.items()})
    assert case.id == Case({"a.String_input": 1000.0, "a.Real_input": 20.0}).id, case.values
    plan, _ = prepare(load_scenario(_scenario(tmp_path), dotted_overrides(case.values, "sweep case")).structure())
    got = plan.start_values[0]
    assert got == {"String_input": "1e3", "Real_input": 20.0}, f"start values {got}"


def test_a_later_override_written_otherwise_replaces_the_text(tmp_path):
    """Two overrides of one String parameter: the last one counts, whichever way it was written."""
    overrides = apply_overrides(["a.String_input=1e3", "components.a.parameters.String_input=abc"])
    plan, _ = prepare(load_scenario(_scenario(tmp_path), overrides).structure())
    assert plan.start_values[0] == {"String_input": "abc"}, plan.start_values[0]
