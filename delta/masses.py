"""Mass parameters of the delta robots, SI units.

One set per robot kind, shared by the analytic model (:mod:`delta.model`, lumped as in
thesis eqs. (28)-(29)) and the multibody plants, so that both describe the same machine.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

from .errors import ParameterError
from .numbers import SCALAR

__all__ = ["GRAVITY", "LinearDeltaMasses", "RotaryDeltaMasses", "Masses"]

GRAVITY = 9.81
"""Standard gravity used by default, m/s^2 (acts along -z)."""


def validate(masses, xp=SCALAR) -> None:  # noqa: ANN001
    """Lumping shares in [0, 1], every other mass parameter >= 0. On symbols (``fmus.native``: ``masses`` is a
    namespace of symbols) the conditions are recorded for the generated code (see :data:`delta.numbers.SCALAR`)."""
    name = "masses" if xp.symbolic else type(masses).__name__
    items = vars(masses).items() if xp.symbolic else ((f.name, getattr(masses, f.name)) for f in fields(masses))
    for field, value in items:
        if field.startswith("w_"):
            if not xp.check(xp.both(0.0 <= value, value <= 1.0), f"{name}.{field} must be in [0, 1]"):
                raise ParameterError(f"{name}.{field} must be in [0, 1], got {value!r}")
        elif (xp.symbolic or isinstance(value, float)) and not xp.check(value >= 0.0, f"{name}.{field} must be >= 0"):
            raise ParameterError(f"{name}.{field} must be >= 0, got {value!r}")


@dataclass(frozen=True)
class _Masses:
    """The parameters both kinds share, their validation and copy-with-changes.

    Attributes
    ----------
    rod : float
        Mass of one parallelogram rod (forearm rod of a rotary delta), kg (thesis ``m_l``); each leg has two.
    rod_radius : float
        Rod radius for the multibody plant's rod inertia, m.
    parallelogram_width : float
        Distance between the two rods of a leg, m (multibody plant only).
    platform : float
        Platform mass without payload, kg (thesis ``m_p``).
    payload : float
        Payload carried by the platform, kg.
    w_inertia, w_gravity : float
        Leg mass distribution factor ``w`` (share of each rod lumped at the platform, the rest at the
        carriage or elbow) used for the inertial and the gravity terms; the thesis uses one ``w`` for
        both (default 2/3). ``w_gravity = 1/2`` is exact for the weight of uniform rods.
    w_rotation : float
        Share of the rods' own rotational inertia in the analytic model (:mod:`delta.dynamics`): 0 (the
        default) lumps the rods as two point masses each, as the thesis does; 1 adds the kinetic energy a
        uniform rod has beyond its two end halves, ``-m_l/12 |v_A - v_B|^2`` per rod, so that with
        ``w_inertia = 1/2`` a uniform rod's kinetic energy is exact.
    gravity : float
        Gravitational acceleration along -z, m/s^2.
    """

    rod: float = 0.1
    rod_radius: float = 0.004
    parallelogram_width: float = 0.06
    platform: float = 0.3
    payload: float = 0.0
    w_inertia: float = 2.0 / 3.0
    w_gravity: float = 2.0 / 3.0
    w_rotation: float = 0.0
    gravity: float = GRAVITY

    def __post_init__(self) -> None:
        validate(self)

    def with_(self, **changes: float):
        """A copy with ``changes`` applied (validated again)."""
        return replace(self, **changes)


@dataclass(frozen=True)
class LinearDeltaMasses(_Masses):
    """Masses of the linear delta (thesis eqs. 28-29), SI units: the shared parameters of ``_Masses``
    with the thesis robot's defaults, and

    carriage : float
        Mass of one carriage (slider), kg (thesis ``m_s``).
    """

    carriage: float = 0.5


@dataclass(frozen=True)
class RotaryDeltaMasses(_Masses):
    """Masses of the rotary delta (Codourey-style lumping), SI units: the shared parameters of
    ``_Masses`` (rods lighter and thicker, a lighter platform) and

    motor_inertia : float
        Rotor (and gearbox) inertia about the motor axis, kg m^2.
    arm : float
        Upper arm mass, kg, uniform along the arm (inertia ``arm * La**2 / 3`` about the axis).
    elbow : float
        Concentrated mass at the elbow (joint hardware), kg.
    """

    rod: float = 0.08
    rod_radius: float = 0.005
    platform: float = 0.25
    motor_inertia: float = 5e-4
    arm: float = 0.4
    elbow: float = 0.05


Masses = LinearDeltaMasses | RotaryDeltaMasses
