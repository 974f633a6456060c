"""Analytic dynamics of the delta robots (thesis section 7, virtual work).

Mass parameters are shared by the analytic model and the multibody plants so
that both describe the same machine.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from math import cos, sin

import numpy as np

from .errors import ParameterError, RobotError, UnreachableError
from .kinematics import actuator_points_batch, actuator_tangents_batch, ik_batch, platform_offsets
from .robots import LinearDelta, Robot, RotaryDelta
from .scalar_kinematics import ScalarKinematics
from .scalar_kinematics import Vec as _Vec
from .scalar_kinematics import dot as _dot
from .scalar_kinematics import inv3 as _inv3

__all__ = [
    "LinearDeltaMasses",
    "RotaryDeltaMasses",
    "GRAVITY",
    "LinearDeltaModel",
    "RotaryDeltaModel",
    "AnalyticModel",
    "analytic_model",
    "joint_references",
]

GRAVITY = 9.81
"""Standard gravity used by default, m/s^2 (acts along -z)."""


class _Masses:
    """Validation and copy-with-changes shared by the mass dataclasses."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name.startswith("w_"):
                if not 0.0 <= value <= 1.0:
                    raise ParameterError(f"{type(self).__name__}.{f.name} must be in [0, 1], got {value!r}")
            elif isinstance(value, float) and value < 0.0:
                raise ParameterError(f"{type(self).__name__}.{f.name} must be >= 0, got {value!r}")

    def with_(self, **changes: float):
        """A copy with ``changes`` applied (validated again)."""
        return replace(self, **changes)


@dataclass(frozen=True)
class LinearDeltaMasses(_Masses):
    """Masses of the linear delta (thesis eqs. 28-29), SI units.

    Attributes
    ----------
    carriage : float
        Mass of one carriage (slider), kg (thesis ``m_s``).
    rod : float
        Mass of one parallelogram rod, kg (thesis ``m_l``); each leg has two.
    rod_radius : float
        Rod radius for the multibody plant's rod inertia, m.
    parallelogram_width : float
        Distance between the two rods of a leg, m (multibody plant only).
    platform : float
        Platform mass without payload, kg (thesis ``m_p``).
    payload : float
        Payload carried by the platform, kg.
    w_inertia, w_gravity : float
        Leg mass distribution factor ``w`` (share of each rod lumped at the platform)
        used for the inertial and the gravity terms; the thesis uses one ``w`` for both
        (default 2/3). ``w_gravity = 1/2`` is exact for the weight of uniform rods.
    gravity : float
        Gravitational acceleration along -z, m/s^2.
    """

    carriage: float = 0.5
    rod: float = 0.1
    rod_radius: float = 0.004
    parallelogram_width: float = 0.06
    platform: float = 0.3
    payload: float = 0.0
    w_inertia: float = 2.0 / 3.0
    w_gravity: float = 2.0 / 3.0
    gravity: float = GRAVITY



@dataclass(frozen=True)
class RotaryDeltaMasses(_Masses):
    """Masses of the rotary delta (Codourey-style lumping), SI units.

    Attributes
    ----------
    motor_inertia : float
        Rotor (and gearbox) inertia about the motor axis, kg m^2.
    arm : float
        Upper arm mass, kg, uniform along the arm (inertia ``arm * La**2 / 3`` about the axis).
    elbow : float
        Concentrated mass at the elbow (joint hardware), kg.
    rod : float
        Mass of one forearm rod, kg; each leg has two.
    rod_radius, parallelogram_width : float
        Multibody plant only, m.
    platform, payload : float
        kg.
    w_inertia, w_gravity : float
        Share of each forearm rod lumped at the platform (the rest at the elbow).
    gravity : float
        m/s^2 along -z.
    """

    motor_inertia: float = 5e-4
    arm: float = 0.4
    elbow: float = 0.05
    rod: float = 0.08
    rod_radius: float = 0.005
    parallelogram_width: float = 0.06
    platform: float = 0.25
    payload: float = 0.0
    w_inertia: float = 2.0 / 3.0
    w_gravity: float = 2.0 / 3.0
    gravity: float = GRAVITY



# --------------------------------------------------------------------------------------
# Analytic models (virtual work, thesis section 7)
# --------------------------------------------------------------------------------------
#
# Both robots are lumped the same way: each actuator carries a constant inertia ``D_i``
# about / along its joint (carriage or arm plus the actuator-side share of the rods) and
# the platform carries a point mass ``m_p`` (platform, payload and the platform-side
# share of the rods). With ``v = J^-1 qd`` (thesis eq. (31)) the kinetic and potential
# energies are
#
#     T = 1/2 sum_i D_i qd_i^2 + 1/2 m_p |v|^2,
#     V = sum_i V_i(q_i) + m_p,g g p_z,
#
# and d'Alembert's virtual work (thesis eqs. (30)-(35)) gives
#
#     f = D qdd + J^-T m_p a + dV/dq,   a = J^-1 (qdd - [v^T H_i v])   (thesis eq. (37)),
#
# i.e. f = M(q) qdd + C(q, qd) qd + G(q) (thesis eq. (38)) with
#
#     M = D + m_p J^-T J^-1,  C qd = -m_p J^-T J^-1 [v^T H_i v],  G = dV/dq.
#
# ``C qd`` is exactly J^-T m_p d/dt(J^-1) qd, so f . qd = d/dt(T + V) holds identically
# (tested as the power balance). The inertial and the gravity lumps may differ
# (``w_inertia`` vs ``w_gravity``): T and V are then built from different lumps and the
# model stays conservative.

class _KinState:
    """Kinematic quantities of one joint position, plain floats (cached by the model)."""

    __slots__ = ("q", "p", "rods", "d1", "d2", "denom", "jinv")

    def __init__(self, q, p, rods, d1, d2, denom, jinv):
        self.q = q
        self.p = p
        self.rods = rods
        self.d1 = d1
        self.d2 = d2
        self.denom = denom
        self.jinv = jinv


class _DeltaModel:
    """Shared virtual-work model (kinematics from :class:`ScalarKinematics`); subclasses define the lumps.

    Every public method takes joint-space ``q`` (3,) and ``qd`` (3,) and computes the
    platform position by closed-form forward kinematics (the last one is cached).
    Efforts are along +q: N for a linear delta, N*m for a rotary delta.
    """

    robot: Robot
    masses: object

    def __init__(self, robot: Robot, masses: object) -> None:
        self.robot = robot
        self.masses = masses
        self.kin = ScalarKinematics(robot)  # actuator path B_i(q_i), forward kinematics
        self._cache: _KinState | None = None
        # Set by subclasses: actuator inertias D_i, platform masses.
        self._d: float = 0.0
        self._mp_inertia: float = 0.0
        self._mp_gravity: float = 0.0
        self._g: float = 0.0

    # -- actuator-side lumps (subclass) --------------------------------------------------
    def _actuator_gravity(self, qi: float) -> float:
        """``dV_i/dq_i`` of the actuator-side lumps."""
        raise NotImplementedError

    def _actuator_potential(self, qi: float) -> float:
        raise NotImplementedError

    # -- kinematics ----------------------------------------------------------------------
    def _kin(self, q: np.ndarray) -> _KinState:
        q0, q1, q2 = float(q[0]), float(q[1]), float(q[2])
        c = self._cache
        if c is not None and c.q == (q0, q1, q2):
            return c
        p, pts, d1s, d2s = self.kin.fk((q0, q1, q2))
        rods, denom, jac = [], [], []
        for i in range(3):
            b_i, bpt = self.kin.b[i], pts[i]
            rod = (p[0] - (bpt[0] - b_i[0]), p[1] - (bpt[1] - b_i[1]), p[2] - (bpt[2] - b_i[2]))  # l_i = p + b_i - B_i
            den = _dot(rod, d1s[i])
            if den == 0.0:
                raise RobotError(f"type 1 (serial) singularity at q = {(q0, q1, q2)}: leg {i + 1}")
            rods.append(rod)
            denom.append(den)
            jac.append([rod[0] / den, rod[1] / den, rod[2] / den])  # thesis eq. (15)
        try:
            jinv = _inv3(jac)
        except ZeroDivisionError:
            raise RobotError(f"type 2 (parallel) singularity at q = {(q0, q1, q2)}: J is singular") from None
        state = _KinState((q0, q1, q2), p, rods, d1s, d2s, denom, jinv)
        self._cache = state
        return state

    def _platform_velocity(self, ks: _KinState, qd: _Vec) -> _Vec:
        j = ks.jinv
        return (
            j[0][0] * qd[0] + j[0][1] * qd[1] + j[0][2] * qd[2],
            j[1][0] * qd[0] + j[1][1] * qd[1] + j[1][2] * qd[2],
            j[2][0] * qd[0] + j[2][1] * qd[1] + j[2][2] * qd[2],
        )

    def _quadratic(self, ks: _KinState, v: _Vec, qd: _Vec) -> _Vec:
        """``[v^T H_i v]`` (thesis eq. (22)) using ``J_i v = qd_i``:
        ``(|v - B_i' qd_i|^2 - (l_i . B_i'') qd_i^2) / (l_i . B_i')``."""
        out = []
        for i in range(3):
            d1, qi = ks.d1[i], qd[i]
            w = (v[0] - d1[0] * qi, v[1] - d1[1] * qi, v[2] - d1[2] * qi)
            out.append((_dot(w, w) - _dot(ks.rods[i], ks.d2[i]) * qi * qi) / ks.denom[i])
        return out[0], out[1], out[2]

    def _jinv_t(self, ks: _KinState, x: _Vec) -> _Vec:
        j = ks.jinv
        return (
            j[0][0] * x[0] + j[1][0] * x[1] + j[2][0] * x[2],
            j[0][1] * x[0] + j[1][1] * x[1] + j[2][1] * x[2],
            j[0][2] * x[0] + j[1][2] * x[1] + j[2][2] * x[2],
        )

    def _mass(self, ks: _KinState) -> list[list[float]]:
        j, mp, d = ks.jinv, self._mp_inertia, self._d
        m = [[0.0] * 3 for _ in range(3)]
        for r in range(3):
            for c in range(r, 3):
                val = mp * (j[0][r] * j[0][c] + j[1][r] * j[1][c] + j[2][r] * j[2][c])
                m[r][c] = val
                m[c][r] = val
            m[r][r] += d
        return m

    def _cqd(self, ks: _KinState, qd: _Vec) -> _Vec:
        v = self._platform_velocity(ks, qd)
        # thesis eq. (37): J^-1 (qdd - [v^T H v]); the velocity part is -J^-1 [v^T H v].
        a_v = self._platform_velocity(ks, self._quadratic(ks, v, qd))
        mp = -self._mp_inertia
        return self._jinv_t(ks, (mp * a_v[0], mp * a_v[1], mp * a_v[2]))

    def _grav(self, ks: _KinState) -> _Vec:
        j, w = ks.jinv, self._mp_gravity * self._g
        q = ks.q
        # dV/dq: actuator lumps plus m_p g d(p_z)/dq = m_p g (J^-T e_z).
        return (
            self._actuator_gravity(q[0]) + w * j[2][0],
            self._actuator_gravity(q[1]) + w * j[2][1],
            self._actuator_gravity(q[2]) + w * j[2][2],
        )

    # -- public API ----------------------------------------------------------------------
    def platform_state(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Platform position ``p`` (3,), m, and velocity ``v = J^-1 qd`` (3,), m/s."""
        ks = self._kin(q)
        v = self._platform_velocity(ks, (float(qd[0]), float(qd[1]), float(qd[2])))
        return np.array(ks.p), np.array(v)

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """Joint-space inertia ``M(q) = D + m_p J^-T J^-1`` (thesis eqs. (35)-(38)), (3, 3)."""
        return np.array(self._mass(self._kin(q)))

    def velocity_term(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Centrifugal/Coriolis effort ``C(q, qd) qd`` (3,), N or N*m."""
        ks = self._kin(q)
        return np.array(self._cqd(ks, (float(qd[0]), float(qd[1]), float(qd[2]))))

    def gravity_term(self, q: np.ndarray) -> np.ndarray:
        """Gravity effort ``G(q) = dV/dq`` (3,): the effort along +q that holds the robot still."""
        return np.array(self._grav(self._kin(q)))

    def terms(self, q: np.ndarray, qd: np.ndarray) -> tuple[list[list[float]], _Vec, _Vec]:
        """``(M, C qd, G)`` in one pass as plain floats (for controllers and integrators)."""
        ks = self._kin(q)
        qdt = (float(qd[0]), float(qd[1]), float(qd[2]))
        return self._mass(ks), self._cqd(ks, qdt), self._grav(ks)

    def inverse_dynamics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """Actuator efforts ``f = M qdd + C qd + G`` (thesis eq. (38)), (3,)."""
        m, c, g = self.terms(q, qd)
        a0, a1, a2 = float(qdd[0]), float(qdd[1]), float(qdd[2])
        return np.array([
            m[0][0] * a0 + m[0][1] * a1 + m[0][2] * a2 + c[0] + g[0],
            m[1][0] * a0 + m[1][1] * a1 + m[1][2] * a2 + c[1] + g[1],
            m[2][0] * a0 + m[2][1] * a1 + m[2][2] * a2 + c[2] + g[2],
        ])

    def forward_dynamics(self, q: np.ndarray, qd: np.ndarray, f: np.ndarray) -> np.ndarray:
        """Joint accelerations ``qdd = M^-1 (f - C qd - G)`` (3,)."""
        return np.array(self.accel(q, qd, f))

    def accel(self, q, qd, f) -> _Vec:  # noqa: ANN001
        """:meth:`forward_dynamics` on any 3-sequences, returning a float tuple (integrator fast path)."""
        m, c, g = self.terms(q, qd)
        mi = _inv3(m)
        r0, r1, r2 = float(f[0]) - c[0] - g[0], float(f[1]) - c[1] - g[1], float(f[2]) - c[2] - g[2]
        return (
            mi[0][0] * r0 + mi[0][1] * r1 + mi[0][2] * r2,
            mi[1][0] * r0 + mi[1][1] * r1 + mi[1][2] * r2,
            mi[2][0] * r0 + mi[2][1] * r1 + mi[2][2] * r2,
        )

    def energy(self, q: np.ndarray, qd: np.ndarray) -> tuple[float, float]:
        """Kinetic and potential energy of the lumped model, J (potential zero at q = 0, p_z = 0)."""
        ks = self._kin(q)
        qdt = (float(qd[0]), float(qd[1]), float(qd[2]))
        v = self._platform_velocity(ks, qdt)
        kinetic = 0.5 * self._d * _dot(qdt, qdt) + 0.5 * self._mp_inertia * _dot(v, v)
        potential = sum(self._actuator_potential(qi) for qi in ks.q) + self._mp_gravity * self._g * ks.p[2]
        return kinetic, potential


class LinearDeltaModel(_DeltaModel):
    """Virtual-work model of the linear delta (thesis eqs. (28)-(38)).

    Lumps: carriage ``m_s + 2 (1 - w) m_l`` moving with ``q`` (thesis eq. (29)) and
    platform ``m_p + payload + 6 w m_l`` moving with ``p`` (thesis eq. (28)). The inertial
    lumps use ``masses.w_inertia``, the weights ``masses.w_gravity``. The thesis uses one
    ``w = 2/3`` for both; ``w_gravity = 1/2`` is the exact weight split of a uniform rod
    (its centre of mass is at mid-length), while no constant ``w`` is exact for a rod's
    kinetic energy (``m/6 (|v_a|^2 + v_a.v_b + |v_b|^2)``), so ``w_inertia`` stays a
    modelling choice (2/3 is Codourey's). ``q`` is carriage travel downward, so the
    carriage weight is ``+m g`` along ``q`` and ``G`` holds ``-m_s g`` per carriage.
    """

    def __init__(self, robot: LinearDelta, masses: LinearDeltaMasses | None = None) -> None:
        masses = LinearDeltaMasses() if masses is None else masses
        super().__init__(robot, masses)
        m = masses
        self._d = m.carriage + 2.0 * (1.0 - m.w_inertia) * m.rod  # thesis eq. (29)
        self._mp_inertia = m.platform + m.payload + 6.0 * m.w_inertia * m.rod  # thesis eq. (28)
        self._ms_gravity = m.carriage + 2.0 * (1.0 - m.w_gravity) * m.rod
        self._mp_gravity = m.platform + m.payload + 6.0 * m.w_gravity * m.rod
        self._g = m.gravity

    def _actuator_gravity(self, qi: float) -> float:
        return -self._ms_gravity * self._g

    def _actuator_potential(self, qi: float) -> float:
        return -self._ms_gravity * self._g * qi  # carriage height is -q


class RotaryDeltaModel(_DeltaModel):
    """Codourey-style virtual-work model of the rotary delta.

    Each arm rotates with inertia ``I = motor_inertia + arm La^2/3 + (elbow + 2 (1 - w) rod) La^2``
    about its motor axis; the platform carries ``platform + payload + 6 w rod`` (3 legs x 2
    rods). Gravity: arm centre of mass at ``La/2``, elbow lumps at ``La``, both at height
    ``-r sin q`` below the motor axis; ``w_inertia``/``w_gravity`` as for the linear delta.
    """

    def __init__(self, robot: RotaryDelta, masses: RotaryDeltaMasses | None = None) -> None:
        masses = RotaryDeltaMasses() if masses is None else masses
        super().__init__(robot, masses)
        m, la = masses, robot.arm_length
        self._d = m.motor_inertia + m.arm * la * la / 3.0 + (m.elbow + 2.0 * (1.0 - m.w_inertia) * m.rod) * la * la
        self._mp_inertia = m.platform + m.payload + 6.0 * m.w_inertia * m.rod
        self._mp_gravity = m.platform + m.payload + 6.0 * m.w_gravity * m.rod
        self._arm_moment = m.arm * la / 2.0 + (m.elbow + 2.0 * (1.0 - m.w_gravity) * m.rod) * la  # kg m
        self._g = m.gravity

    def _actuator_gravity(self, qi: float) -> float:
        return -self._arm_moment * self._g * cos(qi)

    def _actuator_potential(self, qi: float) -> float:
        return -self._arm_moment * self._g * sin(qi)


AnalyticModel = LinearDeltaModel | RotaryDeltaModel


def analytic_model(robot: Robot, masses: LinearDeltaMasses | RotaryDeltaMasses | None = None) -> AnalyticModel:
    """The analytic model matching ``robot`` (masses default to the dataclass defaults)."""
    if isinstance(robot, LinearDelta):
        if masses is not None and not isinstance(masses, LinearDeltaMasses):
            raise ParameterError(f"linear delta {robot.name!r} needs LinearDeltaMasses, got {type(masses).__name__}")
        return LinearDeltaModel(robot, masses)
    if isinstance(robot, RotaryDelta):
        if masses is not None and not isinstance(masses, RotaryDeltaMasses):
            raise ParameterError(f"rotary delta {robot.name!r} needs RotaryDeltaMasses, got {type(masses).__name__}")
        return RotaryDeltaModel(robot, masses)
    raise ParameterError(f"no analytic model for robot of type {type(robot).__name__}")


def joint_references(model: AnalyticModel, p: np.ndarray, v: np.ndarray, a: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint references for (N, 3) platform positions, velocities and accelerations (vectorised).

    ``q = IK(p)``, ``qd = J v`` (thesis eq. (16)), ``qdd = J a + [v^T H_i v]`` (thesis eq. (25)).
    Raises :class:`UnreachableError` at the first sample with no IK solution.
    """
    robot = model.robot
    p, v, a = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (p, v, a))
    q, solvable = ik_batch(robot, p)
    if not solvable.all():
        k = int(np.argmin(solvable.all(axis=1)))
        raise UnreachableError(f"reference sample {k}: p = {p[k]} m has no inverse-kinematics solution")
    rods = p[:, None, :] + platform_offsets(robot)[None] - actuator_points_batch(robot, q)
    d1, d2 = actuator_tangents_batch(robot, q)
    denom = np.einsum("nij,nij->ni", rods, d1)
    jac = rods / denom[:, :, None]
    qd = np.einsum("nij,nj->ni", jac, v)
    w = v[:, None, :] - d1 * qd[:, :, None]
    quad = (np.einsum("nij,nij->ni", w, w) - np.einsum("nij,nij->ni", rods, d2) * qd**2) / denom
    qdd = np.einsum("nij,nj->ni", jac, a) + quad
    return q, qd, qdd
