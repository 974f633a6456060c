"""Mass parameters of the delta robots, SI units, and their lumping.

One set per robot kind, shared by the analytic model (:mod:`delta.model`) and the multibody plants, so that
both describe the same machine. :func:`lumps` is the one place the rods' masses are split between the platform
and the actuators (thesis eqs. (28)-(29)); the analytic model, the actuators' inertia and weight
(:mod:`delta.actuators`) and the Exudyn plants' bodies (:mod:`multibody`) all take their masses from it.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any, Mapping

from .errors import ParameterError
from .numbers import SCALAR

__all__ = ["GRAVITY", "LinearDeltaMasses", "RotaryDeltaMasses", "Masses", "Lumps", "lumps"]

GRAVITY = 9.81
"""Standard gravity used by default, m/s^2 (acts along -z)."""


def validate(masses, xp=SCALAR, names: Mapping[str, str] | None = None) -> None:  # noqa: ANN001
    """Lumping shares in [0, 1], every other mass parameter >= 0. On symbols (``fmus.native``: ``masses`` is a
    namespace of symbols) the conditions are recorded for the generated code (see :data:`delta.numbers.SCALAR`).
    ``names``: how the messages name each field (an FMU's parameter, ``mass.payload``); by default
    ``<class>.<field>`` (``masses.<field>`` on symbols)."""
    prefix = "masses" if xp.symbolic else type(masses).__name__
    items = vars(masses).items() if xp.symbolic else ((f.name, getattr(masses, f.name)) for f in fields(masses))
    for field, value in items:
        label = names[field] if names is not None and field in names else f"{prefix}.{field}"
        if field.startswith("w_"):
            if not xp.check(xp.both(0.0 <= value, value <= 1.0), f"{label} must be in [0, 1]"):
                raise ParameterError(f"{label} must be in [0, 1], got {value!r}", name=label)
        elif (xp.symbolic or isinstance(value, float)) and not xp.check(value >= 0.0, f"{label} must be >= 0"):
            raise ParameterError(f"{label} must be >= 0, got {value!r}", name=label)


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


ACTUATOR_POINT = {"linear": "carriage", "rotary": "elbow"}
"""Robot kind -> the mass field of the point where its rods meet the actuator (``B_i``): the carriage of a
linear delta, the elbow hardware at the end of a rotary delta's arm."""


@dataclass(frozen=True)
class Lumps:
    """The masses of one robot as point masses, kg (made by :func:`lumps`, which gives the formulas).

    Attributes
    ----------
    platform_alone : the platform and its payload, without any share of the rods (the full plants' platform
        body: their rods are bodies of their own).
    platform_inertial, platform_weight_mass : the platform lump ``m_p`` of the inertial terms and of the weight.
    actuator_alone : the carriage (linear) or the elbow hardware (rotary) alone, at ``B_i`` (the full plants').
    actuator_inertial, actuator_weight_mass : the lump at ``B_i`` of the inertial terms and of the weight.
    rod_inertia : ``mu``, each leg's two rods' rotational inertia as a (negative) point mass moving with the rod
        vector (:mod:`delta.dynamics`); 0 in the thesis's lumping.

    The fields are numbers, or symbols when the masses are (``fmus.native`` traces the model to C).
    """

    platform_alone: Any
    platform_inertial: Any
    platform_weight_mass: Any
    actuator_alone: Any
    actuator_inertial: Any
    actuator_weight_mass: Any
    rod_inertia: Any


def lumps(masses: Any, kind: str) -> Lumps:
    """The lumping of ``masses`` for a robot of ``kind`` (``"linear"`` or ``"rotary"``): each rod's mass is split,
    a share ``w`` to the platform and ``1 - w`` to the actuator point ``B_i`` (the carriage, or the elbow), with
    ``w = w_inertia`` for the inertial terms and ``w = w_gravity`` for the weight:

    * platform, thesis eq. (28): ``m_p = platform + payload + 6 w rod`` (three legs of two rods);
    * actuator point, thesis eq. (29) (Codourey's lumping for the rotary delta, at the elbow):
      ``carriage + 2 (1 - w) rod``, or ``elbow + 2 (1 - w) rod``;
    * the rods' rotation (``w_rotation``, :mod:`delta.dynamics`): ``mu = -w_rotation rod / 3``.

    ``masses`` is a mass dataclass or any object with its fields (symbols for ``fmus.native``): the formulas only
    add and multiply, so they serve every number type. The actuators (:meth:`delta.actuators.Rail.inertia`, ...)
    add the arm of a rotary delta to the elbow's lump."""
    try:
        at_actuator = getattr(masses, ACTUATOR_POINT[kind])
    except KeyError:
        raise ParameterError(f"unknown robot kind {kind!r}; valid kinds: {', '.join(ACTUATOR_POINT)}") from None
    platform, rod = masses.platform + masses.payload, masses.rod
    w_inertia, w_gravity = masses.w_inertia, masses.w_gravity
    return Lumps(
        platform_alone=platform,
        platform_inertial=platform + 6.0 * w_inertia * rod,
        platform_weight_mass=platform + 6.0 * w_gravity * rod,
        actuator_alone=at_actuator,
        actuator_inertial=at_actuator + 2.0 * (1.0 - w_inertia) * rod,
        actuator_weight_mass=at_actuator + 2.0 * (1.0 - w_gravity) * rod,
        rod_inertia=-masses.w_rotation * rod / 3.0,
    )
