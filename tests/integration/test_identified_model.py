"""A scenario's identified model reaches every model-based component of ours, and only those (issue 27)."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.engine.prepare import prepare
from cosim.robot.model_file import system_model
from cosim.engine.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.integration


def _start(scenario, name):
    plan, report = prepare(scenario.structure())
    return plan.start_values[plan.names.index(name)], report


def test_the_controller_takes_the_identified_split_and_the_exudyn_plant_does_not():
    scenario = load_scenario(ROOT / "scenarios" / "helix_ctc.yaml", {("fmus",): "python"})
    model = system_model(scenario.structure()).parameters
    ctl, report = _start(scenario, "ctl")
    for name, value in model.items():
        assert ctl.get(name) == value, (name, ctl.get(name), value)
    plant, _ = _start(scenario, "plant")
    assert not set(model) & set(plant), f"the Exudyn plant took {set(model) & set(plant)}"
    assert "identified model models/linear_delta_thesis.yaml (w_inertia = " in report, report


def test_the_analytic_plant_takes_it_and_an_explicit_parameter_wins():
    scenario = load_scenario(ROOT / "scenarios" / "helix_ctc.yaml",
                             {("fmus",): "python", ("components", "plant", "fmu"): "linear_analytic_plant",
                              ("components", "plant", "parameters"): {},
                              ("components", "ctl", "parameters", "model.w_inertia"): 0.25})
    model = system_model(scenario.structure()).parameters
    plant, _ = _start(scenario, "plant")
    assert {k: plant.get(k) for k in model} == model, (plant, model)
    ctl, _ = _start(scenario, "ctl")
    assert ctl["model.w_inertia"] == 0.25, ctl
    assert ctl["model.w_gravity"] == model["model.w_gravity"], (ctl, model)


def test_the_scenario_as_run_names_the_model_file_so_that_a_log_runs_again_from_anywhere(tmp_path):
    """The log's scenario as run (what ``run --from-log`` runs) names the identified model by its absolute path,
    as it does the FMU files: read back from another folder it finds the same model."""
    from cosim.engine.scenario import effective_scenario, scenario_from_data

    scenario = load_scenario(ROOT / "scenarios" / "helix_ctc.yaml")
    data = effective_scenario(scenario)
    assert Path(data["model"]).is_absolute() and Path(data["model"]).is_file(), data["model"]
    again = scenario_from_data(data, str(tmp_path / "elsewhere" / "run.mcap"))
    assert system_model(again.structure()).parameters == system_model(scenario.structure()).parameters
