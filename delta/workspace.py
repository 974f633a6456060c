"""Reachability, sampled workspace, coaxial cylinders and trajectory checks.

A point is reachable when every leg has a real inverse-kinematics solution,
every joint is within its limits and, if a margin is given, the task Jacobian's
singularity proximity stays at or above that margin (see
:mod:`delta.singularity`). Every negative answer says why.
"""

from __future__ import annotations

import math

from dataclasses import dataclass
from enum import Enum
from typing import Callable

import numpy as np

from .errors import ParameterError
from .kinematics import ik_batch, joint_limit_reason, proximity_batch
from .model import Model, as_model
from .robots import Robot

__all__ = [
    "Failure",
    "Reachability",
    "WorkspaceSample",
    "TrajectoryCheck",
    "reachability_batch",
    "check_point",
    "sample_workspace",
    "check_cylinder",
    "largest_cylinder",
    "check_trajectory",
    "default_bounds",
]


class Failure(str, Enum):
    """Why a point is not reachable."""

    NONE = "reachable"
    NO_SOLUTION = "no real solution"
    JOINT_LIMIT = "joint or stroke limit"
    SINGULARITY = "singularity margin"


@dataclass(frozen=True)
class Reachability:
    """Answer for one point: ``ok`` or the failure, the leg and a readable reason."""

    p: np.ndarray
    failure: Failure
    leg: int | None
    q: np.ndarray | None
    proximity: float | None
    reason: str

    @property
    def ok(self) -> bool:
        return self.failure is Failure.NONE


def reachability_batch(
    robot: Robot | Model, p: np.ndarray, singularity_margin: float | None = None, check_limits: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Vectorised reachability of (N, 3) points.

    ``check_limits=False`` ignores the joint limits (only real solutions and the
    singularity margin count), which is the "Out of workspace!" test of seed 004.

    Returns
    -------
    failure_code : (N,) int array
        Index into ``list(Failure)`` (0 = reachable), first failing check wins.
    leg : (N,) int array
        1-based failing leg, 0 when none or when the failure is not per leg.
    q : (N, 3) array
        Joint values (NaN where a leg has no solution).
    proximity : (N,) array
        NaN where not computed.
    """
    p = np.atleast_2d(np.asarray(p, dtype=float))
    n = len(p)
    q, solvable = ik_batch(robot, p)
    code = np.zeros(n, dtype=int)
    leg = np.zeros(n, dtype=int)
    no_sol = ~solvable.all(axis=1)
    code[no_sol] = 1
    leg[no_sol] = np.argmin(solvable[no_sol], axis=1) + 1
    with np.errstate(invalid="ignore"):
        out_of_limits = (q < robot.q_min) | (q > robot.q_max)
    limit = (~no_sol) & out_of_limits.any(axis=1) & check_limits
    code[limit] = 2
    leg[limit] = np.argmax(out_of_limits[limit], axis=1) + 1
    prox = np.full(n, np.nan)
    rest = code == 0
    if singularity_margin is not None and rest.any():
        prox[rest] = proximity_batch(robot, q[rest], p[rest])
        sing = rest & (prox < singularity_margin)
        code[sing] = 3
    return code, leg, q, prox


def _explain(robot: Robot | Model, p: np.ndarray, code: int, leg: int, q: np.ndarray, prox: float,
             margin: float | None) -> Reachability:
    failure = list(Failure)[code]
    if failure is Failure.NONE:
        reason = "reachable"
    elif failure is Failure.NO_SOLUTION:
        reason = f"leg {leg} has no solution"
    elif failure is Failure.JOINT_LIMIT:
        reason = joint_limit_reason(robot, leg, q[leg - 1])
    else:
        reason = f"too close to a singularity: proximity {prox:.3g} < margin {margin:g}"
    return Reachability(
        p=np.asarray(p, dtype=float),
        failure=failure,
        leg=leg or None,
        q=None if failure is Failure.NO_SOLUTION else q,
        proximity=None if np.isnan(prox) else float(prox),
        reason=reason,
    )


def check_point(robot: Robot | Model, p: np.ndarray, singularity_margin: float | None = None) -> Reachability:
    """Reachability of one platform position ``p`` (3,), m, with the reason when not reachable."""
    code, leg, q, prox = reachability_batch(robot, np.asarray(p, dtype=float).reshape(1, 3), singularity_margin)
    if code[0] == 0 and singularity_margin is None:
        prox = proximity_batch(robot, q, np.asarray(p, dtype=float).reshape(1, 3))
    return _explain(robot, p, int(code[0]), int(leg[0]), q[0], float(prox[0]), singularity_margin)


def default_bounds(robot: Robot | Model) -> tuple[np.ndarray, np.ndarray]:
    """An axis-aligned box that contains the whole workspace, (lower, upper), m."""
    model = as_model(robot)
    return model.actuator.bounds(model.robot)


@dataclass(frozen=True)
class WorkspaceSample:
    """Result of grid sampling: reachable points, volume estimate and bounding box."""

    points: np.ndarray  # (M, 3) reachable grid points, m
    volume: float  # m^3, reachable cell count times cell volume
    bbox_min: np.ndarray
    bbox_max: np.ndarray
    spacing: float  # grid step, m
    counts: dict[str, int]  # grid points per failure kind


MAX_GRID_POINTS = 20_000_000
"""Grid points :func:`sample_workspace` takes (0.5 GB of coordinates; the default 10 mm grid of the thesis robot
has about 0.6 million)."""


def sample_workspace(
    robot: Robot | Model,
    spacing: float = 0.01,
    singularity_margin: float | None = None,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
    chunk: int = 200_000,
) -> WorkspaceSample:
    """Sample the workspace on a regular grid of step ``spacing`` (m).

    The volume is the number of reachable grid points times ``spacing**3``; its
    error shrinks with the grid step (first order in ``spacing`` at the boundary).
    """
    if not 0.0 < spacing < math.inf:
        raise ParameterError(f"spacing must be a finite length > 0, got {spacing}")
    lo, hi = default_bounds(robot) if bounds is None else (np.asarray(bounds[0]), np.asarray(bounds[1]))
    # counted in floats: a spacing of 1e-300 m gives 1e900 points, past any integer a message can format
    counts_per_axis = [max(0.0, math.ceil((hi[k] - lo[k] - spacing / 2) / spacing)) for k in range(3)]
    n_grid = float(counts_per_axis[0]) * counts_per_axis[1] * counts_per_axis[2]
    if n_grid > MAX_GRID_POINTS:
        raise ParameterError(f"spacing {spacing:g} m gives about {n_grid:.3g} grid points in the robot's bounding box "
                             f"(at most {MAX_GRID_POINTS:.0e}); use a spacing of at least "
                             f"{(float(np.prod(hi - lo)) / MAX_GRID_POINTS) ** (1 / 3):.2g} m")
    axes = [np.arange(lo[k] + spacing / 2, hi[k], spacing) for k in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    kept = []
    counts = {f.value: 0 for f in Failure}
    for start in range(0, len(grid), chunk):
        part = grid[start:start + chunk]
        code, _, _, _ = reachability_batch(robot, part, singularity_margin)
        for k, f in enumerate(Failure):
            counts[f.value] += int(np.count_nonzero(code == k))
        kept.append(part[code == 0])
    pts = np.concatenate(kept) if kept else np.empty((0, 3))
    if len(pts) == 0:
        return WorkspaceSample(pts, 0.0, np.full(3, np.nan), np.full(3, np.nan), spacing, counts)
    return WorkspaceSample(pts, len(pts) * spacing**3, pts.min(axis=0), pts.max(axis=0), spacing, counts)


def _cylinder_points(centre: np.ndarray, z_below: float, z_above: float, radius: float,
                     n_azimuth: int, n_height: int, n_radius: int, surface_only: bool) -> np.ndarray:
    az = np.linspace(0.0, 2.0 * np.pi, n_azimuth, endpoint=False)
    heights = np.linspace(-z_below, z_above, n_height)
    radii = np.array([radius]) if surface_only else np.linspace(0.0, radius, n_radius)
    rr, aa, hh = np.meshgrid(radii, az, heights, indexing="ij")
    pts = np.stack([rr * np.cos(aa), rr * np.sin(aa), hh], axis=-1).reshape(-1, 3)
    return np.asarray(centre, dtype=float) + pts


def check_cylinder(
    robot: Robot | Model,
    centre: np.ndarray,
    z_below: float,
    z_above: float,
    radius: float,
    singularity_margin: float | None = None,
    *,
    surface_only: bool = False,
    check_limits: bool = True,
    n_azimuth: int = 72,
    n_height: int = 41,
    n_radius: int = 11,
) -> Reachability:
    """Check a vertical cylinder around ``centre`` reaching ``z_below`` under and ``z_above`` over it.

    The solid cylinder is sampled on ``n_radius`` radii x ``n_azimuth`` azimuths x
    ``n_height`` heights (outer surface and end caps included); ``surface_only``
    samples the lateral surface alone, the ring path that seed 004's MATLAB
    workspace scenarios trace. Returns the first unreachable sample (lowest, then
    outermost) or an ``ok`` answer.
    """
    pts = _cylinder_points(centre, z_below, z_above, radius, n_azimuth, n_height, n_radius, surface_only)
    code, leg, q, prox = reachability_batch(robot, pts, singularity_margin, check_limits)
    bad = np.flatnonzero(code)
    if len(bad) == 0:
        centre_check = check_point(robot, centre, singularity_margin)
        return Reachability(np.asarray(centre, dtype=float), Failure.NONE, None, centre_check.q,
                            centre_check.proximity, "reachable")
    order = np.lexsort((-np.linalg.norm(pts[bad, :2] - np.asarray(centre)[:2], axis=1), pts[bad, 2]))
    k = bad[order[0]]
    return _explain(robot, pts[k], int(code[k]), int(leg[k]), q[k], float(prox[k]), singularity_margin)


def largest_cylinder(
    robot: Robot | Model,
    centre: np.ndarray,
    *,
    z_below: float | None = None,
    z_above: float | None = None,
    radius: float | None = None,
    singularity_margin: float | None = None,
    tolerance: float = 1e-4,
    **options: object,
) -> float:
    """Largest value of the one cylinder dimension left as None, by bisection, m.

    Give two of ``z_below``, ``z_above`` and ``radius``; the third is maximised so
    that the sampled cylinder stays reachable; ``options`` go to :func:`check_cylinder`.
    Returns 0.0 when even a degenerate cylinder is not reachable.
    """
    given = {"z_below": z_below, "z_above": z_above, "radius": radius}
    free = [k for k, v in given.items() if v is None]
    if len(free) != 1:
        raise ParameterError(f"leave exactly one of z_below, z_above, radius as None (got {free or 'none'})")
    name = free[0]
    lo_b, hi_b = default_bounds(robot)

    def fits(value: float) -> bool:
        dims = dict(given, **{name: value})
        return check_cylinder(robot, centre, dims["z_below"], dims["z_above"], dims["radius"],
                              singularity_margin, **options).ok

    lo, hi = 0.0, float(np.max(hi_b - lo_b))
    if not fits(lo):
        return 0.0
    while hi - lo > tolerance:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    return lo


@dataclass(frozen=True)
class TrajectoryCheck:
    """First offending sample of a trajectory, or ``ok``."""

    ok: bool
    t: float | None
    p: np.ndarray | None
    reason: str
    samples: int

    def message(self) -> str:
        if self.ok:
            return f"trajectory reachable ({self.samples} samples checked)"
        x, y, z = self.p
        return f"out of workspace at t = {self.t:.2f} s: p = ({x:.2f}, {y:.2f}, {z:.2f}) m: {self.reason}"


def check_trajectory(
    robot: Robot | Model,
    position: Callable[[np.ndarray], np.ndarray] | np.ndarray,
    times: np.ndarray,
    singularity_margin: float | None = None,
) -> TrajectoryCheck:
    """Check a sampled trajectory against the workspace.

    Parameters
    ----------
    position : callable or (N, 3) array
        Either ``f(times) -> (N, 3)`` positions or the positions themselves, m.
    times : (N,) array, s
    """
    times = np.asarray(times, dtype=float)
    pts = position(times) if callable(position) else np.asarray(position, dtype=float)
    pts = np.atleast_2d(pts)
    if pts.shape != (len(times), 3):
        raise ParameterError(f"positions have shape {pts.shape}, expected ({len(times)}, 3)")
    code, leg, q, prox = reachability_batch(robot, pts, singularity_margin)
    bad = np.flatnonzero(code)
    if len(bad) == 0:
        return TrajectoryCheck(True, None, None, "reachable", len(times))
    k = int(bad[0])
    info = _explain(robot, pts[k], int(code[k]), int(leg[k]), q[k], float(prox[k]), singularity_margin)
    return TrajectoryCheck(False, float(times[k]), pts[k], info.reason, len(times))
