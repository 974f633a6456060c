"""Inverse dynamics of the multibody plant against the analytic model on a prescribed motion.

The plant's joints are driven exactly along the trajectory's ``q(t)`` (drive constraints,
``prescribed`` mode) and the drive reactions are the actuator efforts the multibody model
needs; the analytic model's ``inverse_dynamics(q, qd, qdd)`` is evaluated at the same
instants. Rod masses in the full plant are distributed (rigid rods), so the analytic error
depends on the lumping factor ``w``; this module measures that dependence.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from delta.dynamics import analytic_model
from delta.kinematics import joint_state_from_platform

from .plant import SolverSettings

__all__ = ["FORCE_COMPARISON_SETTINGS", "PrescribedRun", "run_prescribed", "force_errors", "force_error_vs_w"]

FORCE_COMPARISON_SETTINGS = SolverSettings(spectral_radius=0.5, newton_rel_tol=1e-8)
"""Spectral radius 0.5 (less numerical damping of the reactions) for force comparisons."""


@dataclass(frozen=True)
class PrescribedRun:
    """Drive efforts of the plant along a prescribed motion: ``t`` (N,), ``q, qd, qdd, f_plant`` (N, 3)."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    f_plant: np.ndarray


class _JointMotion:
    """``t -> (q, qd)`` of a platform trajectory through IK, cached on the last time."""

    def __init__(self, robot, trajectory) -> None:
        self.robot, self.trajectory = robot, trajectory
        self._t = None
        self._value = None

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        if t != self._t:
            p, v, _ = self.trajectory.evaluate(t)
            q, qd, _ = joint_state_from_platform(self.robot, p, v)
            self._t, self._value = t, (q, qd)
        return self._value

    def full(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        p, v, a = self.trajectory.evaluate(t)
        return joint_state_from_platform(self.robot, p, v, a)


def run_prescribed(robot, trajectory, masses=None, h: float = 2e-4, duration: float | None = None,
                   fidelity: str = "full", settings: SolverSettings | None = None) -> PrescribedRun:
    """Drive the plant along ``trajectory`` (platform motion, ``evaluate(t) -> (p, v, a)``) and record efforts."""
    from . import make_plant

    motion = _JointMotion(robot, trajectory)
    end = float(trajectory.duration if duration is None else duration)
    n = int(round(end / h))
    p0, v0, _ = trajectory.evaluate(0.0)
    plant = make_plant(robot, masses, fidelity=fidelity, settings=settings or FORCE_COMPARISON_SETTINGS,
                       p0=p0, v0=v0, prescribed=motion, h_nominal=h)
    t = np.empty(n)
    q, qd, qdd, f = (np.empty((n, 3)) for _ in range(4))
    for k in range(n):
        out = plant.step(k * h, h, None) if k == 0 else plant.step(plant.time, h, None)
        t[k] = (k + 1) * h
        q[k], qd[k], qdd[k] = motion.full(t[k])
        f[k] = out.reaction
    return PrescribedRun(t, q, qd, qdd, f)


def force_errors(run: PrescribedRun, robot, masses) -> tuple[float, float]:
    """Relative RMS and peak error of the analytic efforts against the plant's, over all joints."""
    model = analytic_model(robot, masses)
    f_model = np.array([model.inverse_dynamics(q, qd, qdd) for q, qd, qdd in zip(run.q, run.qd, run.qdd)])
    err = f_model - run.f_plant
    rms = float(np.sqrt(np.mean(err**2)) / np.sqrt(np.mean(run.f_plant**2)))
    peak = float(np.max(np.abs(err)) / np.max(np.abs(run.f_plant)))
    return rms, peak


def force_error_vs_w(robot, trajectory, w_values, masses=None, h: float = 2e-4, duration: float | None = None,
                     fidelity: str = "full") -> list[tuple[float, float, float]]:
    """Analytic-vs-plant effort error as a function of the lumping factor ``w``.

    The plant is run once (its rods are rigid bodies, independent of ``w``); the analytic
    model uses ``w_inertia = w_gravity = w``.

    Returns
    -------
    list of (w, rms_rel_error, peak_rel_error)
        ``rms_rel_error = rms(f_model - f_plant) / rms(f_plant)`` over all joints and samples,
        ``peak_rel_error = max|f_model - f_plant| / max|f_plant|``.
    """
    from delta.dynamics import LinearDeltaMasses, RotaryDeltaMasses
    from delta.robots import LinearDelta

    if masses is None:
        masses = LinearDeltaMasses() if isinstance(robot, LinearDelta) else RotaryDeltaMasses()
    run = run_prescribed(robot, trajectory, masses, h=h, duration=duration, fidelity=fidelity)
    out = []
    for w in w_values:
        rms, peak = force_errors(run, robot, masses.with_(w_inertia=float(w), w_gravity=float(w)))
        out.append((float(w), rms, peak))
    return out
