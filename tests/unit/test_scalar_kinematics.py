"""The plain-float kinematics (delta.scalar_kinematics) against delta.kinematics, both robot kinds."""

import numpy as np
import pytest

from delta.errors import RobotError
from delta.kinematics import fk, ik, joint_rates, platform_velocity
from delta.robots import PRESETS, linear_delta_thesis
from delta.scalar_kinematics import ScalarKinematics
from delta.singularity import analyse, proximity_batch
from delta.workspace import check_point

# Both modules evaluate the same closed forms, only in a different order of operations
# (numpy arrays vs Python floats): they differ by rounding, a few ulps amplified by the
# conditioning of J, which stays below 1 / MARGIN = 20 on the sampled poses. 1e-12
# relative to max(1, |value|) (m, rad, per second, per second squared) leaves two orders
# of magnitude above that and still catches any wrong term.
AGREE_TOL = 1e-12
MARGIN = 0.05  # away from singularities, as in test_kinematics.py
N_POSES = 200


def _poses(robot, seed):
    """Random reachable poses with random platform velocities and accelerations."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < N_POSES:
        q = robot.q_min + (robot.q_max - robot.q_min) * rng.uniform(0.02, 0.98, 3)
        res = fk(robot, q)
        if not res.ok or analyse(robot, q, res.p).proximity <= MARGIN:
            continue
        out.append((res.p, rng.normal(0.0, 1.0, 3), rng.normal(0.0, 20.0, 3)))
    return out


def _assert_close(got, ref, what):
    got, ref = np.asarray(got, dtype=float), np.asarray(ref, dtype=float)
    err = np.abs(got - ref) / np.maximum(1.0, np.abs(ref))
    assert err.max() <= AGREE_TOL, f"{what}: scalar {got} vs delta.kinematics {ref} (rel. error {err.max():.2e})"


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_scalar_kinematics_agrees_with_delta_kinematics(name):
    robot = PRESETS[name]
    sk = ScalarKinematics(robot)
    for p, v, a in _poses(robot, seed=11):
        ref = ik(robot, p)
        q, leg = sk.ik(tuple(p))
        assert leg == 0 and ref.solvable, f"p = {p}: scalar leg {leg}, delta.kinematics {ref.reason}"
        _assert_close(q, ref.q, f"IK at p = {p}")
        qd, qdd = sk.joint_rates(q, tuple(p), tuple(v), tuple(a))
        qd_ref, qdd_ref = joint_rates(robot, ref.q, p, v, a)
        _assert_close(qd, qd_ref, f"joint velocity at p = {p}")
        _assert_close(qdd, qdd_ref, f"joint acceleration at p = {p}")
        _assert_close(sk.joint_rates(q, tuple(p), tuple(v))[1], 0.0, "qdd without a")
        _assert_close(sk.proximity(q, tuple(p)), proximity_batch(robot, ref.q, p)[0], f"proximity at p = {p}")
        p_fk = sk.fk(q)[0]
        _assert_close(p_fk, p, f"FK(IK(p)) at p = {p}")
        # the analytic model's platform velocity (same scalar FK) against J^-1 qd
        _assert_close(platform_velocity(robot, ref.q, p, qd_ref), v, f"J^-1 J v at p = {p}")


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_scalar_ik_reports_the_same_failing_leg(name):
    """Unreachable points: the same first failing leg as delta.workspace, and the same joint-limit leg."""
    robot = PRESETS[name]
    sk = ScalarKinematics(robot)
    rng = np.random.default_rng(5)
    seen = {"no solution": 0, "joint limit": 0}
    for _ in range(3000):
        p = rng.uniform(-1.2, 1.2, 3) * np.array([1.0, 1.0, 1.0])
        ref = check_point(robot, p)
        q, leg = sk.ik(tuple(p))
        if ref.failure.name == "NO_SOLUTION":
            seen["no solution"] += 1
            assert q is None and leg == ref.leg, f"p = {p}: scalar leg {leg}, delta.workspace {ref.reason}"
            continue
        assert leg == 0, f"p = {p}: scalar says leg {leg} has no solution, delta.workspace: {ref.reason}"
        limit = sk.limit_violation(q)
        if ref.failure.name == "JOINT_LIMIT":
            seen["joint limit"] += 1
            assert limit == ref.leg, f"p = {p}: scalar limit leg {limit}, delta.workspace {ref.reason}"
        else:
            assert limit == 0, f"p = {p}: scalar limit leg {limit} for a reachable point"
    assert min(seen.values()) > 0, f"the sample must exercise both failures: {seen}"


def test_unreachable_linear_point_names_the_leg():
    """The README's CLI example: (0.5, 0, -0.6) m is out of reach of leg 1."""
    assert ScalarKinematics(linear_delta_thesis).ik((0.5, 0.0, -0.6)) == (None, 1)
    assert ik(linear_delta_thesis, [0.5, 0.0, -0.6]).leg == 1


def test_type1_singularity_raises_naming_the_leg():
    """Linear leg 1 with its rod horizontal (carriage at platform height): l_1 . B_1' = 0, J is undefined."""
    sk = ScalarKinematics(linear_delta_thesis)
    p = (0.0, 0.0, -0.5)
    q, leg = sk.ik(p)
    assert leg == 0, f"p = {p} must be reachable"
    with pytest.raises(RobotError, match="leg 1"):
        sk.joint_rates((0.5, q[1], q[2]), p, (0.0, 0.0, 0.01))
