"""Identified model files (cosim.robot.model_file) and the scenario's ``model:`` key."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.robot.model_file import read_model_file, system_model, write_model_file
from cosim.engine.scenario import load_scenario, parse_scenario
from cosim.errors import ScenarioError

ROOT = Path(__file__).resolve().parents[2]

SCENARIO = """
name: s
robot: linear_delta_thesis
model: {model}
components:
  ctl: {{fmu: linear_ctc}}
time: {{stop: 0.01, step: 0.001}}
"""


def _write(path: Path, robot: str = "linear_delta_thesis", **params: float) -> Path:
    write_model_file(path, robot, params or {"model.w_inertia": 0.35, "model.w_gravity": 0.5},
                     {"trajectories": ["pick_place"]}, {"pick_place": {"rms_rel": 0.05}}, "python -m cosim test")
    return path


def test_round_trip_keeps_parameters_and_the_command(tmp_path):
    path = _write(tmp_path / "m.yaml")
    model = read_model_file(path)
    assert model.robot == "linear_delta_thesis", model
    assert model.parameters == {"model.w_inertia": 0.35, "model.w_gravity": 0.5}, model.parameters
    assert model.fitted_on == {"trajectories": ["pick_place"]} and model.fit["pick_place"]["rms_rel"] == 0.05
    assert "# Written by: python -m cosim test" in path.read_text(), path.read_text()
    assert [p.name for p in tmp_path.iterdir()] == ["m.yaml"], "the temporary file of the atomic write is left"


@pytest.mark.parametrize("text,expected", [
    ("format: other\n", "format must be"),
    ("format: cosim-identified-model/1\nrobot: linear_delta_thesis\nparameters: {mass.rod: 0.2}\n",
     "unknown parameter 'mass.rod'"),
    ("format: cosim-identified-model/1\nrobot: linear_delta_thesis\nparameters: {model.w_inertia: 1.5}\n",
     "must be a number in [0, 1]"),
    ("format: [\n", "not a YAML file"),
])
def test_bad_files_are_one_line_naming_the_file(tmp_path, text, expected):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ScenarioError) as err:
        read_model_file(path)
    message = str(err.value)
    assert expected in message and str(path) in message and "\n" not in message, message


def test_scenario_model_path_is_relative_to_the_scenario_file(tmp_path):
    (tmp_path / "models").mkdir()
    _write(tmp_path / "models" / "m.yaml")
    scenario_path = tmp_path / "s.yaml"
    scenario_path.write_text(SCENARIO.format(model="models/m.yaml"))
    scenario = load_scenario(scenario_path)
    assert system_model(scenario.structure()).parameters["model.w_inertia"] == 0.35, system_model(scenario.structure())


def test_scenario_refuses_a_model_of_another_robot_and_a_missing_file(tmp_path):
    _write(tmp_path / "rot.yaml", robot="rotary_delta_prototype")
    scenario_path = tmp_path / "s.yaml"
    scenario_path.write_text(SCENARIO.format(model="rot.yaml"))
    with pytest.raises(ScenarioError, match="identified for rotary_delta_prototype.*robot is linear_delta_thesis"):
        load_scenario(scenario_path)
    scenario_path.write_text(SCENARIO.format(model="nowhere.yaml"))
    with pytest.raises(ScenarioError, match=r"s.yaml:4: model: identified model .*nowhere.yaml: no such file \(write one with"):
        load_scenario(scenario_path)


def test_a_model_needs_a_robot():
    text = SCENARIO.format(model="m.yaml").replace("robot: linear_delta_thesis\n", "")
    with pytest.raises(ScenarioError, match="an identified model needs 'robot'"):
        parse_scenario(text)


@pytest.mark.parametrize("name", ["helix_ctc", "pick_place_ctc", "rotary_pick_place_ctc"])
def test_shipped_ctc_scenarios_use_their_committed_identified_model(name):
    scenario = load_scenario(ROOT / "scenarios" / f"{name}.yaml")
    model = system_model(scenario.structure())
    assert model is not None and model.robot == scenario.robot, (name, model)
    assert set(model.parameters) == {"model.w_inertia", "model.w_gravity", "model.w_rotation"}, model.parameters
    assert model.parameters["model.w_rotation"] == 1.0, "identified with the rods' rotational inertia"
    header = Path(model.path).read_text().splitlines()[1]
    assert header.startswith("# Written by: python -m cosim validate-model --robot " + scenario.robot), header


def test_thesis_scenario_keeps_the_thesis_split():
    scenario = load_scenario(ROOT / "scenarios" / "helix_ctc_thesis.yaml")
    assert scenario.model is None and "model.w_inertia" not in scenario.components["ctl"].parameters, scenario


def test_a_model_file_whose_aliases_expand_past_the_limit_is_refused_before_it_expands(tmp_path):
    """A model file is outside input like a scenario: the same bounded reader (nine levels of nine aliases are 387
    million values)."""
    lines = ["a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 10)]
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text("\n".join(lines) + "\n")
    with pytest.raises(ScenarioError, match=r"bomb.yaml.*expands to more than 200000 values"):
        read_model_file(bomb)


def test_a_model_file_larger_than_any_model_is_refused_unread(tmp_path):
    from cosim.errors import ScenarioError
    from cosim.robot.model_file import MAX_MODEL_BYTES

    big = tmp_path / "big.yaml"
    with open(big, "wb") as f:  # sparse: the size is there, the bytes are not
        f.truncate(3 * 2 ** 30)
    try:
        read_model_file(big)
    except ScenarioError as exc:
        assert f"larger than {MAX_MODEL_BYTES // 2 ** 10} kB" in str(exc) and "big.yaml" in str(exc), str(exc)
    else:
        raise AssertionError("a 3 GiB model file was accepted")
