"""Pre-flight: the reference trajectory against the robot's workspace and singularity margin.

Runs before any FMU is instantiated. The trajectory comes from
:mod:`delta.trajectories` (``helix`` -> ``Helix(**params)`` and so on).
"""

from __future__ import annotations

import numpy as np

from .errors import Issue, PreflightError, ScenarioError
from .scenario import Scenario, TrajectorySpec

__all__ = ["make_trajectory", "check_positions", "preflight", "initial_state_values"]

_CLASSES = {"helix": "Helix", "pick_and_place": "PickAndPlace", "point_to_point": "PointToPoint",
            "waypoints": "Waypoints"}


def make_trajectory(spec: TrajectorySpec, source: str | None = None):
    """Instantiate the delta.trajectories class named by ``spec.type`` with ``spec.params``."""
    try:
        from delta import trajectories
    except ImportError:
        raise ScenarioError(Issue("trajectory", "delta.trajectories is not available", source)) from None
    cls = getattr(trajectories, _CLASSES[spec.type])
    try:
        return cls(**spec.params)
    except (TypeError, ValueError) as exc:
        raise ScenarioError(Issue("trajectory.params", f"{_CLASSES[spec.type]}: {exc}", source)) from None


def check_positions(robot_name: str, times: np.ndarray, positions: np.ndarray,
                    singularity_margin: float | None) -> None:
    """Raise :class:`PreflightError` (the first offending sample and why) if any position is unreachable."""
    from delta.robots import get_preset
    from delta.workspace import check_trajectory

    res = check_trajectory(get_preset(robot_name), np.asarray(positions, dtype=float), np.asarray(times, dtype=float),
                           singularity_margin)
    if not res.ok:
        raise PreflightError(res.message())


def _positions(traj, times: np.ndarray) -> np.ndarray:
    sample = traj.sample(times)
    p = getattr(sample, "p", sample)
    if isinstance(sample, tuple):
        p = sample[0]
    return np.asarray(p, dtype=float).reshape(len(times), 3)


def preflight(scenario: Scenario) -> str:
    """Check the scenario's trajectory; returns a one-line report, raises PreflightError."""
    spec = scenario.trajectory
    if spec is None or scenario.robot is None:
        return "no trajectory to check"
    traj = make_trajectory(spec, scenario.source)
    t0, t1 = scenario.time.start, scenario.time.stop
    n = max(2, int(np.ceil((t1 - t0) / spec.check_step)) + 1)
    times = np.linspace(t0, t1, n)
    check_positions(scenario.robot, times, _positions(traj, times), spec.singularity_margin)
    return f"trajectory reachable ({n} samples, margin {spec.singularity_margin})"


def initial_state_values(scenario: Scenario) -> dict[str, float]:
    """Start parameters of ``initial_state.component``: position and velocity on the trajectory at t = start."""
    init = scenario.initial_state
    if scenario.trajectory is None or not init.from_trajectory:
        return {}
    traj = make_trajectory(scenario.trajectory, scenario.source)
    state = traj.evaluate(scenario.time.start)
    p = np.asarray(getattr(state, "p", state[0] if isinstance(state, tuple) else state), dtype=float).reshape(3)
    v = getattr(state, "v", state[1] if isinstance(state, tuple) and len(state) > 1 else None)
    out = dict(zip(init.position, map(float, p)))
    if v is not None and init.velocity:
        out.update(zip(init.velocity, map(float, np.asarray(v, dtype=float).reshape(3))))
    return out
