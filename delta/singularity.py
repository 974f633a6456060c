"""Singularity classification and proximity (seed 003 section 3).

The velocity constraint of leg i is ``l_i . v = (l_i . B_i') qd_i``, i.e.
``J_p v = J_theta qd`` with ``J_p`` rows ``l_i^T`` and ``J_theta = diag(l_i . B_i')``
(seed 003 eqs. (12)-(15)).

* Type 1 (serial): ``det J_theta = 0``; a rod is orthogonal to its actuator
  motion. For a rotary leg ``l_i . B_i' = La Lb sin(theta_2i) sin(theta_3i)``
  (seed 003 eq. (13)): the leg is stretched (theta_2 = 0), folded (theta_2 = pi)
  or its forearm lies along the motor axis (theta_3 = 0 or pi). For a linear leg
  the rod is horizontal.
* Type 2 (parallel): ``det J_p = 0``; the three rods are coplanar.

Proximity measures are dimensionless, in [0, 1], 0 = singular:
``serial[i] = |l_i . B_i'| / (|l_i| |B_i'|)``, ``parallel = |det [l_i / |l_i|]|``,
``inverse_condition = sigma_min(J) / sigma_max(J)`` of the task Jacobian and
``proximity = min(min_i serial[i], sigma_min / sigma_max of the unit-row J_p)``.
The margin applies to ``proximity``: the inverse condition number of ``J`` alone
misses a type 1 singularity reached by all legs at once (every row of ``J``
scales by the same factor, e.g. a 3-RRR with the three legs stretched).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import ParameterError, UnreachableError
from .kinematics import Data, fk, ik, leg_axes, proximity, proximity_batch, set_pose
from .model import Model, as_model
from .robots import Robot

__all__ = ["SingularityReport", "DEFAULT_TOLERANCE", "analyse", "analyse_pose", "proximity_batch"]

DEFAULT_TOLERANCE = 1e-6
"""Measures at or below this value are reported as singular (exact singularity up to rounding)."""


@dataclass(frozen=True)
class SingularityReport:
    """Singularity analysis of one configuration."""

    q: np.ndarray
    p: np.ndarray
    serial: np.ndarray  # (3,) per-leg serial measure
    parallel: float
    inverse_condition: float
    proximity: float
    type1_legs: tuple[int, ...]
    type2: bool
    theta2: np.ndarray | None = None  # seed 003 angles (rotary only), rad
    theta3: np.ndarray | None = None

    @property
    def singular(self) -> bool:
        return bool(self.type1_legs) or self.type2

    @property
    def kind(self) -> str:
        kinds = []
        if self.type1_legs:
            kinds.append("type 1 (serial) on leg " + ", ".join(str(i) for i in self.type1_legs))
        if self.type2:
            kinds.append("type 2 (parallel)")
        return "; ".join(kinds) if kinds else "regular"

    def within_margin(self, margin: float) -> bool:
        """True when the configuration keeps ``proximity >= margin``."""
        return self.proximity >= margin


def analyse(robot: Robot | Model, q: np.ndarray, p: np.ndarray, tolerance: float = DEFAULT_TOLERANCE
            ) -> SingularityReport:
    """Classify the configuration (q, p) and measure its distance to singularity."""
    model = as_model(robot)
    q = np.asarray(q, dtype=float)
    p = np.asarray(p, dtype=float)
    data = set_pose(model, Data(model), q.tolist(), p.tolist())
    legs = np.array(data.legs)  # row i: l_i (3), B_i' (3), l_i . B_i'', l_i . B_i'
    rods, d1, denom = legs[:, 0:3], legs[:, 3:6], legs[:, 7]
    rod_norm = np.linalg.norm(rods, axis=1)
    serial = np.abs(denom) / (rod_norm * np.linalg.norm(d1, axis=1))
    parallel = float(abs(np.linalg.det(rods / rod_norm[:, None])))
    type1 = tuple(int(i) + 1 for i in np.flatnonzero(serial <= tolerance))
    if type1:
        inv_cond = 0.0
    else:
        s = np.linalg.svd(rods / denom[:, None], compute_uv=False)
        inv_cond = float(s[-1] / s[0])
    theta2, theta3 = model.actuator.leg_angles(q, rods, leg_axes(model))
    return SingularityReport(q, p, serial, parallel, inv_cond, proximity(data), type1, parallel <= tolerance,
                             theta2, theta3)


def analyse_pose(robot: Robot | Model, *, q: np.ndarray | None = None, p: np.ndarray | None = None,
                 tolerance: float = DEFAULT_TOLERANCE) -> SingularityReport:
    """Analyse a pose given by joint values ``q`` or platform position ``p`` (exactly one)."""
    if (q is None) == (p is None):
        raise ParameterError("give exactly one of q or p")
    if q is None:
        res = ik(robot, p)
        if res.q is None:
            raise UnreachableError(res.reason)
        q = res.q
    else:
        p = fk(robot, q).require()
    return analyse(robot, q, p, tolerance)
