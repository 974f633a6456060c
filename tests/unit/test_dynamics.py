"""Analytic virtual-work dynamics of the linear and rotary deltas (thesis section 7)."""

import numpy as np
import pytest

from delta.dynamics import (
    LinearDeltaMasses,
    RotaryDeltaMasses,
    analytic_model,
    joint_references,
)
from delta.errors import ParameterError
from delta.kinematics import fk, ik, jacobian, joint_acceleration, joint_velocity, platform_acceleration
from delta.robots import linear_delta_thesis, rotary_delta_prototype

# Inverse then forward dynamics is a 3x3 solve of a well-conditioned matrix (cond(M) < 1e3
# inside the workspace): round-off stays ~1e-13 relative; 1e-10 is the bound.
ROUND_TRIP_RTOL = 1e-10
# Central difference of the energy with step DT: truncation O(DT^2 E''') ~ 1e-10 relative,
# rounding O(eps E / DT) ~ 1e-11: 1e-6 (the bound) still catches any wrong term,
# which would be O(1) relative.
POWER_RTOL = 1e-6
DT = 1e-5
# Two independent closed-form evaluations of the same formula (float lists vs numpy):
# a few ulps amplified by J^-1 (cond < 1e2).
FORMULA_RTOL = 1e-11

CASES = [
    (linear_delta_thesis, LinearDeltaMasses(), np.array([0.0, 0.0, -0.45])),
    (linear_delta_thesis, LinearDeltaMasses(w_inertia=2 / 3, w_gravity=0.5, payload=0.2), np.array([0.03, -0.02, -0.50])),
    (rotary_delta_prototype, RotaryDeltaMasses(), np.array([0.0, 0.0, -0.50])),
    (rotary_delta_prototype, RotaryDeltaMasses(w_inertia=0.6, w_gravity=0.5, payload=0.3), np.array([0.05, 0.02, -0.55])),
    (linear_delta_thesis, LinearDeltaMasses(w_inertia=0.5, w_gravity=0.5, w_rotation=1.0), np.array([0.03, -0.02, -0.50])),
    (rotary_delta_prototype, RotaryDeltaMasses(w_inertia=0.45, w_gravity=0.5, w_rotation=0.8, payload=0.1),
     np.array([0.05, 0.02, -0.55])),
]
IDS = ["linear", "linear-split-w", "rotary", "rotary-split-w", "linear-rod-rotation", "rotary-rod-rotation"]


def _motion(p0, t, amp=0.04):
    """Smooth random-looking platform motion: three incommensurate sinusoids per axis."""
    w = np.array([[3.1, 5.3, 7.7], [2.3, 4.9, 6.1], [3.7, 5.9, 8.3]])
    ph = np.array([[0.3, 1.1, 2.0], [0.7, 1.9, 0.2], [1.3, 0.4, 2.6]])
    s = np.sin(w * t + ph)
    c = np.cos(w * t + ph)
    p = p0 + amp * s.sum(axis=1) / 3
    v = amp * (w * c).sum(axis=1) / 3
    a = -amp * (w**2 * s).sum(axis=1) / 3
    return p, v, a


def _joint_state(model, p, v, a):
    q, qd, qdd = joint_references(model, p[None], v[None], a[None])
    return q[0], qd[0], qdd[0]


@pytest.mark.parametrize("robot,masses,p0", CASES, ids=IDS)
def test_inverse_forward_round_trip(robot, masses, p0):
    model = analytic_model(robot, masses)
    for t in np.linspace(0.0, 2.0, 7):
        q, qd, qdd = _joint_state(model, *_motion(p0, t))
        f = model.inverse_dynamics(q, qd, qdd)
        qdd_back = model.forward_dynamics(q, qd, f)
        f_back = model.inverse_dynamics(q, qd, qdd_back)
        err = np.linalg.norm(f_back - f) / np.linalg.norm(f)
        assert err < ROUND_TRIP_RTOL, f"t={t}: f={f}, f after round trip={f_back}, rel err {err:.2e}"


@pytest.mark.parametrize("robot,masses,p0", CASES, ids=IDS)
def test_power_balance(robot, masses, p0):
    """d/dt (T + V) = f . qd along a prescribed motion (no damping, f from inverse dynamics)."""
    model = analytic_model(robot, masses)

    def total_energy(t):
        q, qd, _ = _joint_state(model, *_motion(p0, t))
        return sum(model.energy(q, qd))

    for t in np.linspace(0.1, 2.0, 9):
        q, qd, qdd = _joint_state(model, *_motion(p0, t))
        power = float(model.inverse_dynamics(q, qd, qdd) @ qd)
        de_dt = (total_energy(t + DT) - total_energy(t - DT)) / (2 * DT)
        scale = max(abs(power), abs(float(model.gravity_term(q) @ qd)), 1e-3)
        assert abs(de_dt - power) < POWER_RTOL * scale, f"t={t}: dE/dt={de_dt!r}, f.qd={power!r}"


THESIS = [(c, i) for c, i in zip(CASES, IDS) if c[1].w_rotation == 0.0]


@pytest.mark.parametrize("robot,masses,p0", [c for c, _ in THESIS], ids=[i for _, i in THESIS])
def test_matches_thesis_eq35_with_reference_kinematics(robot, masses, p0):
    """f = D qdd + J^-T m_p a + G_s + J^-T G_p (thesis eq. (35)) built from delta.kinematics (the thesis's
    lumping: the rods' rotation is checked by the power balance against the exact kinetic energy below)."""
    model = analytic_model(robot, masses)
    p, v, a = _motion(p0, 0.37)
    q = ik(robot, p).require()
    qd = joint_velocity(robot, q, p, v)
    qdd = joint_acceleration(robot, q, p, v, a)
    jinv_t = np.linalg.inv(jacobian(robot, q, p)).T
    g = masses.gravity
    if model.kind == "linear":
        d = masses.carriage + 2 * (1 - masses.w_inertia) * masses.rod  # thesis eq. (29)
        g_act = -(masses.carriage + 2 * (1 - masses.w_gravity) * masses.rod) * g * np.ones(3)
    else:
        la = robot.arm_length
        d = masses.motor_inertia + masses.arm * la**2 / 3 + (masses.elbow + 2 * (1 - masses.w_inertia) * masses.rod) * la**2
        g_act = -g * np.cos(q) * (masses.arm * la / 2 + (masses.elbow + 2 * (1 - masses.w_gravity) * masses.rod) * la)
    mp = masses.platform + masses.payload + 6 * masses.w_inertia * masses.rod  # thesis eq. (28)
    mp_g = masses.platform + masses.payload + 6 * masses.w_gravity * masses.rod
    expected = d * qdd + jinv_t @ (mp * a) + g_act + jinv_t @ np.array([0.0, 0.0, mp_g * g])
    got = model.inverse_dynamics(q, qd, qdd)
    assert np.allclose(got, expected, rtol=FORMULA_RTOL, atol=FORMULA_RTOL * np.abs(expected).max()), \
        f"model {got} vs thesis eq. (35) {expected}"
    p_model, v_model = model.platform_state(q, qd)
    assert np.allclose(p_model, fk(robot, q).require(), atol=1e-12), f"FK {p_model} vs {fk(robot, q).p}"
    a_back = platform_acceleration(robot, q, p, v, model.forward_dynamics(q, qd, got))
    assert np.allclose(a_back, a, rtol=1e-8, atol=1e-9), f"platform acceleration {a_back} vs {a}"


@pytest.mark.parametrize("robot,masses,p0", CASES, ids=IDS)
def test_mass_matrix_symmetric_positive_and_terms_split(robot, masses, p0):
    model = analytic_model(robot, masses)
    q, qd, qdd = _joint_state(model, *_motion(p0, 1.1))
    m = model.mass_matrix(q)
    assert np.allclose(m, m.T, rtol=0, atol=1e-15 * np.abs(m).max()), f"M not symmetric: {m}"
    eig = np.linalg.eigvalsh(m)
    assert eig.min() > 0, f"M not positive definite, eigenvalues {eig}"
    split = m @ qdd + model.velocity_term(q, qd) + model.gravity_term(q)
    whole = model.inverse_dynamics(q, qd, qdd)
    assert np.allclose(split, whole, rtol=FORMULA_RTOL), f"M qdd + C qd + G = {split} vs inverse_dynamics {whole}"
    assert np.allclose(model.velocity_term(q, np.zeros(3)), 0.0), "C qd must vanish at rest"


@pytest.mark.parametrize("robot,masses,p0", [c for c in CASES if c[1].w_rotation == 0.0][:1] + [CASES[4]], ids=["thesis", "rods"])
def test_kinetic_energy_of_uniform_rods_is_exact(robot, masses, p0):
    """With ``w_inertia = 1/2`` and ``w_rotation = 1`` the model's kinetic energy is that of the machine with
    uniform rods, computed here from the rods' end velocities (``m/6 (|v_A|^2 + v_A . v_B + |v_B|^2)`` per rod:
    the integral of ``1/2 |v(s)|^2 dm`` along the rod), the carriages and the platform; the thesis's lumping
    (``w_rotation = 0``) is not (it counts each rod as two point masses)."""
    exact_masses = masses.with_(w_inertia=0.5, w_rotation=1.0)
    model = analytic_model(robot, exact_masses)
    q, qd, _ = _joint_state(model, *_motion(p0, 0.7, amp=0.05))
    _, v = model.platform_state(q, qd)
    m = exact_masses
    expected = 0.5 * (m.platform + m.payload) * v @ v + 0.5 * m.carriage * qd @ qd
    for qdi in qd:  # carriage i moves at -qd_i along z (B_i' = (0, 0, -1)); platform joint at v
        va = np.array([0.0, 0.0, -qdi])
        expected += 2 * m.rod / 6 * (va @ va + va @ v + v @ v)
    assert abs(model.energy(q, qd)[0] - expected) < 1e-12 * expected, (model.energy(q, qd)[0], expected)
    lumped = analytic_model(robot, masses.with_(w_inertia=0.5, w_rotation=0.0)).energy(q, qd)[0]
    assert abs(lumped - expected) > 1e-4 * expected, "two point masses per rod are not a uniform rod"


def test_gravity_signs_and_static_weight():
    """At rest, the vertical efforts carry the total weight (linear: sum f = -total m g)."""
    masses = LinearDeltaMasses(payload=0.5, w_gravity=0.5)
    model = analytic_model(linear_delta_thesis, masses)
    q = ik(linear_delta_thesis, np.array([0.0, 0.0, -0.45])).require()
    g_term = model.gravity_term(q)
    total = 3 * (masses.carriage + 2 * masses.rod) + masses.platform + masses.payload
    # Rails are vertical: the three actuator forces are the only vertical forces on the robot.
    assert abs(g_term.sum() + total * masses.gravity) < 1e-12 * total * masses.gravity, \
        f"sum G = {g_term.sum()} vs -m_total g = {-total * masses.gravity}"
    assert np.all(g_term < 0), f"carriages must be held up (negative effort along q down): {g_term}"


def test_factory_and_errors():
    assert analytic_model(linear_delta_thesis).kind == "linear", "linear factory"
    assert analytic_model(rotary_delta_prototype).kind == "rotary", "rotary factory"
    with pytest.raises(ParameterError, match="RotaryDeltaMasses"):
        analytic_model(rotary_delta_prototype, LinearDeltaMasses())
    with pytest.raises(ParameterError, match="w_inertia"):
        LinearDeltaMasses(w_inertia=1.5)


@pytest.mark.parametrize("robot,helix,rotation", [(linear_delta_thesis, {}, 0.0),
                                                  (rotary_delta_prototype, {"z0": -0.45, "rx": 0.05, "ry": 0.05}, 0.0),
                                                  (linear_delta_thesis, {}, 1.0),
                                                  (rotary_delta_prototype, {"z0": -0.45, "rx": 0.05, "ry": 0.05}, 1.0)],
                         ids=["linear", "rotary", "linear-rod-rotation", "rotary-rod-rotation"])
def test_plant_stepper_in_platform_coordinates_matches_joint_coordinates(robot, helix, rotation):
    """The analytic plant's stepper (RK4 on the platform state, one 1 ms step) against RK4 on the joint
    state with 4 substeps, both under the same CTC efforts on 2 s of the helix: two routes through the
    dynamics (platform_dynamics / forward_dynamics, inverse / forward kinematics) and two step sizes.
    Measured 2.9e-14 m (linear) and 8.7e-15 m (rotary) over 10 s; 1e-12 m leaves rounding room and
    still catches an O(h^4) error of the 1 ms step (~1e-11 m for RK3, 1.7e-8 m for the midpoint rule).
    4 substeps make the joint route's own RK4 error 256 times smaller than the 1 ms step's: the difference is
    the same with 16 substeps (3.4e-14 m linear, 1.2e-14 m rotary with rod rotation, over these 2 s) at a
    third of the time."""
    from delta.control import default_controller
    from delta.dynamics import forward_dynamics, integrate, platform_state, rk4_step
    from delta.kinematics import inverse_kinematics
    from delta.model import Data, build_model
    from delta.trajectories import Helix

    masses = (LinearDeltaMasses if robot.kind == "linear" else RotaryDeltaMasses)(w_inertia=0.5, w_rotation=rotation)
    model, h, n = build_model(robot, masses), 1e-3, 2000
    data = Data(model)
    p_ref, v_ref, a_ref = Helix(**helix).sample(np.arange(n) * h)
    q_ref, qd_ref, qdd_ref = joint_references(model, p_ref, v_ref, a_ref)
    ctc_p, ctc_q = default_controller("ctc", robot, model), default_controller("ctc", robot, model)
    p, v = tuple(p_ref[0]), tuple(v_ref[0])
    q, qd = tuple(q_ref[0]), tuple(qd_ref[0])
    worst = 0.0
    for k in range(n):
        refs = (q_ref[k].tolist(), qd_ref[k].tolist(), qdd_ref[k].tolist())
        qp, qdp, _, _ = inverse_kinematics(model, p, v, limits=False)
        p, v = integrate(model, p, v, ctc_p.output_scalar(qp, qdp, *refs), h, h)
        u = ctc_q.output_scalar(q, qd, *refs)
        for _ in range(4):
            q, qd = rk4_step(lambda x, xd: forward_dynamics(model, data, x, xd, u), q, qd, h / 4)
        worst = max(worst, max(abs(a - b) for a, b in zip(p, platform_state(model, data, q, qd)[0])))
    assert worst < 1e-12, f"platform-coordinate RK4 (1 ms) vs joint-coordinate RK4 (1/4 ms): {worst:.3g} m"


def test_plant_stepper_splits_long_steps_and_fails_with_the_reason():
    """integrate(): a step longer than max_step is ceil(h / max_step) equal RK4 steps (the same floats as
    taking them one by one); a non-finite effort and a state driven out of the workspace raise errors
    that say so."""
    from delta.dynamics import integrate, platform_dynamics, rk4_step
    from delta.errors import DeltaError
    from delta.kinematics import inverse_kinematics
    from delta.model import build_model

    model = build_model(linear_delta_thesis)
    p, v = (0.1, 0.0, -0.45), (0.0, 0.3, -0.01)
    q = inverse_kinematics(model, p)[0]
    u = tuple(analytic_model(linear_delta_thesis).gravity_term(q) + np.array([1.0, -2.0, 0.5]))
    x, xd = p, v
    for _ in range(3):
        x, xd = rk4_step(lambda y, yd: platform_dynamics(model, y, yd, u), x, xd, 2.5e-3 / 3)
    assert integrate(model, p, v, u, 2.5e-3, 1e-3) == (x, xd)
    with pytest.raises(ParameterError, match="non-finite effort"):
        integrate(model, p, v, (float("nan"), 0.0, 0.0), 1e-3, 1e-3)
    with pytest.raises(DeltaError, match="left the workspace|singularity|diverged"):
        integrate(model, p, v, (1e9, -1e9, 1e9), 1e-3, 1e-3)
