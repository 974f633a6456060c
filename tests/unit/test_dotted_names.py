"""Overrides by dotted name (``--set NAME=VALUE``, :mod:`cosim.api`): resolution, close matches,
typed trajectory parameters (pure, no FMUs)."""

import pytest

from cosim.errors import ScenarioError
from cosim.engine.overrides import apply_overrides, dotted_overrides, resolve_name
from cosim.engine.scenario import parse_scenario

TEXT = """name: t
robot: linear_delta_thesis
trajectory: {type: helix, params: {rx: 0.1}}
components:
  traj: {path: a.fmu}
  plant: {path: c.fmu}
  ctl: {path: b.fmu, parameters: {gain.kp: [1, 2, 3]}}
connections:
  - {from: traj.y, to: ctl.u}
time: {stop: 1.0, step: 0.001}
"""
DATA = {"components": {"traj": {}, "ctl": {}}}


@pytest.mark.parametrize("name, path", [
    ("ctl.gain.kp[1]", ("components", "ctl", "parameters", "gain.kp[1]")),
    ("trajectory.params.rx", ("trajectory", "params", "rx")),
    ("time.stop", ("time", "stop")),
    ("algorithm", ("algorithm",)),
    ("components.ctl.parameters.gain.kp[1]", ("components", "ctl", "parameters", "gain.kp[1]")),
    ("regression.tolerances.plant.p", ("regression", "tolerances", "plant.p")),
])
def test_names_resolve_to_key_paths(name, path):
    assert resolve_name(name, DATA) == path, (name, resolve_name(name, DATA), path)


@pytest.mark.parametrize("name, expected", [
    ("ctll.gain", "unknown name 'ctll'; did you mean ctl?"),
    ("trajectory.parms.rx", "unknown name 'trajectory.parms'; did you mean trajectory.params?"),
    ("time.stp", "did you mean time.stop, time.step"),
    ("ctl", "'ctl' is a component: name one of its parameters"),
    ("time.stop.x", "time.stop is a value, it has no 'x'"),
])
def test_unknown_names_are_one_line_with_close_matches(name, expected):
    with pytest.raises(ScenarioError) as exc:
        resolve_name(name, DATA, f"--set {name}=1")
    msg = str(exc.value)
    assert expected in msg and "\n" not in msg and msg.startswith(f"--set {name}=1: "), msg


def test_set_reaches_trajectory_time_and_parameters():
    s = parse_scenario(TEXT, "x.yaml", apply_overrides(["trajectory.params.rx=0.05", "time.stop=0.5",
                                                        "ctl.gain.kp[1]=4e4"]))
    assert s.trajectory.params["rx"] == 0.05, s.trajectory.params
    assert s.time.stop == 0.5, s.time
    assert s.components["ctl"].parameters["gain.kp[1]"] == 4e4, s.components["ctl"].parameters


def test_api_overrides_take_python_values():
    s = parse_scenario(TEXT, "x.yaml", dotted_overrides({"ctl.gain.kp": [4.0, 5.0, 6.0], "time.step": 0.002}))
    assert s.components["ctl"].parameters["gain.kp"] == [4.0, 5.0, 6.0], s.components["ctl"].parameters
    assert s.time.step_ns == 2_000_000, s.time.step_ns


def test_trajectory_parameters_are_typed_and_named():
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(TEXT, "x.yaml", apply_overrides(["trajectory.params.radius=1"]))
    msg = str(exc.value)
    assert msg == ("--set trajectory.params.radius=1: helix has no parameter 'radius'; "
                   "valid: centre, rx, ry, omega, z0, vz, duration"), msg
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(TEXT.replace("rx: 0.1", "rx: abc"), "x.yaml")
    assert "x.yaml:3: trajectory.params.rx: Input should be a valid number" in str(exc.value), str(exc.value)


def test_schema_types_trajectory_parameters_per_type():
    from cosim.engine.schema import scenario_json_schema

    schema = scenario_json_schema()
    helix = schema["$defs"]["helix_parameters"]
    assert helix["additionalProperties"] is False and "rx" in helix["properties"], helix
    branches = schema["$defs"]["TrajectorySpec"]["allOf"]
    kinds = [b["if"]["properties"]["type"]["const"] for b in branches]
    assert kinds == ["helix", "pick_and_place", "point_to_point", "waypoints"], kinds


# --------------------------------------------------------------------------- names as SSP allows them

QUOTED = {"components": {"DP Controller": {}, "Ship.Engine": {}, "a=b": {}, "ctl": {}}}


@pytest.mark.parametrize("name, path", [
    ("DP Controller.gain.kp", ("components", "DP Controller", "parameters", "gain.kp")),
    ("'DP Controller'.gain.kp", ("components", "DP Controller", "parameters", "gain.kp")),
    ("'Ship.Engine'.rpm", ("components", "Ship.Engine", "parameters", "rpm")),
    ("components.'Ship.Engine'.step_multiple", ("components", "Ship.Engine", "step_multiple")),
    ("'it\\'s'.x", None),
])
def test_quoted_component_names_resolve(name, path):
    data = {"components": {**QUOTED["components"], "it's": {}}}
    want = path or ("components", "it's", "parameters", "x")
    assert resolve_name(name, data) == want, (name, resolve_name(name, data), want)


def test_unquoted_dotted_component_name_is_refused_with_the_quoted_spelling():
    with pytest.raises(ScenarioError) as exc:
        resolve_name("Ship.Engine.rpm", QUOTED, "--set Ship.Engine.rpm=1")
    assert "\n" not in str(exc.value) and "'Ship.Engine'" in str(exc.value), str(exc.value)


def test_set_splits_after_a_quoted_name_and_refuses_an_open_quote():
    ov = apply_overrides(["'a=b'.k=3", "DP Controller.gain.kp=2"])
    assert ov == {("<dotted name>", "'a=b'.k"): 3, ("<dotted name>", "DP Controller.gain.kp"): 2}, ov
    with pytest.raises(ScenarioError) as exc:
        apply_overrides(["'Ship.Engine.rpm=1"])
    assert "no closing quote" in str(exc.value), str(exc.value)


def test_names_round_trip_through_quote_and_split():
    from cosim.engine.names import quote, ref, split_ref

    for name in ["ctl", "DP Controller", "Ship.Engine", "it's", "a\\b", "'q'", "x=y"]:
        assert split_ref(ref(name, "p.x[1]"))[:2] == (name, "p.x[1]"), (name, ref(name, "p.x[1]"))
    assert quote("DP Controller") == "DP Controller" and quote("Ship.Engine") == "'Ship.Engine'"


def test_component_names_with_spaces_load_and_control_characters_do_not():
    text = TEXT.replace("ctl:", "DP Controller:").replace("to: ctl.u", "to: DP Controller.u")
    s = parse_scenario(text, "x.yaml", apply_overrides(["'DP Controller'.gain.kp[1]=4"]))
    assert s.components["DP Controller"].parameters["gain.kp[1]"] == 4, s.components["DP Controller"]
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(TEXT.replace("ctl:", '"c\\tl":'), "x.yaml")
    assert "control character" in str(exc.value), str(exc.value)
