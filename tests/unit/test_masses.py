"""The one mass lumping (delta.masses.lumps) and what each of its users takes from it; Data tied to its Model."""

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from delta.dynamics import analytic_model, platform_state
from delta.errors import ParameterError
from delta.kinematics import set_pose, update
from delta.masses import LinearDeltaMasses, RotaryDeltaMasses, lumps
from delta.model import Data, build_model
from delta.robots import linear_delta_thesis, rotary_delta_prototype

SPLIT = {"w_inertia": 0.6, "w_gravity": 0.45, "w_rotation": 0.5, "payload": 0.2}
CASES = [(linear_delta_thesis, LinearDeltaMasses(**SPLIT)), (rotary_delta_prototype, RotaryDeltaMasses(**SPLIT))]
IDS = ["linear", "rotary"]


def test_lumps_are_the_thesis_split_written_out():
    """Thesis eqs. (28)-(29) by hand for the linear delta: platform 0.3 kg + payload 0.2 kg, carriage 0.5 kg, rods
    0.1 kg, w = 0.6 (inertia) / 0.45 (weight); the rotary delta's elbow (0.05 kg) takes the carriage's place."""
    lin = lumps(LinearDeltaMasses(**SPLIT), "linear")
    assert lin.platform_alone == pytest.approx(0.5, rel=1e-15)
    assert lin.platform_inertial == pytest.approx(0.5 + 6 * 0.6 * 0.1, rel=1e-15)  # 0.86 kg
    assert lin.platform_weight_mass == pytest.approx(0.5 + 6 * 0.45 * 0.1, rel=1e-15)  # 0.77 kg
    assert lin.actuator_alone == 0.5
    assert lin.actuator_inertial == pytest.approx(0.5 + 2 * 0.4 * 0.1, rel=1e-15)  # 0.58 kg
    assert lin.actuator_weight_mass == pytest.approx(0.5 + 2 * 0.55 * 0.1, rel=1e-15)  # 0.61 kg
    assert lin.rod_inertia == pytest.approx(-0.5 * 0.1 / 3, rel=1e-15)
    rot = lumps(RotaryDeltaMasses(**SPLIT), "rotary")
    assert (rot.actuator_alone, rot.actuator_inertial, rot.actuator_weight_mass) == pytest.approx(
        (0.05, 0.05 + 2 * 0.4 * 0.08, 0.05 + 2 * 0.55 * 0.08), rel=1e-15)
    assert rot.platform_inertial == pytest.approx(0.25 + 0.2 + 6 * 0.6 * 0.08, rel=1e-15)


@pytest.mark.parametrize("w", [0.0, 0.3, 2.0 / 3.0, 1.0])
@pytest.mark.parametrize("robot,masses", CASES, ids=IDS)
def test_lumping_keeps_the_total_mass(robot, masses, w):
    """Whatever the split, the platform's and the three actuator points' lumps hold the machine's mass (and its
    weight) but the arms': the platform, three carriages or elbows and six rods."""
    masses = masses.with_(w_inertia=w, w_gravity=1.0 - w)
    lp = lumps(masses, robot.kind)
    total = lp.platform_alone + 3 * lp.actuator_alone + 6 * masses.rod
    assert lp.platform_inertial + 3 * lp.actuator_inertial == pytest.approx(total, rel=1e-14)
    assert lp.platform_weight_mass + 3 * lp.actuator_weight_mass == pytest.approx(total, rel=1e-14)


def test_lumps_serve_every_number_type_and_refuse_an_unknown_kind():
    """The same formulas on numpy arrays (a sweep of w, as multibody.validate does) and on CasADi symbols (the native
    FMUs trace the model to C) give the floats' values."""
    ws = np.array([0.0, 0.25, 0.5, 1.0])
    fields = {f: getattr(LinearDeltaMasses(), f) for f in LinearDeltaMasses.__dataclass_fields__}
    swept = lumps(SimpleNamespace(**{**fields, "w_inertia": ws}), "linear")
    for k, w in enumerate(ws):
        one = lumps(LinearDeltaMasses(w_inertia=float(w)), "linear")
        assert swept.platform_inertial[k] == one.platform_inertial
        assert swept.actuator_inertial[k] == one.actuator_inertial
    ca = pytest.importorskip("casadi")
    rod, w = ca.SX.sym("rod"), ca.SX.sym("w")
    traced = lumps(SimpleNamespace(**{**fields, "rod": rod, "w_inertia": w}), "linear")
    at = ca.Function("f", [rod, w], [traced.platform_inertial, traced.actuator_inertial])(0.1, 0.6)
    one = lumps(LinearDeltaMasses(w_inertia=0.6), "linear")
    assert (float(at[0]), float(at[1])) == (one.platform_inertial, one.actuator_inertial)
    with pytest.raises(ParameterError, match="unknown robot kind 'scara'"):
        lumps(LinearDeltaMasses(), "scara")


@pytest.mark.parametrize("robot,masses", CASES, ids=IDS)
def test_the_analytic_model_and_the_actuators_take_the_lumps(robot, masses):
    model = build_model(robot, masses)
    lp, g = lumps(masses, robot.kind), masses.gravity
    assert model.lumps == lp
    assert model.platform_mass == lp.platform_inertial and model.rod_inertia == lp.rod_inertia
    assert model.platform_weight == lp.platform_weight_mass * g
    if robot.kind == "linear":  # D and the weight of the carriage's lump
        assert model.inertia == lp.actuator_inertial and model.actuator_weight == lp.actuator_weight_mass * g
    else:  # the arm about the motor axis and the elbow's lump at La
        la = robot.arm_length
        inertia = masses.motor_inertia + masses.arm * la**2 / 3 + lp.actuator_inertial * la**2
        assert model.inertia == pytest.approx(inertia, rel=1e-15)
        weight = (masses.arm * la / 2 + lp.actuator_weight_mass * la) * g
        assert model.actuator_weight == pytest.approx(weight, rel=1e-15)
    assert model.actuator.inertia(masses) == model.inertia and model.actuator.weight(masses) == model.actuator_weight


@pytest.mark.parametrize("fidelity", ["lumped", "full"])
@pytest.mark.parametrize("robot,masses", CASES, ids=IDS)
def test_the_exudyn_plants_take_the_lumps(robot, masses, fidelity):
    """The lumped plant's platform and carriages (arms) carry the lumps; the full plant's platform and carriages
    (elbows) carry their own masses only, its rods being bodies; both weigh the whole machine."""
    from multibody import make_plant
    from multibody.rotary import ARM_RADIUS

    plant = make_plant(robot, masses, fidelity=fidelity)
    lp, lumped = lumps(masses, robot.kind), fidelity == "lumped"
    platform = plant._bodies[0]
    assert platform[1] == (lp.platform_inertial if lumped else lp.platform_alone)
    assert plant._weights[0][2] == (lp.platform_weight_mass if lumped else lp.platform_alone)
    arms = 0.0 if robot.kind == "linear" else 3 * masses.arm
    weight = sum(g for _, _, g in plant._weights) + sum(float(x[4].sum()) for x in plant._point_masses)
    expected = (lp.platform_weight_mass + 3 * lp.actuator_weight_mass if lumped
                else lp.platform_alone + 3 * lp.actuator_alone + 6 * masses.rod)
    assert weight == pytest.approx(expected + arms, rel=1e-14)
    if robot.kind == "linear":
        carriages = [float(x[3][0, 0]) for x in plant._point_masses]
        assert carriages == [lp.actuator_inertial if lumped else lp.actuator_alone] * 3
    else:  # the arm's moment about the motor axis: the analytic model's D (the elbow's lump), plus the arm's thickness
        axial = [float(inertia[2, 2]) for _, _, inertia in plant._bodies[1:4]]
        d = build_model(robot, masses).inertia if lumped else build_model(
            robot, masses.with_(w_inertia=1.0)).inertia  # w = 1: the elbow alone
        assert axial == pytest.approx([d + masses.arm * ARM_RADIUS**2 / 4] * 3, rel=1e-12)


# ----------------------------------------------------------------------------- Data(model)

def test_data_is_made_from_its_model():
    model = build_model(linear_delta_thesis)
    assert Data(model).model is model
    with pytest.raises(TypeError, match="Data"):
        Data()  # the model is required
    with pytest.raises(TypeError, match="needs the compiled delta.model.Model, got AnalyticModel"):
        Data(analytic_model(linear_delta_thesis))


def test_a_data_used_with_another_model_computes_that_models_pose():
    """The forward-kinematics cache is keyed on the model and q: a data that holds one model's pose, asked for
    another model's at the same q, gives the other model's answer (it used to answer with the first one's p)."""
    first = build_model(linear_delta_thesis)
    other = build_model(replace(linear_delta_thesis, rod_length=linear_delta_thesis.rod_length * 1.1))
    q, qd = (0.30, 0.32, 0.29), (0.1, -0.2, 0.05)
    data = Data(first)
    p_first, _ = platform_state(first, data, q, qd)
    legs = data.legs
    update(first, data, q)
    assert data.legs is legs, "the same model at the same q must hit the cache"
    p_other, v_other = platform_state(other, data, q, qd)
    assert (p_other, v_other) == platform_state(other, Data(other), q, qd)
    assert data.model is other and data.legs is not legs
    assert abs(p_other[2] - p_first[2]) > 1e-3, (p_first, p_other)
    set_pose(first, data, q, p_first)  # set_pose records the model too
    assert data.model is first and data.q is None
