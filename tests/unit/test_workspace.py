"""Workspace checks: seed 004's cylinder limits, reasons, trajectory checks."""

import numpy as np

from delta.robots import linear_delta_thesis, rotary_delta_prototype
from delta.workspace import (
    Failure,
    check_cylinder,
    check_point,
    check_trajectory,
    largest_cylinder,
    sample_workspace,
)

HOME = np.array([0.0, 0.0, rotary_delta_prototype.home_z])
# Seed 004 traces the lateral surface of the cylinder (60 azimuths x 20 rings in its
# MATLAB listing) and reports "Out of workspace!" where IK has no real solution.
SEED004 = {"surface_only": True, "check_limits": False}


def test_seed_004_cylinder_is_reachable():
    res = check_cylinder(rotary_delta_prototype, HOME, 0.200, 0.150, 0.250, **SEED004)
    assert res.ok, res.reason


def test_seed_004_cylinder_bottom_ring_respects_upper_joint_limit():
    """The paper's +110 deg limit (Table 7) is the largest arm angle on the cylinder:
    we find 109.87 deg on the bottom ring, within the limit."""
    res = check_cylinder(rotary_delta_prototype, HOME, 0.200, 0.0, 0.250, surface_only=True, check_limits=True)
    assert res.ok, res.reason


def test_seed_004_cylinder_top_ring_exceeds_lower_joint_limit():
    """Documented discrepancy: on the top ring (z2 = +150 mm, R = 250 mm) our IK needs
    -100.7 deg, beyond the paper's -85 deg; within -85 deg the top ring is limited to
    about +132 mm. See docs/figures.md, 'Known discrepancies with the papers'."""
    res = check_cylinder(rotary_delta_prototype, HOME, 0.200, 0.150, 0.250, surface_only=True, check_limits=True)
    assert res.failure is Failure.JOINT_LIMIT, res.reason
    z_above = largest_cylinder(rotary_delta_prototype, HOME, z_below=0.2, radius=0.25, surface_only=True)
    assert 0.125 < z_above < 0.140, f"z2 within joint limits = {z_above * 1e3:.1f} mm"


def test_seed_004_z1_210_is_out_of_workspace():
    res = check_cylinder(rotary_delta_prototype, HOME, 0.210, 0.150, 0.250, **SEED004)
    assert res.failure is Failure.NO_SOLUTION, res.reason
    assert "has no solution" in res.reason


def test_seed_004_workspace_limits_match_paper():
    """Paper: z1 limit near -204 mm (Table 4) and z2 limit 159 mm (Table 5) for R = 250 mm.
    Bisection tolerance 0.1 mm; the paper's figures are read off a path sampled every few mm."""
    z1 = largest_cylinder(rotary_delta_prototype, HOME, z_above=0.150, radius=0.250, **SEED004)
    z2 = largest_cylinder(rotary_delta_prototype, HOME, z_below=0.200, radius=0.250, **SEED004)
    assert 0.200 < z1 < 0.205, f"z1 limit = -{z1 * 1e3:.1f} mm, paper -204 mm"
    assert 0.155 < z2 < 0.160, f"z2 limit = {z2 * 1e3:.1f} mm, paper 159 mm"


def test_check_point_reasons():
    r = linear_delta_thesis
    far = check_point(r, [0.5, 0.0, -0.6])
    assert far.failure is Failure.NO_SOLUTION and far.leg is not None, far
    high = check_point(r, [0.0, 0.0, -0.33])  # carriages above their 70 mm stroke start
    assert high.failure is Failure.JOINT_LIMIT and "q_min" in high.reason, high
    ok = check_point(r, [0.0, -0.05, -0.64], singularity_margin=0.05)
    assert ok.ok and ok.proximity > 0.05, ok
    tight = check_point(r, [0.0, -0.05, -0.64], singularity_margin=0.99)
    assert tight.failure is Failure.SINGULARITY and "singularity" in tight.reason


def test_trajectory_check_reports_first_offending_time():
    t = np.linspace(0.0, 10.0, 1001)

    def line(times):
        return np.stack([0.05 * times, np.zeros_like(times), np.full_like(times, -0.6)], axis=1)

    res = check_trajectory(linear_delta_thesis, line, t)
    assert not res.ok
    before = check_point(linear_delta_thesis, line(np.array([res.t - 0.01]))[0])
    assert before.ok, f"the sample before t = {res.t} should be reachable: {before.reason}"
    assert res.message().startswith(f"out of workspace at t = {res.t:.2f} s: p = (")


def test_sampled_workspace_contains_thesis_points():
    ws = sample_workspace(linear_delta_thesis, spacing=0.02)
    assert ws.volume > 0.0
    for p in ([0.0, -0.05, -0.64], [-0.02, 0.004, -0.61]):
        assert np.all(ws.bbox_min - 0.02 <= p) and np.all(p <= ws.bbox_max + 0.02), (p, ws.bbox_min, ws.bbox_max)


def test_sampled_volume_converges():
    """Halving the grid step changes the volume by less than 5 %: the estimate is resolved."""
    coarse = sample_workspace(rotary_delta_prototype, spacing=0.03).volume
    fine = sample_workspace(rotary_delta_prototype, spacing=0.015).volume
    assert abs(fine - coarse) / fine < 0.05, (coarse, fine)
