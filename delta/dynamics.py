"""Analytic virtual-work dynamics of the delta robots (thesis section 7), over ``(model, data)``.

Both robots are lumped the same way (:mod:`delta.model`): each actuator carries a constant
inertia ``D`` and the platform a point mass ``m_p``. With ``v = J^-1 qd`` (thesis eq. (31))
the kinetic and potential energies are

    T = 1/2 sum_i D qd_i^2 + 1/2 m_p |v|^2 + 1/2 mu sum_i |l_i'|^2,
    V = sum_i V_i(q_i) + m_p,g g p_z,

and d'Alembert's virtual work (thesis eqs. (30)-(35)) gives

    f = D qdd + J^-T (m_p a + m_p,g g e_z + mu sum_j l_j'') - mu [l_i'' . B_i'] + dV/dq,
    a = J^-1 (qdd - [v^T H_i v])   (thesis eq. (37)),

i.e. ``f = M(q) qdd + C(q, qd) qd + G(q)`` (thesis eq. (38)) with ``M = D + m_p J^-T J^-1 + mu sum_i
K_i^T K_i`` (``K_i = J^-1 - B_i' e_i^T``, the map from ``qd`` to ``l_i'``).

**The rods' rotation** (``mu``, :attr:`delta.model.Model.rod_inertia`). The thesis lumps each rod as two
point masses at its ends (shares ``1 - w`` and ``w``). A uniform rod of mass ``m`` whose ends move at
``v_A`` and ``v_B`` has the kinetic energy ``m/6 (|v_A|^2 + v_A . v_B + |v_B|^2)``, which is the two halves'
``m/4 (|v_A|^2 + |v_B|^2)`` less ``m/12 |v_A - v_B|^2``: the rod turning about its centre. Here ``v_B - v_A``
is the rate of the rod vector ``l_i = p + b_i - B_i(q_i)``, ``l_i' = v - B_i' qd_i``, the same for a leg's two
rods (a parallelogram). So both rods of leg ``i`` add ``1/2 mu |l_i'|^2`` with ``mu = -w_rotation m_l / 3``
(``w_rotation = 1``: a uniform rod, exact with ``w_inertia = 1/2``; 0: the thesis). That is the kinetic
energy of a (negative) point mass ``mu`` at the position ``l_i``, a function of ``p`` and ``q_i``; its virtual
work ``mu l_i'' . (dp - B_i' dq_i)``, with ``l_i'' = a - B_i' qdd_i - B_i'' qd_i^2``, gives the two ``mu``
terms of ``f`` above, and the model stays conservative. Without it the identified ``w_inertia`` came out
near 1/3 (compensating) and the fast pick cycle kept 6 % RMS effort error against the multibody plant
(``python -m cosim validate-model``).

``C qd`` is exactly ``J^-T m_p d/dt(J^-1) qd`` plus the rods' share, so ``f . qd = d/dt(T + V)`` holds
identically (tested as the power balance). The inertial and the gravity lumps may differ (``w_inertia``
vs ``w_gravity``): T and V are then built from different lumps and the model stays conservative.

The algorithms take any 3-sequences and return tuples of floats. :func:`inverse_dynamics` writes
thesis eq. (35) for the efforts (``C qd + G`` is its value at ``qdd = 0``, ``G`` at rest) and
:func:`mass_matrix` writes ``M``; :func:`forward_dynamics` solves ``M qdd = f - C qd - G`` with
both (joint coordinates: the model-exchange plant, :mod:`delta.closed_loop`).
:func:`platform_dynamics` solves eq. (35) for the platform acceleration instead (platform
coordinates, no forward kinematics: the co-simulation plant's right-hand side). The two routes are
tested against each other (``tests/unit/test_dynamics.py``).
:class:`AnalyticModel` is the same on numpy arrays, for scripts and tests.
"""

from __future__ import annotations

from math import isfinite

import numpy as np

from .errors import ParameterError, RobotError, UnreachableError
from .kinematics import (
    PARALLEL,
    NO_SOLUTION,
    SERIAL,
    ik_batch,
    inv3,
    leg_rates,
    rates_batch,
    serial_singularity,
    update,
)
from .masses import GRAVITY, LinearDeltaMasses, Masses, RotaryDeltaMasses
from .model import Data, Model, as_model, build_model
from .robots import Robot

__all__ = [
    "GRAVITY",
    "LinearDeltaMasses",
    "RotaryDeltaMasses",
    "inverse_dynamics",
    "mass_matrix",
    "forward_dynamics",
    "gravity",
    "platform_state",
    "energy",
    "platform_dynamics",
    "rk4_step",
    "platform_step",
    "substeps",
    "integrate",
    "AnalyticModel",
    "analytic_model",
    "joint_references",
]

Vec = tuple[float, float, float]


def inverse_dynamics(model: Model, data: Data, q, qd, qdd) -> Vec:  # noqa: ANN001
    """Actuator efforts along +q (N for a linear delta, N m for a rotary one) that give ``qdd`` at ``(q, qd)``.

    Thesis eq. (35): ``f = D qdd + J^-T (m_p a + m_p,g g e_z) + dV_i/dq_i`` with the platform
    acceleration ``a = J^-1 (qdd - [v^T H_i v])`` (thesis eq. (37)) and ``v = J^-1 qd`` (eq. (31)),
    plus the rods' rotation ``J^-T mu sum_j l_j'' - mu l_i'' . B_i'`` (module docstring), which is
    ``M qdd + C qd + G`` (thesis eq. (38)) without forming ``M`` and ``C``.
    """
    update(model, data, q)
    j00, j01, j02, j10, j11, j12, j20, j21, j22 = data.jinv
    qd0, qd1, qd2 = qd
    a0, a1, a2 = qdd
    v0 = j00 * qd0 + j01 * qd1 + j02 * qd2
    v1 = j10 * qd0 + j11 * qd1 + j12 * qd2
    v2 = j20 * qd0 + j21 * qd1 + j22 * qd2
    leg0, leg1, leg2 = data.legs
    r0 = a0 - leg_rates(leg0, v0, v1, v2, 0.0, 0.0, 0.0)[1]  # qdd - [v^T H_i v]
    r1 = a1 - leg_rates(leg1, v0, v1, v2, 0.0, 0.0, 0.0)[1]
    r2 = a2 - leg_rates(leg2, v0, v1, v2, 0.0, 0.0, 0.0)[1]
    p0 = j00 * r0 + j01 * r1 + j02 * r2  # the platform acceleration a
    p1 = j10 * r0 + j11 * r1 + j12 * r2
    p2 = j20 * r0 + j21 * r1 + j22 * r2
    mp, d, mu = model.platform_mass, model.inertia, model.rod_inertia
    q0, q1, q2 = data.q
    # the rods' rotation: the rate of l_i = p + b_i - B_i is l_i'' = a - B_i' qdd_i - B_i'' qd_i^2
    rods = [_rod_acceleration(model, leg, qi, c, p0, p1, p2, ai, qdi)
            for leg, qi, c, ai, qdi in zip(data.legs, data.q, model.legs, qdd, qd)]
    (s0, s1, s2, b0), (t0, t1, t2, b1), (u0, u1, u2, b2) = rods
    y0 = mp * p0 + mu * (s0 + t0 + u0)  # m_p a + m_p,g g e_z + mu sum_i l_i''
    y1 = mp * p1 + mu * (s1 + t1 + u1)
    y2 = mp * p2 + model.platform_weight + mu * (s2 + t2 + u2)
    gravity, w, xp = model.actuator.gravity, model.actuator_weight, model.xp
    return (d * a0 + j00 * y0 + j10 * y1 + j20 * y2 + gravity(q0, w, xp) - mu * b0,
            d * a1 + j01 * y0 + j11 * y1 + j21 * y2 + gravity(q1, w, xp) - mu * b1,
            d * a2 + j02 * y0 + j12 * y1 + j22 * y2 + gravity(q2, w, xp) - mu * b2)


def _rod_acceleration(model: Model, leg, q, axis, ax, ay, az, qdd, qd):  # noqa: ANN001, ANN202
    """``l_i'' = a - B_i' qdd_i - B_i'' qd_i^2`` of one leg (the rod vector's acceleration) and ``l_i'' . B_i'``."""
    d1x, d1y, d1z = leg[3], leg[4], leg[5]
    d2x, d2y, d2z = model.actuator.curve(q, axis[0], axis[1], model.xp)
    q2 = qd * qd
    lx, ly, lz = ax - d1x * qdd - d2x * q2, ay - d1y * qdd - d2y * q2, az - d1z * qdd - d2z * q2
    return lx, ly, lz, lx * d1x + ly * d1y + lz * d1z


def mass_matrix(model: Model, data: Data, q) -> tuple[float, ...]:  # noqa: ANN001
    """Joint-space inertia ``M(q) = D + m_p J^-T J^-1 + mu sum_i K_i^T K_i`` (thesis eqs. (35)-(38) and the
    rods' rotation), upper triangle ``(m00, m01, m02, m11, m12, m22)``; ``M`` is symmetric positive definite.

    ``K_i = J^-1 - B_i' e_i^T`` maps ``qd`` to the rod rate ``l_i' = v - B_i' qd_i``, so with ``c_k`` the
    columns of ``J^-1``: ``sum_i K_i^T K_i = 3 c_k . c_m - B_m' . c_k - B_k' . c_m + delta_km |B_k'|^2``."""
    update(model, data, q)
    j00, j01, j02, j10, j11, j12, j20, j21, j22 = data.jinv
    mp, d, mu = model.platform_mass, model.inertia, model.rod_inertia
    c = ((j00, j10, j20), (j01, j11, j21), (j02, j12, j22))
    b = [leg[3:6] for leg in data.legs]

    def rods(k: int, m: int):  # noqa: ANN202
        ck, cm, bk, bm = c[k], c[m], b[k], b[m]
        out = (3.0 * (ck[0] * cm[0] + ck[1] * cm[1] + ck[2] * cm[2]) - (bm[0] * ck[0] + bm[1] * ck[1] + bm[2] * ck[2])
               - (bk[0] * cm[0] + bk[1] * cm[1] + bk[2] * cm[2]))
        return out + (bk[0] * bk[0] + bk[1] * bk[1] + bk[2] * bk[2]) if k == m else out

    return (mp * (j00 * j00 + j10 * j10 + j20 * j20) + d + mu * rods(0, 0), mp * (j00 * j01 + j10 * j11 + j20 * j21)
            + mu * rods(0, 1), mp * (j00 * j02 + j10 * j12 + j20 * j22) + mu * rods(0, 2),
            mp * (j01 * j01 + j11 * j11 + j21 * j21) + d + mu * rods(1, 1),
            mp * (j01 * j02 + j11 * j12 + j21 * j22) + mu * rods(1, 2), mp * (j02 * j02 + j12 * j12 + j22 * j22) + d
            + mu * rods(2, 2))


_REST = (0.0, 0.0, 0.0)


def _platform_acceleration(model: Model, legs, q, v, f) -> Vec:  # noqa: ANN001
    """Platform acceleration ``a`` under the efforts ``f`` at the pose of ``legs`` (joint values ``q``)
    moving at ``v``: thesis eq. (35) with ``qdd = J a + [v^T H_i v]`` (eq. (25)), multiplied by ``J^T``:

        (D J^T J + m_p I + mu sum_i K_i^T K_i) a
            = J^T (f - G_act - D [v^T H_i v]) - m_p,g g e_z + mu sum_i K_i^T (B_i' [v^T H_i v] + B_i'' qd_i^2)

    with ``K_i = I - B_i' J_i`` (the rod rate ``l_i' = K_i v``; ``mu = 0``: the thesis's lumping): a
    symmetric positive definite 3x3 system in the platform coordinates: no ``J^-1``, no ``M``."""
    d, mp, mu = model.inertia, model.platform_mass, model.rod_inertia
    gravity, w, xp, curve = model.actuator.gravity, model.actuator_weight, model.xp, model.actuator.curve
    vx, vy, vz = v
    rows, rods = [], []
    for leg, qi, fi, axis in zip(legs, q, f, model.legs):
        den = leg[7]
        if not xp.check(den != 0.0, SERIAL[len(rows)]):
            raise serial_singularity(len(rows) + 1, q)
        qdi, quad = leg_rates(leg, vx, vy, vz, 0.0, 0.0, 0.0)
        ji = (leg[0] / den, leg[1] / den, leg[2] / den)
        rows.append((*ji, fi - gravity(qi, w, xp) - d * quad))
        bi, b2, q2 = leg[3:6], curve(qi, axis[0], axis[1], xp), qdi * qdi
        g = (bi[0] * quad + b2[0] * q2, bi[1] * quad + b2[1] * q2, bi[2] * quad + b2[2] * q2)
        rods.append((ji, bi, g, bi[0] * g[0] + bi[1] * g[1] + bi[2] * g[2]))
    (j00, j01, j02, r0), (j10, j11, j12, r1), (j20, j21, j22, r2) = rows
    b0 = j00 * r0 + j10 * r1 + j20 * r2
    b1 = j01 * r0 + j11 * r1 + j21 * r2
    b2 = j02 * r0 + j12 * r1 + j22 * r2 - model.platform_weight
    a00 = d * (j00 * j00 + j10 * j10 + j20 * j20) + mp
    a01 = d * (j00 * j01 + j10 * j11 + j20 * j21)
    a02 = d * (j00 * j02 + j10 * j12 + j20 * j22)
    a11 = d * (j01 * j01 + j11 * j11 + j21 * j21) + mp
    a12 = d * (j01 * j02 + j11 * j12 + j21 * j22)
    a22 = d * (j02 * j02 + j12 * j12 + j22 * j22) + mp

    def kk(k: int, m: int):  # noqa: ANN202  # sum_i (K_i^T K_i)_km = sum_i delta_km - J_ik B_im - B_ik J_im + |B_i|^2 J_ik J_im
        out = 0.0
        for ji, bi, _, _ in rods:
            out = out - ji[k] * bi[m] - bi[k] * ji[m] + (bi[0] * bi[0] + bi[1] * bi[1] + bi[2] * bi[2]) * ji[k] * ji[m]
        return out + 3.0 if k == m else out

    def kg(k: int):  # noqa: ANN202  # sum_i (K_i^T g_i)_k = sum_i g_ik - J_ik (B_i . g_i)
        out = 0.0
        for ji, _, g, bg in rods:
            out = out + g[k] - ji[k] * bg
        return out

    ai, det = inv3(a00 + mu * kk(0, 0), a01 + mu * kk(0, 1), a02 + mu * kk(0, 2), a01 + mu * kk(0, 1),
                   a11 + mu * kk(1, 1), a12 + mu * kk(1, 2), a02 + mu * kk(0, 2), a12 + mu * kk(1, 2),
                   a22 + mu * kk(2, 2))
    if not xp.check(det != 0.0, PARALLEL):
        raise RobotError(f"type 2 (parallel) singularity at q = {tuple(q)}: J is singular")
    b0, b1, b2 = b0 + mu * kg(0), b1 + mu * kg(1), b2 + mu * kg(2)
    return (ai[0] * b0 + ai[1] * b1 + ai[2] * b2,
            ai[3] * b0 + ai[4] * b1 + ai[5] * b2,
            ai[6] * b0 + ai[7] * b1 + ai[8] * b2)


def forward_dynamics(model: Model, data: Data, q, qd, f) -> Vec:  # noqa: ANN001
    """Joint accelerations ``qdd = M^-1 (f - C qd - G)``, with ``C qd + G`` the inverse dynamics at
    ``qdd = 0`` (the joint-coordinate model of the model-exchange plant and :mod:`delta.closed_loop`)."""
    n0, n1, n2 = inverse_dynamics(model, data, q, qd, _REST)
    m00, m01, m02, m11, m12, m22 = mass_matrix(model, data, q)
    mi = inv3(m00, m01, m02, m01, m11, m12, m02, m12, m22)[0]  # M is positive definite
    r0, r1, r2 = f[0] - n0, f[1] - n1, f[2] - n2
    return (mi[0] * r0 + mi[1] * r1 + mi[2] * r2,
            mi[3] * r0 + mi[4] * r1 + mi[5] * r2,
            mi[6] * r0 + mi[7] * r1 + mi[8] * r2)


def platform_dynamics(model: Model, p, v, f) -> Vec:  # noqa: ANN001
    """Platform acceleration under the efforts ``f`` at the platform state ``(p, v)`` (inverse kinematics,
    no forward kinematics): the right-hand side of the analytic plant, which integrates in platform
    coordinates. Raises :class:`UnreachableError` when ``p`` leaves the workspace."""
    x, y, z = p
    solve, leg_at, xp = model.actuator.solve, model.actuator.leg, model.xp
    q, legs = [], []
    for c, s, ox, oy in model.legs:
        qi, ok = solve(x, y, z, c, s, ox, oy, xp)
        if not xp.check(ok, NO_SOLUTION[len(q)]):
            raise UnreachableError(f"the platform left the workspace at p = ({x:.6g}, {y:.6g}, {z:.6g}) m: "
                                   f"leg {len(q) + 1} has no solution")
        q.append(qi)
        legs.append(leg_at(qi, c, s, ox, oy, x, y, z, xp))
    return _platform_acceleration(model, legs, q, v, f)


def gravity(model: Model, data: Data, q) -> Vec:  # noqa: ANN001
    """``G(q) = dV/dq``: the effort along +q that holds the robot still."""
    return inverse_dynamics(model, data, q, _REST, _REST)


def platform_state(model: Model, data: Data, q, qd) -> tuple[Vec, Vec]:  # noqa: ANN001
    """Platform position ``p`` (forward kinematics) and velocity ``v = J^-1 qd`` (thesis eq. (31))."""
    update(model, data, q)
    j = data.jinv
    qd0, qd1, qd2 = qd
    return data.p, (j[0] * qd0 + j[1] * qd1 + j[2] * qd2, j[3] * qd0 + j[4] * qd1 + j[5] * qd2,
                    j[6] * qd0 + j[7] * qd1 + j[8] * qd2)


def energy(model: Model, data: Data, q, qd) -> tuple[float, float]:  # noqa: ANN001
    """Kinetic and potential energy of the lumped model, J (potential zero at q = 0, p_z = 0)."""
    p, v = platform_state(model, data, q, qd)
    act, w = model.actuator, model.actuator_weight
    kinetic = 0.5 * model.inertia * sum(x * x for x in qd) + 0.5 * model.platform_mass * sum(x * x for x in v)
    for leg, qdi in zip(data.legs, qd):  # the rods' rotation: 1/2 mu |l_i'|^2, l_i' = v - B_i' qd_i
        kinetic += 0.5 * model.rod_inertia * sum((vk - bk * qdi) ** 2 for vk, bk in zip(v, leg[3:6]))
    potential = sum(act.potential(x, w, model.xp) for x in data.q) + model.platform_weight * p[2]
    return kinetic, potential


def rk4_step(accel, x, xd, dt: float) -> tuple[Vec, Vec]:  # noqa: ANN001
    """One classical Runge-Kutta step of the second-order system ``x'' = accel(x, x')`` (three coordinates)."""
    half = 0.5 * dt
    x0, x1, x2 = x
    v0, v1, v2 = xd
    a = accel(x, xd)
    b_v = (v0 + half * a[0], v1 + half * a[1], v2 + half * a[2])
    b = accel((x0 + half * v0, x1 + half * v1, x2 + half * v2), b_v)
    c_v = (v0 + half * b[0], v1 + half * b[1], v2 + half * b[2])
    c = accel((x0 + half * b_v[0], x1 + half * b_v[1], x2 + half * b_v[2]), c_v)
    d_v = (v0 + dt * c[0], v1 + dt * c[1], v2 + dt * c[2])
    d = accel((x0 + dt * c_v[0], x1 + dt * c_v[1], x2 + dt * c_v[2]), d_v)
    s = dt / 6.0
    return ((x0 + s * (v0 + 2.0 * (b_v[0] + c_v[0]) + d_v[0]),
             x1 + s * (v1 + 2.0 * (b_v[1] + c_v[1]) + d_v[1]),
             x2 + s * (v2 + 2.0 * (b_v[2] + c_v[2]) + d_v[2])),
            (v0 + s * (a[0] + 2.0 * (b[0] + c[0]) + d[0]),
             v1 + s * (a[1] + 2.0 * (b[1] + c[1]) + d[1]),
             v2 + s * (a[2] + 2.0 * (b[2] + c[2]) + d[2])))


def integrate(model: Model, p, v, f, h: float, max_step: float) -> tuple[Vec, Vec]:  # noqa: ANN001
    """Advance the platform state ``(p, v)`` by ``h`` s under the held efforts ``f`` in ``ceil(h / max_step)``
    equal RK4 steps of :func:`platform_dynamics` (the analytic plant's stepper).

    Platform coordinates need inverse kinematics only (three closed-form legs) where joint coordinates
    need the forward kinematics (a sphere intersection) and ``J^-1`` at every stage; the two describe
    the same motion. Raises :class:`ParameterError` for a non-finite effort, :class:`UnreachableError` /
    :class:`RobotError` when the state leaves the workspace or meets a singularity, and
    :class:`RobotError` when the result is not finite.
    """
    if not all(isfinite(x) for x in f):
        raise ParameterError(f"non-finite effort u = {list(f)}")
    n = substeps(h, max_step)
    dt = h / n
    for _ in range(n):
        p, v = platform_step(model, p, v, f, dt)
    if not all(isfinite(x) for x in (*p, *v)):
        raise RobotError(f"the state diverged to p = {list(p)}, v = {list(v)} (effort u = {list(f)})")
    return p, v


def substeps(h: float, max_step: float) -> int:
    """Number of equal steps no longer than ``max_step`` that make up ``h`` (at least one)."""
    return max(1, -int(-h // max_step))


def platform_step(model: Model, p, v, f, dt: float) -> tuple[Vec, Vec]:  # noqa: ANN001
    """One RK4 step of :func:`platform_dynamics` under the held efforts ``f``: the analytic plant's stage."""
    return rk4_step(lambda x, xd: platform_dynamics(model, x, xd, f), p, v, dt)


class AnalyticModel:
    """The analytic model on numpy arrays: the algorithms above with a :class:`Data` of its own.

    ``model`` is the compiled :class:`~delta.model.Model`; ``robot``, ``masses`` and ``kind`` are its.
    """

    def __init__(self, model: Model) -> None:
        self.model = model
        self.data = Data(model)
        self.robot, self.masses, self.kind = model.robot, model.masses, model.kind

    def _args(self, *xs):  # noqa: ANN002, ANN202
        return (self.model, self.data, *(np.asarray(x, dtype=float).reshape(3).tolist() for x in xs))

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """Joint-space inertia ``M(q)`` (3, 3), see :func:`mass_matrix`."""
        m00, m01, m02, m11, m12, m22 = mass_matrix(*self._args(q))
        return np.array([[m00, m01, m02], [m01, m11, m12], [m02, m12, m22]])

    def velocity_term(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Centrifugal/Coriolis effort ``C(q, qd) qd`` (3,): the inverse dynamics at ``qdd = 0`` less ``G``."""
        return np.array(inverse_dynamics(*self._args(q, qd, np.zeros(3)))) - self.gravity_term(q)

    def gravity_term(self, q: np.ndarray) -> np.ndarray:
        """Gravity effort ``G(q) = dV/dq`` (3,)."""
        return np.array(gravity(*self._args(q)))

    def inverse_dynamics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        return np.array(inverse_dynamics(*self._args(q, qd, qdd)))

    def forward_dynamics(self, q: np.ndarray, qd: np.ndarray, f: np.ndarray) -> np.ndarray:
        return np.array(forward_dynamics(*self._args(q, qd, f)))

    def platform_state(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p, v = platform_state(*self._args(q, qd))
        return np.array(p), np.array(v)

    def energy(self, q: np.ndarray, qd: np.ndarray) -> tuple[float, float]:
        return energy(*self._args(q, qd))


def analytic_model(robot: Robot, masses: Masses | None = None) -> AnalyticModel:
    """The analytic model of ``robot`` (masses default to the kind's dataclass defaults)."""
    return AnalyticModel(build_model(robot, masses))


def joint_references(model: Model | AnalyticModel, p: np.ndarray, v: np.ndarray, a: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint references for (N, 3) platform positions, velocities and accelerations (batch path).

    ``q = IK(p)``, ``qd = J v`` (thesis eq. (16)), ``qdd = J a + [v^T H_i v]`` (thesis eq. (25)).
    Raises :class:`UnreachableError` at the first sample with no IK solution.
    """
    model = as_model(model)
    p, v, a = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (p, v, a))
    q, solvable = ik_batch(model, p)
    if not solvable.all():
        k = int(np.argmin(solvable.all(axis=1)))
        raise UnreachableError(f"reference sample {k}: p = {p[k]} m has no inverse-kinematics solution")
    qd, qdd = rates_batch(model, q, p, v, a)
    return q, qd, qdd
