"""Analytic dynamics of the delta robots (thesis section 7, virtual work).

Mass parameters are shared by the analytic model and the multibody plants so
that both describe the same machine.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

from .errors import ParameterError

__all__ = ["LinearDeltaMasses", "RotaryDeltaMasses", "GRAVITY"]

GRAVITY = 9.81
"""Standard gravity used by default, m/s^2 (acts along -z)."""


def _check(obj: object) -> None:
    for f in fields(obj):
        value = getattr(obj, f.name)
        if f.name.startswith("w_"):
            if not 0.0 <= value <= 1.0:
                raise ParameterError(f"{type(obj).__name__}.{f.name} must be in [0, 1], got {value!r}")
        elif isinstance(value, float) and value < 0.0:
            raise ParameterError(f"{type(obj).__name__}.{f.name} must be >= 0, got {value!r}")


@dataclass(frozen=True)
class LinearDeltaMasses:
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

    def __post_init__(self) -> None:
        _check(self)

    def with_(self, **changes: float) -> "LinearDeltaMasses":
        return replace(self, **changes)


@dataclass(frozen=True)
class RotaryDeltaMasses:
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

    def __post_init__(self) -> None:
        _check(self)

    def with_(self, **changes: float) -> "RotaryDeltaMasses":
        return replace(self, **changes)
