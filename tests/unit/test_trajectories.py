"""Analytic trajectories: derivatives, stops, timing, workspace checks, validation."""

import math

import numpy as np
import pytest

from delta.errors import ParameterError
from delta.robots import linear_delta_thesis, rotary_delta_prototype
from delta.trajectories import G0, Helix, Hold, PickAndPlace, PointToPoint, Waypoints, seed004_z_steps

# Central differences with step FD_STEP on motions with derivatives of order
# |x'''| <= ~1e4 (pick-and-place jerk): truncation |x'''| FD_STEP^2 / 6 ~ 2e-6 and rounding
# eps |x| / FD_STEP ~ 1e-10; compared relative to the signal's own scale.
FD_STEP = 1e-5
FD_RTOL = 1e-5
# Stops are evaluated in closed form (s(1) = 1, s'(1) = 0 exactly up to rounding).
STOP_ATOL = 1e-12

PICK = (-0.1525, 0.0, -0.50)
TRAJECTORIES = {
    "helix": Helix(),
    "ptp-quintic": PointToPoint((0.0, 0.0, -0.40), (0.10, -0.05, -0.50), 0.8),
    "ptp-cubic-t0": PointToPoint((0.0, 0.0, -0.40), (0.10, -0.05, -0.50), 0.8, profile="cubic", t0=0.3),
    "pick-and-place": PickAndPlace(PICK, cycles=2),
    "waypoints-times": Waypoints(((0, 0, -0.4), (0.05, 0, -0.45), (0.05, 0.05, -0.5)), times=(0.2, 0.7, 1.5)),
    "seed004": seed004_z_steps(),
}


def _interior_times(traj, n=40, guard=1e-3):
    """Times strictly inside segments (away from knots, where a cubic's acceleration jumps)."""
    rng = np.random.default_rng(7)
    t = rng.uniform(0.0, traj.end_time, 4 * n)
    knots = np.concatenate([getattr(traj, "_t0", []), getattr(traj, "_t1", [])])
    if len(knots):
        t = t[np.min(np.abs(t[:, None] - knots[None]), axis=1) > guard]
    return t[:n]


@pytest.mark.parametrize("name", list(TRAJECTORIES))
def test_derivatives_match_finite_differences(name):
    traj = TRAJECTORIES[name]
    t = _interior_times(traj)
    p, v, a = traj.sample(t)
    p_plus, v_plus, _ = traj.sample(t + FD_STEP)
    p_minus, v_minus, _ = traj.sample(t - FD_STEP)
    v_fd = (p_plus - p_minus) / (2 * FD_STEP)
    a_fd = (v_plus - v_minus) / (2 * FD_STEP)
    v_scale = max(np.abs(v).max(), 1e-3)
    a_scale = max(np.abs(a).max(), 1e-3)
    assert np.abs(v_fd - v).max() < FD_RTOL * v_scale, f"{name}: v {v[0]} vs finite difference {v_fd[0]}"
    assert np.abs(a_fd - a).max() < FD_RTOL * a_scale, f"{name}: a {a[0]} vs finite difference {a_fd[0]}"
    for k in range(0, len(t), 9):
        pe, ve, ae = traj.evaluate(t[k])
        assert np.array_equal(pe, p[k]) and np.array_equal(ve, v[k]) and np.array_equal(ae, a[k]), \
            f"{name}: evaluate({t[k]}) = {pe, ve, ae} vs sample {p[k], v[k], a[k]}"


def test_helix_formula_thesis_eq27():
    h = Helix()
    t = 0.25
    p, v, a = h.evaluate(t)
    expected = (0.1 * math.cos(math.pi * t), 0.1 * math.sin(math.pi * t), -0.45 - 0.01 * t)  # thesis eq. (27)
    assert np.allclose(p, expected, atol=1e-15), f"helix p {p} vs eq. (27) {expected}"
    assert h.duration == 10.0, f"default helix duration {h.duration} vs 10 s"


def test_pick_and_place_stops_at_stated_times():
    pp = PickAndPlace(PICK, cycles=2)
    stops = pp.waypoints
    expected = np.array([
        PICK, (-0.1525, 0, -0.475), (0.1525, 0, -0.475), (0.1525, 0, -0.5), (0.1525, 0, -0.475),
        (-0.1525, 0, -0.475), PICK,
    ])
    assert np.allclose(stops, expected, atol=STOP_ATOL), f"stops {stops} vs {expected}"
    times = pp.waypoint_times
    assert len(times) == 13, f"two cycles have 13 stops, got {len(times)}"
    assert abs(times[6] - 0.5) < STOP_ATOL and abs(times[-1] - 1.0) < STOP_ATOL, f"cycle ends at {times[6]}, {times[-1]}"
    p, v, a = pp.sample(times)
    assert np.allclose(p, np.concatenate([stops, stops[1:]]), atol=STOP_ATOL), f"positions at stops {p}"
    assert np.abs(v).max() < STOP_ATOL, f"velocity at stops must be 0, max {np.abs(v).max()}"
    assert np.abs(a).max() < STOP_ATOL, f"quintic acceleration at stops must be 0, max {np.abs(a).max()}"


def test_pick_and_place_default_peak_acceleration_is_about_7g():
    pp = PickAndPlace(PICK)
    _, _, a = pp.sample(np.linspace(0.0, pp.duration, 200_001))
    peak = np.linalg.norm(a, axis=1).max()
    # Dense sampling (2.5 us) of a smooth peak: within 1e-6 relative of the analytic value.
    assert abs(peak - pp.peak_acceleration) < 1e-6 * peak, f"sampled {peak} vs analytic {pp.peak_acceleration}"
    assert 6.5 * G0 < peak < 7.5 * G0, f"default cycle peak acceleration {peak / G0:.2f} g, expected about 7 g"


def test_seed004_sequence_and_waypoints_arrivals():
    s = seed004_z_steps(segment_time=1.0, dwell=0.5)
    arrivals = s.arrival_times
    assert np.allclose(arrivals, [0.0, 1.0, 2.5, 4.0]), f"arrival times {arrivals}"
    p, v, _ = s.sample(arrivals)
    assert np.allclose(p[:, 2], [-0.411, -0.561, -0.311, -0.411], atol=STOP_ATOL), f"z at arrivals {p[:, 2]}"
    assert np.abs(v).max() < STOP_ATOL, f"rest at every arrival, max |v| {np.abs(v).max()}"
    p_dwell, v_dwell, _ = s.sample(np.array([1.25]))
    assert abs(p_dwell[0, 2] + 0.561) < STOP_ATOL and np.abs(v_dwell).max() == 0.0, f"dwell {p_dwell}, {v_dwell}"
    assert s.check(rotary_delta_prototype).ok, s.check(rotary_delta_prototype).message()


def test_ptp_holds_before_t0_and_after_end():
    ptp = TRAJECTORIES["ptp-cubic-t0"]
    assert ptp.end_time == pytest.approx(1.1, abs=1e-15), f"end_time {ptp.end_time} vs t0 + duration = 1.1"
    p, v, a = ptp.sample(np.array([0.0, 0.2, 2.0]))
    assert np.allclose(p[:2], ptp.start) and np.allclose(p[2], ptp.end), f"held positions {p}"
    assert np.abs(v).max() == 0.0 and np.abs(a).max() == 0.0, f"at rest outside the move: v {v}, a {a}"


def test_workspace_check():
    assert Helix().check(linear_delta_thesis).ok, Helix().check(linear_delta_thesis).message()
    assert PickAndPlace(PICK).check(linear_delta_thesis).ok, "pick-and-place must fit the thesis robot"
    bad = Helix(z0=-0.05)  # above the top of the rails (q_min = 70 mm)
    result = bad.check(linear_delta_thesis)
    assert not result.ok and "joint limit" in result.reason, f"expected a joint-limit failure, got {result.message()}"
    with pytest.raises(ParameterError, match="endless"):
        Helix(duration=math.inf).check(linear_delta_thesis)


@pytest.mark.parametrize("make,match", [
    (lambda: Helix(rx=-0.1), "rx"),
    (lambda: PointToPoint((0, 0, 0), (0, 0, -1), 0.0), "duration"),
    (lambda: PointToPoint((0, 0), (0, 0, -1), 1.0), "start"),
    (lambda: PointToPoint((0, 0, 0), (0, 0, -1), 1.0, profile="septic"), "profile"),
    (lambda: PickAndPlace(PICK, cycle_time=-1.0), "cycle_time"),
    (lambda: PickAndPlace(PICK, direction=(0, 0)), "direction"),
    (lambda: Waypoints(((0, 0, 0), (0, 0, 1)), segment_time=1.0, times=(0, 1)), "exactly one"),
    (lambda: Waypoints(((0, 0, 0), (0, 0, 1)), times=(1.0, 0.5)), "increasing"),
    (lambda: Hold((0, 0, -0.4), duration=0.0), "duration"),
])
def test_validation_errors(make, match):
    with pytest.raises(ParameterError, match=match):
        make()


def _scalar_times(traj):
    """Dense times over the motion and beyond it, plus every knot (where tau clips and v, a switch)."""
    end = traj.end_time
    knots = np.concatenate([getattr(traj, "_t0", []), getattr(traj, "_t1", [])])
    return np.concatenate([np.linspace(-0.2, end + 0.2, 2001), knots, np.nextafter(knots, np.inf),
                           np.nextafter(knots, -np.inf)])


@pytest.mark.parametrize("name", list(TRAJECTORIES) + ["hold"])
def test_scalar_path_equals_vectorised(name):
    """evaluate_scalar (math on floats) performs sample's IEEE operations in the same order, and
    cos/sin come from the same correctly rounded libm results here, so equality is exact
    (tolerance 0, the contract evaluate already had with sample)."""
    traj = TRAJECTORIES.get(name) or Hold((0.05, -0.02, -0.5), duration=0.7)
    times = _scalar_times(traj)
    p, v, a = traj.sample(times)
    for k, t in enumerate(times):
        ps, vs, as_ = traj.evaluate_scalar(float(t))
        assert all(type(x) is float for x in ps + vs + as_), f"{name}: not plain floats at t = {t}: {ps, vs, as_}"
        assert (ps, vs, as_) == (tuple(p[k]), tuple(v[k]), tuple(a[k])), \
            f"{name}: evaluate_scalar({t!r}) = {ps, vs, as_} vs sample {p[k], v[k], a[k]}"
    pe, ve, ae = traj.evaluate(times[7])
    assert all(isinstance(x, np.ndarray) and x.shape == (3,) for x in (pe, ve, ae)), \
        f"{name}: evaluate must return three (3,) arrays, got {pe!r}, {ve!r}, {ae!r}"


def test_scalar_path_default_samples():
    """A trajectory that only defines sample gets evaluate / evaluate_scalar from it."""
    from delta.trajectories import Trajectory

    class Line(Trajectory):
        duration = 1.0

        def sample(self, times):
            t = np.asarray(times, dtype=float).reshape(-1)
            return np.stack([t, 2 * t, 3 * t], 1), np.ones((len(t), 3)), np.zeros((len(t), 3))

    assert Line().evaluate_scalar(0.5) == ((0.5, 1.0, 1.5), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0)), \
        f"default evaluate_scalar: {Line().evaluate_scalar(0.5)}"
    p, _, _ = Line().evaluate(0.5)
    assert np.array_equal(p, [0.5, 1.0, 1.5]), f"default evaluate: {p} vs [0.5, 1.0, 1.5]"
