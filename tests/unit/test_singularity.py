"""Singularity classification (seed 003)."""

import numpy as np
import pytest

from scipy.optimize import brentq

from delta.kinematics import actuator_points, fk, ik, platform_offsets
from delta.robots import linear_delta_thesis, rotary_delta_3rrr, rotary_delta_prototype
from delta.singularity import analyse, analyse_pose


def _stretched_z(robot):
    reach = robot.arm_length + robot.forearm_length
    return -np.sqrt(reach**2 - (robot.base_radius - robot.platform_radius) ** 2)


def test_all_legs_stretched_is_type_1():
    r = rotary_delta_3rrr
    p = np.array([0.0, 0.0, _stretched_z(r)])
    rep = analyse_pose(r, p=p)
    assert rep.type1_legs == (1, 2, 3), rep.kind
    assert np.allclose(rep.theta2, 0.0, atol=1e-6), np.degrees(rep.theta2)
    assert rep.proximity < 1e-6, rep.proximity


def test_one_leg_stretched_is_type_1_on_that_leg():
    r = rotary_delta_3rrr
    # Leg 1 stretched in its plane: platform joint at arm + forearm length from the motor axis.
    # Leg 1 stretched in its plane: its platform joint at arm + forearm length from the
    # motor axis. At z = -0.22 m the point lies just past the base axis, where legs 2 and
    # 3 still reach it.
    reach = r.arm_length + r.forearm_length
    z = -0.22
    p = np.array([r.base_radius - r.platform_radius - np.sqrt(reach**2 - z**2), 0.0, z])
    q = ik(r, p).q
    assert q is not None
    rep = analyse(r, q, p)
    assert 1 in rep.type1_legs and abs(rep.theta2[0]) < 1e-6, (rep.kind, np.degrees(rep.theta2))
    assert not rep.type2


def test_regular_pose_is_not_singular():
    r = rotary_delta_prototype
    rep = analyse_pose(r, p=np.array([0.0, 0.0, r.home_z]))
    assert not rep.singular and rep.proximity > 0.1, rep


def _circumradius(pts):
    a, b = pts[1] - pts[0], pts[2] - pts[0]
    return np.linalg.norm(a) * np.linalg.norm(b) * np.linalg.norm(a - b) / (2 * np.linalg.norm(np.cross(a, b)))


def test_type_2_when_rods_are_coplanar():
    """Type 2 lies where the platform reaches the plane of the three sphere centres
    (rods coplanar, det J_p = 0), the edge between assembly modes. Build one on the
    linear delta by lowering carriage 3 until the centres' circumradius equals the rod
    length; the platform is then the circumcentre."""
    r = linear_delta_thesis

    def centres(x):
        return actuator_points(r, np.array([0.5, 0.5, x])) - platform_offsets(r)

    x = brentq(lambda x: _circumradius(centres(x)) - r.rod_length, 0.5, 0.5 + 2 * r.rod_length, xtol=1e-15)
    c = centres(x)
    a, b = c[1] - c[0], c[2] - c[0]
    n = np.cross(a, b)
    p = c[0] + np.cross((a @ a) * b - (b @ b) * a, n) / (2 * (n @ n))
    rods = p + platform_offsets(r) - actuator_points(r, np.array([0.5, 0.5, x]))
    assert np.allclose(np.linalg.norm(rods, axis=1), r.rod_length, atol=1e-12)
    rep = analyse(r, np.array([0.5, 0.5, x]), p, tolerance=1e-9)
    assert rep.type2, f"det of unit rods = {rep.parallel}"
    assert not rep.type1_legs, rep.serial
    assert rep.proximity < 1e-9


@pytest.mark.parametrize("name", ["linear_delta_thesis", "rotary_delta_prototype"])
def test_analyse_pose_by_joints_or_position_agree(name):
    """A pose given by its joint values (forward kinematics) or by its position (inverse kinematics)."""
    from delta.robots import PRESETS

    robot = PRESETS[name]
    q = ik(robot, [0.03, -0.02, -0.47 if robot.kind == "linear" else -0.45]).require()
    by_q, by_p = analyse_pose(robot, q=q), analyse_pose(robot, p=fk(robot, q).require())
    assert np.allclose(by_q.p, by_p.p, atol=1e-12) and np.allclose(by_q.q, q, atol=1e-12), (by_q, by_p)
    assert abs(by_q.proximity - by_p.proximity) < 1e-12 and by_q.kind == by_p.kind == "regular"
