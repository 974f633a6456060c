"""Exudyn delta plants: kinematic consistency, energy conservation, inverse dynamics vs the analytic model.

Solver settings (unless stated): generalized-alpha index 3, spectral radius 0.8, modified Newton,
relative tolerance 1e-6, EigenSparse (full) / dense (lumped), h = 1 ms.
"""

from __future__ import annotations

import numpy as np
import pytest

from delta.dynamics import LinearDeltaMasses, RotaryDeltaMasses, analytic_model
from delta.errors import DeltaError
from delta.kinematics import fk
from delta.robots import linear_delta_thesis, rotary_delta_prototype
from delta.trajectories import Helix, PickAndPlace
from multibody import PlantError, SolverSettings, make_plant
from multibody.validate import force_errors, run_prescribed

pytestmark = pytest.mark.integration

FK_TOL = 1e-10  # m: index-3 constraints solved to the default Newton tolerance (measured <= 2e-11); FK is closed form
LEVEL_TOL = 1e-9  # rad: parallelograms keep the platform level exactly (up to constraint residual)
ENERGY_TOL = 1e-4  # relative drift over 1 s (issue target) with spectral radius 0.8 at h = 1 ms


def _drive(plant, n: int, h: float = 1e-3):
    """Gravity compensation from the analytic model plus a 2 Hz wobble; yields outputs."""
    model = analytic_model(plant.robot, plant.masses)
    amp = 2.0 if plant.kind == "linear" else 0.2
    for k in range(n):
        q = plant.output.q
        u = model.gravity_term(q) + amp * np.sin(2 * np.pi * 2.0 * plant.time + np.array([0.0, 2.0, 4.0]))
        yield plant.step(plant.time, h, u)


@pytest.mark.parametrize("robot,p0,n", [(linear_delta_thesis, (0.03, -0.02, -0.45), 300),
                                        (rotary_delta_prototype, (0.03, -0.02, -0.45), 200)])
def test_platform_matches_fk_and_stays_level(robot, p0, n):
    plant = make_plant(robot, fidelity="full", p0=p0, v0=(0.05, 0.0, 0.0))
    fk_err = tilt = 0.0
    for out in _drive(plant, n):
        fk_err = max(fk_err, float(np.linalg.norm(fk(robot, out.q).require() - out.p)))
        tilt = max(tilt, plant.platform_tilt())
    moved = np.linalg.norm(plant.output.p - np.array(p0))
    print(f"{robot.name}: max |p - FK(q)| = {fk_err:.3e} m, max tilt = {tilt:.3e} rad, moved {moved:.3f} m")
    assert moved > 1e-3, f"the driven motion moved the platform only {moved} m"
    assert fk_err < FK_TOL, f"|p - FK(q)| = {fk_err} m >= {FK_TOL} m"
    assert tilt < LEVEL_TOL, f"platform tilt {tilt} rad >= {LEVEL_TOL} rad"


@pytest.mark.parametrize("robot,masses,fidelity,p0", [
    # linear: from z = -0.5 m the coasting carriages stay within 0.10..0.19 m, clear of the end stop
    # at q_min = 0.07 m, which a start at z = -0.45 m reaches after 0.8 s (the plant then stops)
    (linear_delta_thesis, LinearDeltaMasses(gravity=0.0), "full", (0.0, 0.0, -0.5)),
    (linear_delta_thesis, LinearDeltaMasses(gravity=0.0), "lumped", (0.0, 0.0, -0.5)),
    (rotary_delta_prototype, RotaryDeltaMasses(gravity=0.0), "full", (0.0, 0.0, -0.45)),
])
def test_energy_conserved_without_actuation(robot, masses, fidelity, p0):
    # no gravity (the platform would otherwise fall out of the workspace within 1 s), no effort,
    # no damping: the coasting mechanism exchanges kinetic energy between carriages/arms and platform
    plant = make_plant(robot, masses, fidelity=fidelity, p0=p0, v0=(0.08, -0.05, 0.03))
    e0 = sum(plant.energy())
    drift = 0.0
    for _ in range(1000):
        plant.step(plant.time, 1e-3, (0.0, 0.0, 0.0))
        drift = max(drift, abs(sum(plant.energy()) - e0) / e0)
    print(f"{robot.name} {fidelity}: E0 = {e0:.6e} J, max relative drift over 1 s = {drift:.3e}")
    assert drift < ENERGY_TOL, f"relative energy drift {drift} >= {ENERGY_TOL}"


def test_step_rejects_wrong_time():
    plant = make_plant(linear_delta_thesis, fidelity="lumped", p0=(0.0, 0.0, -0.45))
    plant.step(0.0, 1e-3, (0.0, 0.0, 0.0))
    with pytest.raises(PlantError, match="0.005") as info:
        plant.step(0.005, 1e-3, (0.0, 0.0, 0.0))
    assert isinstance(info.value, DeltaError)


MASSLESS_FORCE_TOL = 0.005  # relative RMS (issue target): with massless rods the models are the same physics


@pytest.mark.parametrize("name,trajectory", [
    ("pick 25/305/25 mm, 0.5 s (~7 g)", PickAndPlace(start=(-0.15, 0.0, -0.45))),
    ("helix, first 0.5 s", Helix(duration=0.5)),
])
def test_inverse_dynamics_massless_rods_match_analytic(name, trajectory):
    masses = LinearDeltaMasses(rod=0.0)
    run = run_prescribed(linear_delta_thesis, trajectory, masses, h=2e-4, duration=0.5)
    rms, peak = force_errors(run, linear_delta_thesis, masses)
    print(f"{name}: massless rods, full plant vs analytic: RMS {rms:.3%}, peak {peak:.3%}")
    assert rms < MASSLESS_FORCE_TOL, f"RMS force error {rms} >= {MASSLESS_FORCE_TOL}"


LUMPED_FORCE_TOL = 0.005  # relative RMS: the lumped plant *is* the analytic model's physics (validation floor)


def test_lumped_plant_matches_analytic_with_rod_mass():
    masses = LinearDeltaMasses()
    run = run_prescribed(linear_delta_thesis, PickAndPlace(start=(-0.15, 0.0, -0.45)), masses, h=2e-4,
                         duration=0.5, fidelity="lumped")
    rms, peak = force_errors(run, linear_delta_thesis, masses)
    print(f"lumped plant vs analytic (w = 2/3): RMS {rms:.3%}, peak {peak:.3%}")
    assert rms < LUMPED_FORCE_TOL, f"RMS force error {rms} >= {LUMPED_FORCE_TOL}"


REUSE_FACTORISATIONS = 0.5  # per step: at most one in two (1.0 without reuse). Measured with the wobble below, since a
# kept matrix is refactorised once modified Newton needs a 4th iteration (REUSE_MAX_MODIFIED_ITERATIONS = 3): linear 0.24,
# rotary 0.13 (0.09 / 0.04 with 4, at the same time per step while the platform moves)


@pytest.mark.parametrize("robot,n", [(linear_delta_thesis, 300), (rotary_delta_prototype, 200)], ids=["linear", "rotary"])
def test_reused_jacobian_keeps_kinematics_and_refactorises_rarely(robot, n):
    """SolverSettings(reuse_jacobian=True): Newton still converges on every step (a failure raises) to a state
    as consistent as the default's, while the Newton matrix is factorised on few steps."""
    p0 = (0.03, -0.02, -0.45)
    plant = make_plant(robot, fidelity="full", p0=p0, v0=(0.05, 0.0, 0.0), settings=SolverSettings(reuse_jacobian=True))
    fk_err = 0.0
    for out in _drive(plant, n):
        fk_err = max(fk_err, float(np.linalg.norm(fk(robot, out.q).require() - out.p)))
    factorisations = plant._it.newtonJacobiCount / n
    print(f"{robot.name}: reuse_jacobian: max |p - FK(q)| = {fk_err:.3e} m, factorisations per step {factorisations:.3f}, "
          f"Newton iterations per step {plant._it.newtonStepsCount / n:.2f}")
    assert fk_err < FK_TOL, f"|p - FK(q)| = {fk_err} m >= {FK_TOL} m"
    assert factorisations <= REUSE_FACTORISATIONS, f"{factorisations} factorisations per step > {REUSE_FACTORISATIONS}"


@pytest.mark.parametrize("robot,n", [(linear_delta_thesis, 500), (rotary_delta_prototype, 300)], ids=["linear", "rotary"])
def test_kept_and_fresh_newton_matrix_reach_the_same_steps(robot, n):
    """At the default tolerance Newton converges every step: the plant's states do not depend on the Newton path
    (the matrix kept across steps, or factorised afresh at each), only on the model and the integrator."""
    p0, v0 = (0.03, -0.02, -0.45), (0.05, 0.0, 0.0)
    kept = make_plant(robot, fidelity="full", p0=p0, v0=v0, settings=SolverSettings(reuse_jacobian=True))
    fresh = make_plant(robot, fidelity="full", p0=p0, v0=v0, settings=SolverSettings(reuse_jacobian=False))
    worst = np.zeros(3)
    for a, b in zip(_drive(kept, n), _drive(fresh, n)):
        worst = np.maximum(worst, [np.abs(a.p - b.p).max(), np.abs(a.q - b.q).max(), np.abs(a.qd - b.qd).max()])
    print(f"{robot.name}: kept vs fresh matrix, max |dp| {worst[0]:.2e} m, |dq| {worst[1]:.2e}, |dqd| {worst[2]:.2e}")
    assert kept._it.newtonJacobiCount < n * REUSE_FACTORISATIONS < n <= fresh._it.newtonJacobiCount  # the paths differ
    assert worst[0] <= 1e-10 and worst[1] <= 1e-10 and worst[2] <= 1e-9, worst


@pytest.mark.parametrize("robot,fidelity,kept", [(linear_delta_thesis, "full", True), (linear_delta_thesis, "lumped", False),
                                                 (rotary_delta_prototype, "full", True), (rotary_delta_prototype, "lumped", False)],
                         ids=["linear-full", "linear-lumped", "rotary-full", "rotary-lumped"])
def test_default_reuse_jacobian_is_per_model(robot, fidelity, kept):
    """SolverSettings() (reuse_jacobian=None): the full plants keep their Newton matrix; the lumped plants factorise
    theirs at every step."""
    n = 50
    plant = make_plant(robot, fidelity=fidelity, p0=(0.03, -0.02, -0.45))
    for _ in _drive(plant, n):
        pass
    factorisations = plant._it.newtonJacobiCount / n
    if kept:
        assert factorisations <= REUSE_FACTORISATIONS, f"{factorisations} factorisations per step"
    else:
        assert factorisations >= 1.0, f"{factorisations} factorisations per step"
