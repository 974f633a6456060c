"""The per-pose float path of delta.kinematics against its batch path and independent references.

One set of leg formulas serves both paths (floats for one pose, numpy arrays for many); these
tests check the plumbing around them: every pose gives the same answer either way, the closed-form
singularity proximity equals the SVD of the unit-row J_p computed here, FK(IK(p)) = p.
"""

import numpy as np
import pytest

from delta.errors import RobotError
from delta.kinematics import (
    fk,
    ik_batch,
    inverse_kinematics,
    platform_velocity,
    proximity,
    proximity_batch,
    rates,
    rates_batch,
    rod_vectors,
    set_pose,
    solve_ik,
    update,
)
from delta.model import Data, build_model
from delta.robots import PRESETS, linear_delta_thesis
from delta.singularity import analyse
from delta.workspace import check_point

# The two paths evaluate the same closed forms, in floats or in arrays (numpy may fuse or reorder
# nothing here, but its transcendental functions may differ from libm's by an ulp), amplified by
# the conditioning of J, which stays below 1 / MARGIN = 20 on the sampled poses. 1e-12 relative to
# max(1, |value|) (m, rad, per second, per second squared) leaves two orders of magnitude above
# that and still catches any wrong term.
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
        out.append((q, res.p, rng.normal(0.0, 1.0, 3), rng.normal(0.0, 20.0, 3)))
    return out


def _assert_close(got, ref, what):
    got, ref = np.asarray(got, dtype=float), np.asarray(ref, dtype=float)
    err = np.abs(got - ref) / np.maximum(1.0, np.abs(ref))
    assert err.max() <= AGREE_TOL, f"{what}: {got} vs {ref} (rel. error {err.max():.2e})"


def _svd_proximity(robot, q, p):
    """min(serial measures, sigma_min / sigma_max of the unit rods), by numpy's SVD."""
    rods = rod_vectors(robot, q, p)
    unit = rods / np.linalg.norm(rods, axis=1, keepdims=True)
    s = np.linalg.svd(unit, compute_uv=False)
    return min(analyse(robot, q, p).serial.min(), s[-1] / s[0])


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_float_path_agrees_with_batch_path_and_references(name):
    robot = PRESETS[name]
    model = build_model(robot)
    poses = _poses(robot, seed=11)
    p_all, v_all, a_all = (np.array([x[k] for x in poses]) for k in (1, 2, 3))
    q_batch, ok = ik_batch(model, p_all)
    assert ok.all()
    qd_batch, qdd_batch = rates_batch(model, q_batch, p_all, v_all, a_all)
    prox_batch = proximity_batch(model, q_batch, p_all)
    data = Data(model)
    for k, (q0, p, v, a) in enumerate(poses):
        q, qd, qdd, fault = inverse_kinematics(model, tuple(p), tuple(v), tuple(a))
        assert fault == 0, f"p = {p}: fault {fault}"
        _assert_close(q, q0, f"IK(FK(q)) at q = {q0}")
        _assert_close(q, q_batch[k], f"IK at p = {p}, float vs batch")
        _assert_close(qd, qd_batch[k], f"joint velocity at p = {p}")
        _assert_close(qdd, qdd_batch[k], f"joint acceleration at p = {p}")
        set_pose(model, data, q, tuple(p))
        _assert_close(rates(data, tuple(v), tuple(a)), (qd, qdd), f"rates at the pose of p = {p}")
        _assert_close(rates(data, tuple(v))[1], 0.0, "qdd without a")
        _assert_close(proximity(data), prox_batch[k], f"proximity at p = {p}, float vs batch")
        _assert_close(proximity(data), _svd_proximity(robot, q0, p), f"closed-form proximity vs SVD at p = {p}")
        update(model, data, q)
        assert np.abs(np.array(data.p) - p).max() <= 1e-12, f"FK(IK(p)) = {data.p} vs p = {p}"
        _assert_close(platform_velocity(robot, q0, p, qd), v, f"J^-1 J v at p = {p}")


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_float_ik_reports_the_same_failing_leg_as_the_workspace(name):
    """Unreachable points: the same first failing leg as delta.workspace, and the same joint-limit leg."""
    robot = PRESETS[name]
    model = build_model(robot)
    rng = np.random.default_rng(5)
    seen = {"no solution": 0, "joint limit": 0}
    for _ in range(3000):
        p = rng.uniform(-1.2, 1.2, 3)
        ref = check_point(robot, p)
        q, leg = solve_ik(model, tuple(p))
        fault = inverse_kinematics(model, tuple(p))[3]  # positions only
        if ref.failure.name == "NO_SOLUTION":
            seen["no solution"] += 1
            assert q is None and leg == ref.leg == fault, f"p = {p}: leg {leg}, delta.workspace {ref.reason}"
            continue
        assert leg == 0, f"p = {p}: leg {leg} has no solution, delta.workspace: {ref.reason}"
        if ref.failure.name == "JOINT_LIMIT":
            seen["joint limit"] += 1
            assert -fault == ref.leg, f"p = {p}: fault {fault}, delta.workspace {ref.reason}"
        else:
            assert fault == 0, f"p = {p}: fault {fault} for a reachable point"
    assert min(seen.values()) > 0, f"the sample must exercise both failures: {seen}"


def test_unreachable_linear_point_names_the_leg():
    """The CLI example of docs/core.md: (0.5, 0, -0.6) m is out of reach of leg 1."""
    assert solve_ik(build_model(linear_delta_thesis), (0.5, 0.0, -0.6)) == (None, 1)


def test_type1_singularity_raises_naming_the_leg():
    """Linear leg 1 with its rod horizontal (carriage at platform height): l_1 . B_1' = 0, J is undefined."""
    model = build_model(linear_delta_thesis)
    p = (0.0, 0.0, -0.5)
    q, leg = solve_ik(model, p)
    assert leg == 0, f"p = {p} must be reachable"
    data = set_pose(model, Data(model), (0.5, q[1], q[2]), p)
    with pytest.raises(RobotError, match="leg 1"):
        rates(data, (0.0, 0.0, 0.01))
