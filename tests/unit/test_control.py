"""Controllers and the pure-Python closed loop on the analytic model (thesis sections 9-12)."""

import numpy as np
import pytest

from delta.closed_loop import simulate
from delta.control import CTC, PD, PID, DEFAULT_GAINS, default_controller
from delta.dynamics import LinearDeltaMasses, analytic_model, joint_references
from delta.errors import ParameterError
from delta.kinematics import ik, jacobian
from delta.robots import linear_delta_thesis, rotary_delta_prototype
from delta.trajectories import Helix, Hold

H = 1e-3
# CTC on the exact model leaves only the zero-order-hold error: the effort is frozen over
# h while M, C, G and qdd_ref drift, an acceleration bias ~ h/2 * d/dt(qdd) ~ 1e-3 m/s^2,
# rejected by kp = 22500 1/s^2 -> ~1e-7 m; 1e-6 m is the bound.
CTC_RMSE_BOUND = 1e-6


@pytest.fixture(scope="module")
def helix_runs():
    robot = linear_delta_thesis
    model = analytic_model(robot)
    return {k: simulate(robot, model, Helix(), default_controller(k, robot, model, H), 10.0, H)
            for k in ("pd", "pid", "ctc")}


def test_ctc_tracks_default_helix_exact_model(helix_runs):
    rmse = helix_runs["ctc"].rmse()
    assert np.all(rmse < CTC_RMSE_BOUND), f"CTC RMSE per axis {rmse} m vs bound {CTC_RMSE_BOUND} m"


def test_ctc_tracks_default_helix_rotary():
    robot = rotary_delta_prototype
    model = analytic_model(robot)
    res = simulate(robot, model, Helix(), default_controller("ctc", robot, model, H), 10.0, H)
    assert np.all(res.rmse() < CTC_RMSE_BOUND), f"rotary CTC RMSE {res.rmse()} m vs {CTC_RMSE_BOUND} m"


def test_ranking_as_thesis_table5(helix_runs):
    """Thesis Table 5: RMSE(PD) > RMSE(PID) > RMSE(CTC) (e_z of PD and PID tie there)."""
    pd, pid, ctc = (helix_runs[k].rmse() for k in ("pd", "pid", "ctc"))
    for axis, name in enumerate("xyz"):
        assert pd[axis] > pid[axis] > ctc[axis], f"e_{name}: PD {pd[axis]:.3e}, PID {pid[axis]:.3e}, CTC {ctc[axis]:.3e}"


@pytest.mark.parametrize("robot,p", [
    (linear_delta_thesis, (0.0, 0.0, -0.45)),
    (linear_delta_thesis, (0.06, -0.03, -0.52)),
    (rotary_delta_prototype, (0.05, 0.02, -0.50)),
])
def test_pd_gravity_sag_is_g_over_kp(robot, p):
    """At rest under PD, kp (q_ref - q) = G(q): the steady error is the gravity sag G/kp."""
    model = analytic_model(robot)
    ctrl = default_controller("pd", robot, model, H)
    res = simulate(robot, model, Hold(p, 1.0), ctrl, 1.0, H)
    e = res.q_ref[-1] - res.q[-1]
    kp = np.array(ctrl.kp)
    sag_exact = model.gravity_term(res.q[-1]) / kp
    # Transients decay as exp(-zeta wn t) with zeta wn >= 150 1/s: after 1 s nothing is left
    # but rounding, so the equilibrium holds to 1e-9 relative.
    assert np.allclose(e, sag_exact, rtol=1e-9, atol=0), f"q_ref - q = {e} vs G(q)/kp = {sag_exact}"
    # First-order prediction from the reference pose: G changes by G' e ~ e / L relative (~1e-3).
    sag_ref = model.gravity_term(res.q_ref[-1]) / kp
    assert np.allclose(e, sag_ref, rtol=1e-2), f"q_ref - q = {e} vs G(q_ref)/kp = {sag_ref}"
    # In task space the platform sags by J^-1 (q - q_ref), downward (z < z_ref).
    dp = np.linalg.solve(jacobian(robot, res.q_ref[-1], res.p_ref[-1]), -sag_ref)
    assert np.allclose(res.p[-1] - res.p_ref[-1], dp, rtol=1e-2, atol=1e-9), f"p - p_ref {res.p[-1] - res.p_ref[-1]} vs {dp}"
    assert res.p[-1, 2] < res.p_ref[-1, 2], f"platform must sag down: z {res.p[-1, 2]} vs z_ref {res.p_ref[-1, 2]}"


def test_pid_removes_the_sag():
    robot = linear_delta_thesis
    model = analytic_model(robot)
    p = (0.0, 0.0, -0.45)
    res = simulate(robot, model, Hold(p, 2.0), default_controller("pid", robot, model, H), 2.0, H)
    sag = np.abs(model.gravity_term(res.q_ref[-1]) / DEFAULT_GAINS["linear"]["pid"]["kp"])
    e = np.abs(res.q_ref[-1] - res.q[-1])
    # The slowest closed-loop pole is ~ -ki/kp = -10 1/s: after 2 s, e^-20 ~ 2e-9 of the sag remains.
    assert np.all(e < 1e-6 * sag), f"PID residual {e} m vs sag {sag} m"


@pytest.mark.parametrize("robot", [linear_delta_thesis, rotary_delta_prototype], ids=["linear", "rotary"])
def test_ctc_on_reference_equals_inverse_dynamics(robot):
    model = analytic_model(robot)
    helix = Helix()
    p, v, a = helix.evaluate(0.3)
    q, qd, qdd = (x[0] for x in joint_references(model, p[None], v[None], a[None]))
    u = default_controller("ctc", robot, model, H).step(q, qd, q, qd, qdd)
    f = model.inverse_dynamics(q, qd, qdd)
    assert np.allclose(u, f, rtol=1e-14, atol=1e-14 * np.abs(f).max()), f"CTC at zero error {u} vs f {f}"


def test_pid_anti_windup_and_saturation():
    pid = PID(kp=1.0, ki=100.0, kd=0.0, h=H, u_max=1.0)
    zero = np.zeros(3)
    for _ in range(1000):
        u = pid.step(zero, zero, np.full(3, 10.0), zero, zero)
    assert np.allclose(u, 1.0), f"saturated output {u} vs u_max 1.0"
    # Conditional integration: no growth while saturated in the error's direction.
    assert np.allclose(pid.integral, 0.0), f"integral wound up to {pid.integral} while saturated"
    u = pid.step(zero, zero, np.full(3, -0.5), zero, zero)
    assert np.allclose(u, -0.5 + 100.0 * -0.5 * H), f"after the error flips the PID leaves saturation: {u}"
    clamp = PID(kp=1e-3, ki=10.0, kd=0.0, h=H, u_max=5.0, i_max=0.2)
    for _ in range(1000):
        u = clamp.step(zero, zero, np.full(3, 0.1), zero, zero)
    assert np.allclose(10.0 * np.array(clamp.integral), 0.2), f"integral term {10 * np.array(clamp.integral)} vs i_max 0.2"
    clamp.reset()
    assert clamp.integral == [0.0, 0.0, 0.0], f"reset must clear the integral, got {clamp.integral}"


def test_pd_per_joint_gains_and_saturation():
    pd = PD(kp=[1.0, 2.0, 3.0], kd=0.5, h=H, u_max=[10.0, 1.0, 10.0])
    u = pd.step(np.zeros(3), np.ones(3), np.ones(3), np.zeros(3), np.zeros(3))
    assert np.allclose(u, [0.5, 1.0, 2.5]), f"u {u} vs [0.5, 1.0 (saturated), 2.5]"


@pytest.mark.parametrize("make,match", [
    (lambda: PD(kp=[1, 2], kd=0.1, h=H), "kp"),
    (lambda: PD(kp=-1.0, kd=0.1, h=H), "kp"),
    (lambda: PD(kp=1.0, kd=0.1, h=0.0), "h"),
    (lambda: CTC(analytic_model(linear_delta_thesis), 1.0, 1.0, H, u_max=0.0), "u_max"),
    (lambda: default_controller("lqr", linear_delta_thesis, None), "lqr"),
    (lambda: default_controller("ctc", linear_delta_thesis, None), "model"),
])
def test_validation(make, match):
    with pytest.raises(ParameterError, match=match):
        make()


def test_model_mismatch_payload_degrades_ctc():
    """CTC with a model that ignores a 0.5 kg payload tracks worse than with the exact model."""
    robot = linear_delta_thesis
    model = analytic_model(robot)
    plant = analytic_model(robot, LinearDeltaMasses(payload=0.5))
    ctrl = default_controller("ctc", robot, model, H)
    exact = simulate(robot, model, Helix(), ctrl, 2.0, H).rmse()
    mismatch = simulate(robot, model, Helix(), ctrl, 2.0, H, plant_model=plant).rmse()
    assert np.all(mismatch > 10 * exact), f"mismatch RMSE {mismatch} vs exact {exact}"
    assert np.all(mismatch < 1e-3), f"CTC must stay stable under a payload mismatch, RMSE {mismatch}"


def test_simulate_validation():
    robot = linear_delta_thesis
    model = analytic_model(robot)
    with pytest.raises(ParameterError, match="period"):
        simulate(robot, model, Helix(), PD(1e4, 100, 2e-3), 1.0, H)
    with pytest.raises(ParameterError, match="robot"):
        simulate(rotary_delta_prototype, model, Helix(), PD(1e4, 100, H), 1.0, H)
    q_start = ik(robot, np.array([0.0, 0.0, -0.40])).require()
    res = simulate(robot, model, Hold((0, 0, -0.45), 0.5), default_controller("ctc", robot, model, H), 0.5, H,
                   start_on_trajectory=False, q0=q_start)
    assert np.allclose(res.q[0], q_start) and np.allclose(res.qd[0], 0), f"start state {res.q[0]}, {res.qd[0]}"
    # CTC error dynamics e'' + 300 e' + 22500 e = 0: after 0.5 s the 50 mm step is gone.
    assert np.abs(res.p[-1] - res.p_ref[-1]).max() < 1e-9, f"final error {res.p[-1] - res.p_ref[-1]}"


def _loop_inputs(model, n=25, seed=3):
    """Measured states near the helix references (errors ~ mm, mm/s) as the loop produces them."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 10.0, n)
    q_ref, qd_ref, qdd_ref = joint_references(model, *Helix().sample(t))
    q = q_ref + rng.normal(0.0, 1e-3, q_ref.shape) * (1.0 if model.robot.kind == "linear" else 0.01)
    qd = qd_ref + rng.normal(0.0, 1e-2, qd_ref.shape)
    return q, qd, q_ref, qd_ref, qdd_ref


@pytest.mark.parametrize("robot", [linear_delta_thesis, rotary_delta_prototype], ids=["linear", "rotary"])
@pytest.mark.parametrize("kind", ["pd", "pid", "pdplus", "ctc"])
def test_scalar_path_equals_array_path(kind, robot):
    """output_scalar on tuples, output / step on arrays and on lists: the same floats in the same
    operations, so equal exactly (tolerance 0); output_scalar leaves the PID state alone."""
    model = analytic_model(robot)
    law = default_controller(kind, robot, model, H)
    for k, row in enumerate(zip(*_loop_inputs(model))):
        arrays = tuple(np.array(x) for x in row)
        tuples = tuple(tuple(x.tolist()) for x in row)
        lists = tuple(x.tolist() for x in row)
        before = list(getattr(law, "integral", []))
        us = law.output_scalar(*tuples)
        assert type(us) is tuple and all(type(x) is float for x in us), f"{kind}: output_scalar gave {us!r}"
        assert list(getattr(law, "integral", [])) == before, f"{kind}: output_scalar changed the state"
        ua = law.output(*arrays)
        assert isinstance(ua, np.ndarray) and ua.shape == (3,), f"{kind}: output gave {ua!r}"
        assert tuple(ua.tolist()) == us == law.output_scalar(*lists), \
            f"{kind} sample {k}: output_scalar {us} vs output {ua} vs lists {law.output_scalar(*lists)}"
        stepped = law.step(*arrays)
        assert tuple(stepped.tolist()) == us, f"{kind} sample {k}: step {stepped} vs output_scalar {us}"


@pytest.mark.parametrize("robot", [linear_delta_thesis, rotary_delta_prototype], ids=["linear", "rotary"])
@pytest.mark.parametrize("feedforward", [True, False], ids=["feedforward", "regulation"])
def test_ctc_effort_is_the_inverse_dynamics_of_the_outer_loop(robot, feedforward):
    """The CTC effort is inverse_dynamics(q, qd, w) with the outer-loop acceleration w (thesis
    eq. (50)): equal exactly. Against numpy's M @ w + C + G (another summation order) rounding
    only: rtol 1e-13 of the effort scale (a few ulp times the ~1e2 dynamic range between the terms)."""
    model = analytic_model(robot)
    gains = DEFAULT_GAINS[robot.kind]["ctc"]
    law = CTC(model, gains["kp"], gains["kd"], H, feedforward=feedforward)  # no saturation
    kp, kd = np.array(law.kp), np.array(law.kd)
    for k, (q, qd, q_ref, qd_ref, qdd_ref) in enumerate(zip(*_loop_inputs(model))):
        if feedforward:
            w = qdd_ref + kd * (qd_ref - qd) + kp * (q_ref - q)
        else:
            w = kp * (q_ref - q) - kd * qd
        expected = tuple(model.inverse_dynamics(q, qd, w).tolist())
        u = law.output_scalar(q, qd, q_ref, qd_ref, qdd_ref)
        assert u == expected, f"sample {k}: CTC {u} vs inverse_dynamics {expected}"
        vectorised = model.mass_matrix(q) @ w + model.velocity_term(q, qd) + model.gravity_term(q)
        scale = np.abs(model.mass_matrix(q)).max() * np.abs(w).max() + np.abs(vectorised).max()
        assert np.allclose(u, vectorised, rtol=0.0, atol=1e-13 * scale), \
            f"sample {k}: CTC {u} vs M @ w + C + G {vectorised}"
