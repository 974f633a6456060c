"""Pure-Python closed loop: a discrete controller at period ``h`` on the analytic model.

The plant is the analytic model (or another one, for mismatch studies) integrated with
fixed-step RK4, ``substeps`` steps per control period, under the effort held constant
over the period (zero-order hold). This is the reference for the FMU-based runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .control import Controller
from .dynamics import AnalyticModel, forward_dynamics, joint_references, platform_state, rk4_step
from .errors import ParameterError
from .model import Data, Model, as_model
from .robots import Robot
from .trajectories import Trajectory

__all__ = ["ClosedLoopResult", "simulate"]


@dataclass(frozen=True)
class ClosedLoopResult:
    """Sampled closed-loop signals at the control instants ``t`` (N,) s; other arrays (N, 3).

    ``q, qd`` measured joint state; ``q_ref, qd_ref`` joint references; ``p, v`` platform
    position / velocity (FK of the plant state), ``p_ref, v_ref`` their references; ``u``
    the effort applied over ``[t_k, t_k + h)``.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    q_ref: np.ndarray
    qd_ref: np.ndarray
    p: np.ndarray
    p_ref: np.ndarray
    v: np.ndarray
    v_ref: np.ndarray
    u: np.ndarray

    def rmse(self) -> np.ndarray:
        """Root mean square of ``p - p_ref`` per axis (thesis eq. (52)), (3,) m."""
        return np.sqrt(np.mean((self.p - self.p_ref) ** 2, axis=0))

    def joint_rmse(self) -> np.ndarray:
        """Root mean square of ``q - q_ref`` per joint, (3,) m or rad."""
        return np.sqrt(np.mean((self.q - self.q_ref) ** 2, axis=0))


def simulate(
    robot: Robot,
    model: AnalyticModel | Model,
    trajectory: Trajectory,
    controller: Controller,
    t_end: float,
    h: float = 1e-3,
    substeps: int = 1,
    plant_model: AnalyticModel | Model | None = None,
    start_on_trajectory: bool = True,
    q0: np.ndarray | None = None,
) -> ClosedLoopResult:
    """Run ``controller`` against the plant for ``t_end`` s at control period ``h`` s.

    Parameters
    ----------
    model : analytic model the references are computed with (its robot must be ``robot``).
    plant_model : the simulated plant; defaults to ``model``.
    start_on_trajectory : start at the reference position and velocity at t = 0; otherwise
        start at rest at ``q0`` (3,) (default: the reference position).
    substeps : RK4 steps per control period.
    """
    if model.robot != robot:
        raise ParameterError(f"model is for robot {model.robot.name!r}, not {robot.name!r}")
    if abs(controller.h - h) > 1e-12 * h:
        raise ParameterError(f"controller period {controller.h} s differs from the loop period h = {h} s")
    if not (isinstance(substeps, int) and substeps >= 1):
        raise ParameterError(f"substeps must be an integer >= 1, got {substeps!r}")
    n = int(round(t_end / h))
    if n < 1:
        raise ParameterError(f"t_end = {t_end} s is shorter than one period h = {h} s")
    plant = model if plant_model is None else plant_model
    plant = as_model(plant)
    data = Data(plant)
    times = np.arange(n) * h
    p_ref, v_ref, a_ref = trajectory.sample(times)
    q_ref, qd_ref, qdd_ref = joint_references(model, p_ref, v_ref, a_ref)
    if start_on_trajectory:
        q, qd = [float(x) for x in q_ref[0]], [float(x) for x in qd_ref[0]]
    else:
        q = [float(x) for x in (q_ref[0] if q0 is None else np.asarray(q0, dtype=float).reshape(3))]
        qd = [0.0, 0.0, 0.0]
    controller.reset()
    qs, qds, us = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
    ps, vs = np.empty((n, 3)), np.empty((n, 3))
    dt = h / substeps
    qr_l, qdr_l, qddr_l = q_ref.tolist(), qd_ref.tolist(), qdd_ref.tolist()
    for k in range(n):
        qs[k], qds[k] = q, qd
        ps[k], vs[k] = platform_state(plant, data, q, qd)
        u = controller.step(q, qd, qr_l[k], qdr_l[k], qddr_l[k])
        us[k] = u
        u = u.tolist()

        def accel(x, xd, u=u):  # noqa: ANN001, ANN202
            return forward_dynamics(plant, data, x, xd, u)

        for _ in range(substeps):
            q, qd = rk4_step(accel, q, qd, dt)
    return ClosedLoopResult(times, qs, qds, q_ref, qd_ref, ps, p_ref, vs, v_ref, us)
