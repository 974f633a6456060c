"""A scenario's ``parameters:`` files (the values ``calibrate --out`` writes): set over the scenario's own values and
under ``--set``, a later file over an earlier one, recorded applied in the scenario as run, and every bad file one
line naming the file, its line and where the scenario names it. No FMU is loaded here: the scenario is validated only
(an FMU's missing parameter is refused when the plan is made: tests/integration/test_recording_parameters.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.engine.overrides import apply_overrides
from cosim.engine.scenario import effective_scenario, load_scenario, scenario_from_data
from cosim.engine.schema import scenario_json_schema
from cosim.errors import ScenarioError

SCENARIO = """\
name: fitted
components:
  plant: {fmu: linear_analytic_plant, parameters: {mass.payload: 0.1, mass.platform: 1.5}}
  meas:
    recording: robot.csv
    signals: {q: q1}
    offset: 0.5
time: {stop: 1.0, step: 0.001}
parameters: %s
"""


def _scenario(tmp_path: Path, files: str, **bodies: str) -> Path:
    for name, body in bodies.items():
        (tmp_path / f"{name}.yaml").write_text(body)
    path = tmp_path / "scenario.yaml"
    path.write_text(SCENARIO % files)
    return path


def test_a_files_values_are_set_over_the_scenarios_and_under_set(tmp_path):
    path = _scenario(tmp_path, "fit.yaml", fit="# fitted\nplant.mass.payload: 0.3\ncomponents.meas.offset: 0.2137\n"
                                                "time.stop: 5e-1\n")
    sc = load_scenario(path)
    assert sc.components["plant"].parameters == {"mass.payload": 0.3, "mass.platform": 1.5}, sc.components["plant"]
    assert sc.components["meas"].offset == 0.2137 and sc.time.stop == 0.5, (sc.components["meas"], sc.time)
    sc = load_scenario(path, apply_overrides(["plant.mass.payload=0.7", "components.meas.offset=0.1"]))
    assert sc.components["plant"].parameters["mass.payload"] == 0.7 and sc.components["meas"].offset == 0.1, sc


def test_of_several_files_a_later_ones_value_wins_and_set_may_name_the_files(tmp_path):
    path = _scenario(tmp_path, "[a.yaml, b.yaml]", a="plant.mass.payload: 0.2\nplant.mass.platform: 2.0\n",
                     b="plant.mass.payload: 0.4\n")
    sc = load_scenario(path)
    assert sc.components["plant"].parameters == {"mass.payload": 0.4, "mass.platform": 2.0}, sc.components["plant"]
    sc = load_scenario(path, apply_overrides(["parameters=a.yaml"]))  # relative to the scenario's folder
    assert sc.components["plant"].parameters == {"mass.payload": 0.2, "mass.platform": 2.0}, sc.components["plant"]


def test_the_scenario_as_run_holds_the_values_applied_and_runs_the_same_without_the_files(tmp_path):
    path = _scenario(tmp_path, "fit.yaml", fit="plant.mass.payload: 0.3\ncomponents.meas.offset: 0.25\n")
    sc = load_scenario(path)
    data = effective_scenario(sc)
    assert data["parameters"] is None, data["parameters"]
    (tmp_path / "fit.yaml").unlink()  # a log's scenario runs again after the file is gone (or changed)
    again = scenario_from_data(data, str(tmp_path / "elsewhere" / "run.mcap"))
    assert again.components == sc.components and again.time == sc.time, (again.components, sc.components)
    assert effective_scenario(again) == data, "the scenario as run is a fixed point"


def test_the_schema_has_the_key_and_time_origin():
    schema = scenario_json_schema()
    assert "parameters" in schema["properties"], sorted(schema["properties"])
    component = schema["$defs"]["Component"]["properties"]
    assert component["time_origin"]["enum"] == ["first", "absolute"], component["time_origin"]


@pytest.mark.parametrize("body, message", [
    ("# c\nplant.mass.payload: {a: 1}\n", "fit.yaml:2 (a parameters file, named at {scenario}:9): plant.mass.payload: "
                                          "expected a number, a boolean, a string or a list of them, got {{'a': 1}}"),
    ("plant.mass.payload: 0.3\nnope.x: 1\n", "fit.yaml:2 (a parameters file, named at {scenario}:9): unknown name "
                                             "'nope'"),
    ("\n\ntime.stop: abc\n", "fit.yaml:3 (a parameters file, named at {scenario}:9): Input should be a valid number"),
    ("plant.mass.payload: [\n", "fit.yaml:2 (a parameters file, named at {scenario}:9): invalid YAML"),
    ("- plant.mass.payload\n", "fit.yaml:1 (a parameters file, named at {scenario}:9): expected a mapping of names "
                               "to values"),
    ("parameters: other.yaml\n", "fit.yaml:1 (a parameters file, named at {scenario}:9): a parameters file cannot "
                                 "name other parameters files"),
    ("a: 1\na: 2\n", "fit.yaml:2 (a parameters file, named at {scenario}:9): invalid YAML: duplicate key 'a'"),
])
def test_a_bad_file_is_one_line_naming_its_line_and_the_scenarios(tmp_path, body, message):
    path = _scenario(tmp_path, "fit.yaml", fit=body)
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    text = str(err.value)
    assert "\n" not in text and text.startswith(str(tmp_path / message.format(scenario=path))), text


def test_a_missing_file_is_one_line_at_the_scenarios_line_or_the_option(tmp_path):
    path = _scenario(tmp_path, "gone.yaml")
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert str(err.value) == f"{path}:9: parameters file {tmp_path / 'gone.yaml'}: no such file", str(err.value)
    with pytest.raises(ScenarioError) as err:
        load_scenario(path, apply_overrides(["parameters=[gone.yaml, also_gone.yaml]"]))
    assert str(err.value) == (f"--set parameters=[gone.yaml, also_gone.yaml] (parameters[0]): parameters file "
                              f"{tmp_path / 'gone.yaml'}: no such file"), str(err.value)
