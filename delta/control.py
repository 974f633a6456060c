"""Discrete-time joint-space controllers (thesis sections 9-11), SI units.

Each controller is called once per sample period ``h`` with the measured joint
state and the joint references and returns the actuator efforts ``u`` (3,) along
+q (N for a linear delta, N*m for a rotary delta), held constant over the period.
Gains are per joint: a scalar or 3 values. Controllers hold ``h`` and their state
(the PID integral); :meth:`reset` clears it. :meth:`Controller.output_scalar` is the
per-step path: the same effort as :meth:`Controller.output` as a tuple of plain floats.
"""

from __future__ import annotations

import math

import numpy as np

from .actuators import SCALAR
from .dynamics import AnalyticModel, gravity, inverse_dynamics
from .errors import ParameterError
from .model import Data, Model, as_model
from .robots import Robot

__all__ = ["Controller", "PD", "PID", "PDPlus", "CTC", "default_controller", "DEFAULT_GAINS", "KINDS"]

_Vec = tuple[float, float, float]


def _per_joint(cls: str, name: str, value: object, positive: bool = False) -> _Vec:
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.size == 1:
        arr = np.repeat(arr, 3)
    given = value.tolist() if isinstance(value, np.ndarray) else value  # as a message shows it: no array(...)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ParameterError(f"{cls}.{name} must be a scalar or 3 finite values, got {given!r}", name=f"{cls}.{name}")
    if not all(_gain_ok(x, positive) for x in arr.tolist()):
        raise ParameterError(f"{cls}.{name} must be {'> 0' if positive else '>= 0'} per joint, got {given!r}",
                             name=f"{cls}.{name}")
    return float(arr[0]), float(arr[1]), float(arr[2])


def _gain_ok(x, positive: bool):  # noqa: ANN001, ANN202
    """The condition on one joint's gain or limit: > 0 (``positive``) or >= 0."""
    return x > 0.0 if positive else x >= 0.0


_GAINS = {"kp": True, "ki": False, "kd": False}  # gain -> must be > 0 (else >= 0), as the constructors check


def _limit(cls: str, name: str, value: object) -> _Vec | None:
    return None if value is None else _per_joint(cls, name, value, positive=True)


def _period(cls: str, h: float) -> float:
    if not (h > 0.0 and math.isfinite(h)):
        raise ParameterError(f"{cls}.h must be a sample period > 0 s, got {h!r}")
    return float(h)


def _clip(u0: float, u1: float, u2: float, u_max: _Vec | None, xp=SCALAR) -> _Vec:  # noqa: ANN001
    if u_max is None:
        return u0, u1, u2
    m0, m1, m2 = u_max
    where = xp.where
    return (where(u0 > m0, m0, where(u0 < -m0, -m0, u0)),
            where(u1 > m1, m1, where(u1 < -m1, -m1, u1)),
            where(u2 > m2, m2, where(u2 < -m2, -m2, u2)))


def _floats(x):  # noqa: ANN001, ANN202
    """A 3-sequence with plain float items (arrays through one ``tolist``; same values)."""
    return x.tolist() if type(x) is np.ndarray else x


class Controller:
    """Interface: ``reset()``, ``step(q, qd, q_ref, qd_ref, qdd_ref) -> u`` (all (3,)), called once
    per period ``h`` (it advances the internal state), and ``output(...)``, the same effort
    without changing the state (for hosts that read the output more than once per period,
    e.g. an FMU's getter before ``doStep``); ``output_scalar(...)`` is ``output`` as a tuple
    of 3 plain floats (the per-step path, no arrays). ``stateful`` tells whether :meth:`step`
    changes anything beyond :meth:`output` (hosts may skip it for stateless laws).
    Inputs are any 3-sequences of floats (tuples, lists, arrays)."""

    h: float
    u_max: _Vec | None
    stateful = False
    xp = SCALAR  # the number namespace (symbols when fmus.native traces the law)

    @classmethod
    def traced(cls, xp, **fields):  # noqa: ANN001, ANN206
        """A law whose gains, limits and period are the symbols ``fields`` (names as the attributes set by
        ``__init__``), evaluated in the namespace ``xp``; no checks (``fmus.native`` traces it to C)."""
        law = object.__new__(cls)
        law.__dict__.update(fields, xp=xp)
        for name, positive in _GAINS.items():  # the constructors' checks, recorded for the generated code
            for i, x in enumerate(fields.get(name, ())):
                xp.check(xp.both(xp.isfinite(x), _gain_ok(x, positive)),
                         f"{cls.__name__}.{name} must be {'> 0' if positive else '>= 0'} per joint (joint {i + 1})")
        for i, x in enumerate(fields.get("u_max") or ()):
            xp.check(_gain_ok(x, True), f"{cls.__name__}.u_max must be > 0 per joint (joint {i + 1})")
        return law

    @classmethod
    def check(cls, h: float, u_max=None, **gains) -> None:  # noqa: ANN001
        """What the constructor refuses, without making the law (no model needed): each gain of ``gains`` (``kp``,
        ``ki``, ``kd``), the limit ``u_max`` (None: no saturation) and the period ``h``, by the same checks and
        messages (a pre-flight checks a scenario's gains with it)."""
        for name, value in gains.items():
            _per_joint(cls.__name__, name, value, positive=_GAINS[name])
        _limit(cls.__name__, "u_max", u_max)
        _period(cls.__name__, h)

    def reset(self) -> None:
        """Clear the internal state (nothing for stateless laws)."""

    def step(self, q, qd, q_ref, qd_ref, qdd_ref) -> np.ndarray:  # noqa: ANN001
        raise NotImplementedError

    def output(self, q, qd, q_ref, qd_ref, qdd_ref) -> np.ndarray:  # noqa: ANN001
        """Effort (3,) for these inputs, without changing the state."""
        return np.array(self.output_scalar(q, qd, q_ref, qd_ref, qdd_ref))

    def output_scalar(self, q, qd, q_ref, qd_ref, qdd_ref) -> _Vec:  # noqa: ANN001
        """:meth:`output` as a tuple of 3 floats; stateless laws evaluate :meth:`step`."""
        return tuple(np.asarray(self.step(q, qd, q_ref, qd_ref, qdd_ref), dtype=float).tolist())


class PD(Controller):
    """``u = Kp (q_ref - q) + Kd (qd_ref - qd)`` (thesis eq. (39)), saturated at ``u_max``.

    ``kp`` in N/m (N*m/rad), ``kd`` in N*s/m (N*m*s/rad).
    """

    def __init__(self, kp, kd, h: float, u_max=None) -> None:  # noqa: ANN001
        self.kp = _per_joint("PD", "kp", kp, positive=True)
        self.kd = _per_joint("PD", "kd", kd)
        self.h = _period("PD", h)
        self.u_max = _limit("PD", "u_max", u_max)

    def output_scalar(self, q, qd, q_ref, qd_ref, qdd_ref) -> _Vec:  # noqa: ANN001
        q, qd, q_ref, qd_ref = _floats(q), _floats(qd), _floats(q_ref), _floats(qd_ref)
        (kp0, kp1, kp2), (kd0, kd1, kd2) = self.kp, self.kd
        return _clip(kp0 * (q_ref[0] - q[0]) + kd0 * (qd_ref[0] - qd[0]),
                     kp1 * (q_ref[1] - q[1]) + kd1 * (qd_ref[1] - qd[1]),
                     kp2 * (q_ref[2] - q[2]) + kd2 * (qd_ref[2] - qd[2]), self.u_max, self.xp)

    def step(self, q, qd, q_ref, qd_ref, qdd_ref) -> np.ndarray:  # noqa: ANN001
        return np.array(self.output_scalar(q, qd, q_ref, qd_ref, qdd_ref))


class PID(Controller):
    """``u = Kp e + Kd e_dot + Ki int e dt`` (thesis eq. (40)) with anti-windup and saturation.

    The integral is the forward-Euler sum of ``e h``. Anti-windup: (1) conditional
    integration, the integral does not grow while the output is saturated and the error
    pushes it further into saturation; (2) the integral contribution ``Ki int e`` is
    clamped to ``+-i_max`` (default ``u_max``). ``ki`` in N/(m*s) (N*m/(rad*s)).
    """

    stateful = True

    def __init__(self, kp, ki, kd, h: float, u_max=None, i_max=None) -> None:  # noqa: ANN001
        self.kp = _per_joint("PID", "kp", kp, positive=True)
        self.ki = _per_joint("PID", "ki", ki)
        self.kd = _per_joint("PID", "kd", kd)
        self.h = _period("PID", h)
        self.u_max = _limit("PID", "u_max", u_max)
        self.i_max = _limit("PID", "i_max", i_max) if i_max is not None else self.u_max
        self.integral = [0.0, 0.0, 0.0]

    def reset(self) -> None:
        self.integral = [0.0, 0.0, 0.0]

    def _evaluate(self, q, qd, q_ref, qd_ref, qdd_ref) -> tuple[_Vec, list[float]]:  # noqa: ANN001
        q, qd, q_ref, qd_ref = _floats(q), _floats(qd), _floats(q_ref), _floats(qd_ref)
        xp = self.xp
        where, both = xp.where, xp.both
        u = [0.0, 0.0, 0.0]
        integral = [0.0, 0.0, 0.0]
        for i in range(3):
            e = q_ref[i] - q[i]
            pd = self.kp[i] * e + self.kd[i] * (qd_ref[i] - qd[i])
            old = self.integral[i]
            new = old + e * self.h
            ki = self.ki[i]
            if self.i_max is not None:  # ki + (ki <= 0) is ki where the quotient is used: no division by 0
                bound = where(ki > 0.0, self.i_max[i] / (ki + (ki <= 0.0)), math.inf)
                new = xp.minimum(xp.maximum(new, -bound), bound)
            out = pd + ki * new
            if self.u_max is not None:  # conditional integration
                new = where(both(both(abs(out) > self.u_max[i], out * e > 0.0), abs(new) > abs(old)), old, new)
                out = pd + ki * new
            integral[i] = new
            u[i] = out
        return _clip(u[0], u[1], u[2], self.u_max, xp), integral

    def output_scalar(self, q, qd, q_ref, qd_ref, qdd_ref) -> _Vec:  # noqa: ANN001
        return self._evaluate(q, qd, q_ref, qd_ref, qdd_ref)[0]

    def step(self, q, qd, q_ref, qd_ref, qdd_ref) -> np.ndarray:  # noqa: ANN001
        u, self.integral = self._evaluate(q, qd, q_ref, qd_ref, qdd_ref)
        return np.array(u)


class PDPlus(Controller):
    """PD with gravity compensation: ``u = Kp e + Kd e_dot + G(q)`` from the analytic model."""

    def __init__(self, model: AnalyticModel | Model, kp, kd, h: float, u_max=None) -> None:  # noqa: ANN001
        self.model = as_model(model)
        self.data = Data(self.model)
        self.kp = _per_joint("PDPlus", "kp", kp, positive=True)
        self.kd = _per_joint("PDPlus", "kd", kd)
        self.h = _period("PDPlus", h)
        self.u_max = _limit("PDPlus", "u_max", u_max)

    def output_scalar(self, q, qd, q_ref, qd_ref, qdd_ref) -> _Vec:  # noqa: ANN001
        q, qd, q_ref, qd_ref = _floats(q), _floats(qd), _floats(q_ref), _floats(qd_ref)
        g0, g1, g2 = gravity(self.model, self.data, q)
        (kp0, kp1, kp2), (kd0, kd1, kd2) = self.kp, self.kd
        return _clip(kp0 * (q_ref[0] - q[0]) + kd0 * (qd_ref[0] - qd[0]) + g0,
                     kp1 * (q_ref[1] - q[1]) + kd1 * (qd_ref[1] - qd[1]) + g1,
                     kp2 * (q_ref[2] - q[2]) + kd2 * (qd_ref[2] - qd[2]) + g2, self.u_max, self.model.xp)

    def step(self, q, qd, q_ref, qd_ref, qdd_ref) -> np.ndarray:  # noqa: ANN001
        return np.array(self.output_scalar(q, qd, q_ref, qd_ref, qdd_ref))


class CTC(Controller):
    """Computed torque control ``u = M(q) (qdd_ref + Kd e_dot + Kp e) + C(q, qd) qd + G(q)`` (thesis eq. (50)).

    ``kp`` in 1/s^2 and ``kd`` in 1/s (the error dynamics are ``e'' + Kd e' + Kp e = 0``,
    thesis eq. (48)-(49)). With ``feedforward=False`` the velocity and acceleration
    references are dropped (``qd_ref = qdd_ref = 0``: regulation to ``q_ref``).
    """

    def __init__(self, model: AnalyticModel | Model, kp, kd, h: float, u_max=None,  # noqa: ANN001
                 feedforward: bool = True) -> None:
        self.model = as_model(model)
        self.data = Data(self.model)
        self.kp = _per_joint("CTC", "kp", kp, positive=True)
        self.kd = _per_joint("CTC", "kd", kd)
        self.h = _period("CTC", h)
        self.u_max = _limit("CTC", "u_max", u_max)
        self.feedforward = bool(feedforward)

    def output_scalar(self, q, qd, q_ref, qd_ref, qdd_ref) -> _Vec:  # noqa: ANN001
        q, qd, q_ref, qd_ref, qdd_ref = _floats(q), _floats(qd), _floats(q_ref), _floats(qd_ref), _floats(qdd_ref)
        (kp0, kp1, kp2), (kd0, kd1, kd2) = self.kp, self.kd
        if self.feedforward:
            w = (qdd_ref[0] + kd0 * (qd_ref[0] - qd[0]) + kp0 * (q_ref[0] - q[0]),
                 qdd_ref[1] + kd1 * (qd_ref[1] - qd[1]) + kp1 * (q_ref[1] - q[1]),
                 qdd_ref[2] + kd2 * (qd_ref[2] - qd[2]) + kp2 * (q_ref[2] - q[2]))
        else:
            w = (kp0 * (q_ref[0] - q[0]) - kd0 * qd[0],
                 kp1 * (q_ref[1] - q[1]) - kd1 * qd[1],
                 kp2 * (q_ref[2] - q[2]) - kd2 * qd[2])
        u0, u1, u2 = inverse_dynamics(self.model, self.data, q, qd, w)  # thesis eq. (50)
        return _clip(u0, u1, u2, self.u_max, self.model.xp)

    def step(self, q, qd, q_ref, qd_ref, qdd_ref) -> np.ndarray:  # noqa: ANN001
        return np.array(self.output_scalar(q, qd, q_ref, qd_ref, qdd_ref))


KINDS = ("pd", "pid", "pdplus", "ctc")

# Tuned on the analytic model, h = 1 ms (see tests/unit/test_control.py). Joint-space
# effective inertia: linear thesis robot ~1.0-1.6 kg, rotary prototype ~0.03-0.05 kg m^2.
# PD/PID/PD+: kp sets the stiffness (sag G/kp), kd ~ critical damping 2 sqrt(kp m);
# PID integral time kp/ki = 0.1 s (Routh: kd kp > m ki holds with a wide margin).
# CTC: natural frequency 150 rad/s, damping ratio 1 (kp = wn^2, kd = 2 wn): wn h = 0.15.
# u_max: assumed actuator limits (the thesis gives none), far above the helix's needs.
DEFAULT_GAINS: dict[str, dict[str, dict[str, float]]] = {
    "linear": {
        "pd": {"kp": 4.0e4, "kd": 500.0},
        "pid": {"kp": 4.0e4, "ki": 4.0e5, "kd": 500.0},
        "pdplus": {"kp": 4.0e4, "kd": 500.0},
        "ctc": {"kp": 22500.0, "kd": 300.0},
        "u_max": {"u_max": 500.0},
    },
    "rotary": {
        "pd": {"kp": 1000.0, "kd": 12.0},
        "pid": {"kp": 1000.0, "ki": 1.0e4, "kd": 12.0},
        "pdplus": {"kp": 1000.0, "kd": 12.0},
        "ctc": {"kp": 22500.0, "kd": 300.0},
        "u_max": {"u_max": 50.0},
    },
}


def default_controller(kind: str, robot: Robot, model: AnalyticModel | Model | None = None,
                       h: float = 1e-3) -> Controller:
    """A controller of ``kind`` (``"pd"``, ``"pid"``, ``"pdplus"``, ``"ctc"``) with the tuned defaults.

    ``model`` is required by ``"pdplus"`` and ``"ctc"``.
    """
    if kind not in KINDS:
        raise ParameterError(f"unknown controller kind {kind!r}; valid kinds: {', '.join(KINDS)}")
    table = DEFAULT_GAINS[robot.kind]
    gains = table[kind]
    u_max = table["u_max"]["u_max"]
    if kind in ("pdplus", "ctc") and model is None:
        raise ParameterError(f"controller {kind!r} needs the analytic model (pass model=analytic_model(robot))")
    if kind == "pd":
        return PD(gains["kp"], gains["kd"], h, u_max=u_max)
    if kind == "pid":
        return PID(gains["kp"], gains["ki"], gains["kd"], h, u_max=u_max)
    if kind == "pdplus":
        return PDPlus(model, gains["kp"], gains["kd"], h, u_max=u_max)
    return CTC(model, gains["kp"], gains["kd"], h, u_max=u_max)
