"""Trajectory FMU parameters <-> delta.trajectories dataclasses, and the scenario's trajectory section
as the one source of the trajectory component's parameters (cosim.robot.preflight.trajectory_start_values)."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("pythonfmu")

from cosim.errors import ScenarioError  # noqa: E402
from cosim.robot.preflight import trajectory_start_values  # noqa: E402
from cosim.engine.overrides import apply_overrides  # noqa: E402
from cosim.engine.scenario import parse_scenario
from delta.trajectories import Helix, PickAndPlace, PointToPoint, Waypoints  # noqa: E402
from fmus.adapters.trajectories import (  # noqa: E402
    ADAPTERS,
    HelixTrajectory,
    PickAndPlaceTrajectory,
    PointToPointTrajectory,
    WaypointsTrajectory,
)

# every field differs from its default, so a field the mapping dropped or swapped shows up
NON_DEFAULT = [
    (HelixTrajectory, Helix(centre=(0.01, -0.02), rx=0.07, ry=0.05, omega=2.0, z0=-0.5, vz=0.003, duration=4.0)),
    (PointToPointTrajectory, PointToPoint(start=(0.01, 0.02, -0.45), end=(-0.03, 0.04, -0.52), duration=0.7,
                                          profile="cubic", t0=0.2)),
    (PickAndPlaceTrajectory, PickAndPlace(start=(-0.1, 0.01, -0.48), up=0.02, across=0.2, down=0.03,
                                          cycle_time=0.8, direction=(0.6, 0.8), cycles=3, profile="cubic")),
    (WaypointsTrajectory, Waypoints(points=((0.0, 0.0, -0.4), (0.05, 0.0, -0.5), (0.0, 0.05, -0.45),
                                            (0.01, 0.02, -0.42)), segment_time=0.6, dwell=0.25, profile="cubic")),
]


@pytest.mark.parametrize("cls,trajectory", NON_DEFAULT, ids=lambda x: getattr(x, "__name__", ""))
def test_parameters_round_trip(cls, trajectory):
    # exact: the mapping copies floats, so the round trip must not change a bit
    values = cls.parameters_of(trajectory)
    assert set(values) == {p.name for p in cls.PARAMS}, f"{sorted(values)} vs {sorted(p.name for p in cls.PARAMS)}"
    back = cls.from_parameters(values)
    assert back == trajectory, f"{back} vs {trajectory}"


@pytest.mark.parametrize("cls", list(ADAPTERS.values()), ids=lambda c: c.__name__)
def test_defaults_round_trip(cls):
    back = cls.from_parameters(cls.parameters_of(cls.DEFAULT))
    assert back == cls.DEFAULT, f"{back} vs {cls.DEFAULT}"


def test_parameter_kinds_and_units():
    by_name = {p.name: p for p in PickAndPlaceTrajectory.PARAMS}
    values = PickAndPlaceTrajectory.parameters_of(PickAndPlace(start=(0.0, 0.0, -0.5), cycles=2))
    assert type(values["cycle.count"]) is int, f"{type(values['cycle.count'])} vs int"
    assert values["cycle.profile"] == "quintic", f"{values['cycle.profile']!r} vs 'quintic'"
    assert by_name["cycle.start.x"].unit == "m", f"{by_name['cycle.start.x'].unit} vs m"
    assert HelixTrajectory.parameters_of(Helix())["helix.omega"] == math.pi, "omega default is pi rad/s"


@pytest.mark.parametrize("trajectory,field", [
    (Waypoints(points=((0, 0, -0.4), (0, 0, -0.5)), segment_time=1.0), "points"),
    (Waypoints(points=((0, 0, -0.4),) * 5, segment_time=1.0), "points"),
    (Waypoints(points=((0, 0, -0.4), (0, 0, -0.5), (0, 0, -0.45), (0, 0, -0.4)), times=(0, 1, 2, 3)),
     "segment_time"),
])
def test_unrepresentable_trajectory_names_the_field(trajectory, field):
    with pytest.raises(ValueError) as exc:
        WaypointsTrajectory.parameters_of(trajectory)
    assert f"Waypoints.{field} = " in str(exc.value), f"{exc.value} vs a message naming Waypoints.{field}"


def test_wrong_class_is_a_type_error():
    with pytest.raises(TypeError, match="HelixTrajectory generates Helix, got PickAndPlace"):
        HelixTrajectory.parameters_of(PickAndPlace(start=(0.0, 0.0, -0.5)))


# ----------------------------------------------------------------------------- scenario section

SCENARIO = """\
name: t
robot: linear_delta_thesis
trajectory:
  type: helix
  params: {rx: 0.08, z0: -0.5}
components:
  traj:
    fmu: helix
    parameters: {PARAMS}
  other: {path: foreign.fmu, parameters: {helix.rx: 0.3}}
time: {stop: 1.0, step: 0.01}
initial_state: {from_trajectory: false}
"""


def _scenario(params: str = "{}", fmu: str = "helix", sets: list[str] | None = None):
    text = SCENARIO.replace("{PARAMS}", params).replace("fmu: helix", f"fmu: {fmu}")
    return parse_scenario(text, "x.yaml", apply_overrides(sets or []))


def test_section_sets_every_parameter_and_leaves_foreign_fmus_alone():
    values = trajectory_start_values(_scenario().structure())
    expected = HelixTrajectory.parameters_of(Helix(rx=0.08, z0=-0.5))
    assert values == {"traj": expected}, f"{values} vs {{'traj': {expected}}}"


def test_equal_explicit_values_are_fine():
    values = trajectory_start_values(_scenario("{helix.rx: 0.08, helix.ry: 0.1, helix.centre.x: 0, helix.duration: 10}").structure())
    assert values["traj"]["helix.rx"] == 0.08, f"{values['traj']['helix.rx']} vs 0.08"


def test_disagreeing_parameter_names_file_line_component_and_both_values():
    with pytest.raises(ScenarioError) as exc:
        trajectory_start_values(_scenario("{helix.rx: 0.2}").structure())
    assert str(exc.value) == ("x.yaml:9: components.traj.parameters.helix.rx: 0.2 disagrees with trajectory.params "
                              "rx = 0.08; set it in one place (trajectory.params)"), str(exc.value)


def test_disagreeing_default_and_set_override_are_reported_together():
    with pytest.raises(ScenarioError) as exc:
        trajectory_start_values(_scenario("{helix.omega: 2.0}", sets=["traj.helix.vz=0.0"]).structure())
    lines = str(exc.value).splitlines()
    assert lines == [
        "x.yaml:9: components.traj.parameters.helix.omega: 2.0 disagrees with trajectory (the Helix default) "
        f"omega = {math.pi}; set it in one place (trajectory.params)",
        # the value came from the command line: the issue names the option, as every override's issue does
        "--set traj.helix.vz=0.0: 0.0 disagrees with trajectory (the Helix default) "
        "vz = -0.01; set it in one place (trajectory.params)",
    ], "\n".join(lines)


def test_type_mismatch_names_the_fmu_to_use():
    with pytest.raises(ScenarioError) as exc:
        trajectory_start_values(_scenario(fmu="pick_place").structure())
    assert str(exc.value) == ("x.yaml:8: components.traj.fmu: pick_place generates a pick_and_place trajectory "
                              "but trajectory.type is helix; use fmu: helix or change trajectory.type"), str(exc.value)


def test_section_the_fmu_cannot_generate():
    text = SCENARIO.replace("type: helix", "type: waypoints").replace("fmu: helix", "fmu: waypoints").replace(
        "params: {rx: 0.08, z0: -0.5}", "params: {points: [[0, 0, -0.4], [0, 0, -0.5]], segment_time: 1.0}"
    ).replace("{PARAMS}", "{}")
    with pytest.raises(ScenarioError) as exc:
        trajectory_start_values(parse_scenario(text, "x.yaml").structure())
    msg = str(exc.value)
    assert msg.startswith("x.yaml:5: trajectory.params: traj (fmu: waypoints) cannot generate it: Waypoints.points = "), msg
    assert "it takes 4 points" in msg, msg


def test_no_section_no_values():
    text = SCENARIO.replace("trajectory:\n  type: helix\n  params: {rx: 0.08, z0: -0.5}\n", "").replace(
        "{PARAMS}", "{helix.rx: 0.2}")
    assert trajectory_start_values(parse_scenario(text, "x.yaml").structure()) == {}, "no trajectory section: nothing set"


# ----------------------------------------------------------------------------- one list of types

def test_every_trajectory_type_has_one_adapter_and_one_fmu():
    from delta.trajectories import TYPES
    from fmus import registry

    assert list(ADAPTERS) == list(TYPES), f"{list(ADAPTERS)} vs {list(TYPES)}"
    fmus = {e.name: e.adapter for e in registry.REGISTRY.values() if e.role == "trajectory"}
    expected = {a.FMU: a for a in ADAPTERS.values()}
    assert fmus == expected, f"{fmus} vs {expected}"
    # the published FMU names (scenarios, golden runs) do not move
    assert sorted(fmus) == ["helix", "pick_place", "point_to_point", "waypoints"], sorted(fmus)


def test_a_new_trajectory_type_gets_a_derived_adapter(monkeypatch):
    # adding a type to delta.trajectories.TYPES is the only edit: its adapter comes from its dataclass
    from dataclasses import dataclass, field

    import fmus.adapters.trajectories as traj
    from delta.trajectories import TYPES

    @dataclass(frozen=True)
    class Tilted(Helix):
        """Helix with a tilt (test type)."""

        tilt: tuple[float, float, float] = field(default=(0.1, 0.2, 0.3), metadata={"unit": "rad"})
        turns: int = 2

    monkeypatch.setitem(TYPES, "tilted", Tilted)
    monkeypatch.setitem(ADAPTERS, "tilted", None)  # restored (removed) after the test
    cls = traj.derived_adapter("tilted")
    assert (cls.TYPE, cls.FMU, cls.CLASS, ADAPTERS["tilted"]) == ("tilted", "tilted", Tilted, cls), cls
    by_name = {p.name: p for p in cls.PARAMS}
    assert {"tilted.centre.x", "tilted.centre.y", "tilted.rx", "tilted.tilt.z", "tilted.turns"} <= set(by_name), \
        sorted(by_name)
    assert (by_name["tilted.tilt.x"].unit, by_name["tilted.turns"].cast) == ("rad", int), by_name["tilted.tilt.x"]
    other = Tilted(rx=0.05, tilt=(0.0, 0.5, 0.25), turns=3)
    back = cls.from_parameters(cls.parameters_of(other))
    assert back == other, f"{back} vs {other}"
