"""Kinematics of the three presets against the papers and against themselves."""

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from delta.paper_data import THESIS_TABLE_4_CM
from delta.kinematics import (
    fk,
    hessians,
    ik,
    jacobian,
    joint_acceleration,
    joint_velocity,
    platform_acceleration,
    platform_velocity,
)
from delta.robots import PRESETS, linear_delta_thesis, rotary_delta_prototype
from delta.singularity import analyse

# Thesis Table 4: platform position (cm) -> carriage travels L1, L2, L3 (cm).
THESIS_TABLE_4 = THESIS_TABLE_4_CM
# The table is printed to 2-4 significant digits and its first row is not even
# symmetric (L3 != L1 at x = y = 0), so 0.02 cm is the resolution of the table.
TABLE_4_TOL_CM = 0.02
# Closed-form round trips are exact up to rounding: a few ulps of 1 m, amplified by
# the conditioning of the three-sphere intersection away from singularities.
ROUND_TRIP_TOL_M = 1e-12
# Central differences with step h have truncation O(h^2) ~ 1e-10 and rounding
# O(eps / h) ~ 1e-10 relative: 1e-6 leaves a wide margin and still catches any
# wrong term (a missing factor or sign gives O(1) relative errors).
FD_RTOL = 1e-6


@pytest.mark.parametrize("p_cm, q_cm", THESIS_TABLE_4)
def test_thesis_table_4_inverse_kinematics(p_cm, q_cm):
    res = ik(linear_delta_thesis, np.array(p_cm) / 100.0)
    assert res.solvable, res.reason
    got = res.q * 100.0
    assert np.allclose(got, q_cm, atol=TABLE_4_TOL_CM), f"IK {got} cm vs thesis Table 4 {q_cm} cm"


def test_thesis_table_3_row_6_is_inconsistent_with_table_4():
    """Thesis Table 3 row 6 gives FK(35, 35, 39 cm) = (0, -3.981, -64.22) cm; our FK is the
    exact inverse of our IK (which matches Table 4), so it cannot reproduce that row: the
    thesis's own Table 4 maps (0, -5, -64) cm to 31.33/31.33/35.82 cm, far from 35/35/39."""
    p = fk(linear_delta_thesis, np.array([0.35, 0.35, 0.39])).require()
    assert abs(p[2] * 100 - (-64.22)) > 1.0, f"FK z = {p[2] * 100:.3f} cm unexpectedly matches Table 3"
    q_back = ik(linear_delta_thesis, p).q
    assert np.allclose(q_back, [0.35, 0.35, 0.39], atol=ROUND_TRIP_TOL_M)


def test_seed_004_home_and_z_steps():
    r = rotary_delta_prototype
    assert r.home_z * 1e3 == pytest.approx(-410.8, abs=0.05), f"home z = {r.home_z * 1e3:.3f} mm, paper -410.8 mm"
    assert np.allclose(ik(r, [0, 0, r.home_z]).q, 0.0, atol=1e-12)
    down = np.degrees(ik(r, [0, 0, -0.561]).require())
    up = np.degrees(ik(r, [0, 0, -0.311]).require())
    # The paper prints whole degrees (38 and -40); we state one decimal: 38.2 and -40.0.
    assert np.allclose(down, 38.2, atol=0.05), f"IK at z = -561 mm: {down} deg, expected 38.2"
    assert np.allclose(up, -40.0, atol=0.05), f"IK at z = -311 mm: {up} deg, expected -40.0"


def _sample_q(robot, fractions):
    lo, hi = robot.q_min, robot.q_max
    return lo + (hi - lo) * np.asarray(fractions)


fractions = st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3)
MARGIN = 0.05  # keep away from singularities, where the round trip loses digits by design


@pytest.mark.parametrize("name", sorted(PRESETS))
@given(fr=fractions)
def test_ik_fk_round_trip(name, fr):
    robot = PRESETS[name]
    q = _sample_q(robot, fr)
    res = fk(robot, q)
    assume(res.ok)
    assume(analyse(robot, q, res.p).proximity > MARGIN)
    back = ik(robot, res.p)
    assert back.solvable, back.reason
    assert np.allclose(back.q, q, atol=ROUND_TRIP_TOL_M, rtol=0), f"IK(FK(q)) = {back.q} vs q = {q}"
    again = fk(robot, back.q).p
    assert np.allclose(again, res.p, atol=ROUND_TRIP_TOL_M, rtol=0), f"FK(IK(p)) = {again} vs p = {res.p}"


def _random_pose(robot, rng):
    while True:
        q = _sample_q(robot, rng.uniform(0.1, 0.9, 3))
        res = fk(robot, q)
        if res.ok and analyse(robot, q, res.p).proximity > MARGIN:
            return q, res.p


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_jacobian_and_hessians_match_finite_differences(name):
    robot = PRESETS[name]
    rng = np.random.default_rng(7)
    for _ in range(20):
        q, p = _random_pose(robot, rng)
        h = 1e-6 * max(abs(p).max(), 0.1)
        jac = jacobian(robot, q, p)
        hess = hessians(robot, q, p)
        for k in range(3):
            dp = np.zeros(3)
            dp[k] = h
            qp, qm = ik(robot, p + dp).q, ik(robot, p - dp).q
            col = (qp - qm) / (2 * h)
            assert np.allclose(jac[:, k], col, rtol=FD_RTOL, atol=FD_RTOL * abs(jac).max()), \
                f"J[:, {k}] = {jac[:, k]} vs FD {col}"
            jp = jacobian(robot, qp, p + dp)
            jm = jacobian(robot, qm, p - dp)
            dcol = (jp - jm) / (2 * h)  # d J_i / d p_k = H_i[:, k]
            for i in range(3):
                scale = abs(hess[i]).max()
                assert np.allclose(hess[i][:, k], dcol[i], rtol=FD_RTOL, atol=FD_RTOL * scale), \
                    f"H_{i + 1}[:, {k}] = {hess[i][:, k]} vs FD {dcol[i]}"


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_velocity_and_acceleration_maps_are_inverse(name):
    robot = PRESETS[name]
    rng = np.random.default_rng(11)
    for _ in range(20):
        q, p = _random_pose(robot, rng)
        v, a = rng.normal(size=3), rng.normal(size=3)
        qd = joint_velocity(robot, q, p, v)
        qdd = joint_acceleration(robot, q, p, v, a)
        assert np.allclose(platform_velocity(robot, q, p, qd), v, rtol=1e-9, atol=1e-12)
        assert np.allclose(platform_acceleration(robot, q, p, v, qdd), a, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_joint_acceleration_matches_trajectory_second_derivative(name):
    """qdd = J a + [v^T H_i v] (thesis eq. 22) against d2/dt2 IK(p(t)) along a curve."""
    robot = PRESETS[name]
    q0, p0 = _random_pose(robot, np.random.default_rng(3))
    v, a = np.array([0.05, -0.03, 0.02]), np.array([0.4, 0.2, -0.3])

    def q_of(t):
        return ik(robot, p0 + v * t + 0.5 * a * t * t).q

    dt = 1e-4
    fd = (q_of(dt) - 2 * q_of(0.0) + q_of(-dt)) / dt**2
    ana = joint_acceleration(robot, q0, p0, v, a)
    # second differences: truncation O(dt^2) and rounding O(eps q / dt^2) ~ 1e-8 absolute
    assert np.allclose(ana, fd, rtol=1e-5, atol=1e-6), f"qdd analytic {ana} vs FD {fd}"
