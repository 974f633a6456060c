"""Geometry of the delta robots in the seed papers, as frozen dataclasses in SI units.

Millimetres and degrees from the papers are converted once, here.

Frames (see ``docs/conventions``): base frame at the centre of the fixed base,
z up, gravity -z; the platform hangs below the base.

* Linear delta: vertical rails at planar radius ``rail_radius`` and angles
  ``leg_angles``; ``q[i]`` is the carriage travel *downward* from the top of
  the rail (the carriage joint is at ``z = -q[i]``).
* Rotary delta: motor ``i`` at angle ``leg_angles[i]`` (leg 1 lies on the +x
  axis), its axis tangent to the base circle at ``base_radius``; ``q[i]`` is the
  arm angle, 0 = arm horizontal pointing outward, positive = arm down.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from math import pi, radians, sqrt
from typing import Mapping

from .errors import RobotError
from .numbers import SCALAR

__all__ = [
    "LinearDelta",
    "RotaryDelta",
    "Robot",
    "PRESETS",
    "get_preset",
    "linear_delta_thesis",
    "rotary_delta_prototype",
    "rotary_delta_3rrr",
]

MM = 1e-3
_DEFAULT_ANGLES = (0.0, 2.0 * pi / 3.0, 4.0 * pi / 3.0)


def validate(robot: "LinearDelta | RotaryDelta", xp=SCALAR,
             names: Mapping[str, str] | None = None) -> None:  # noqa: ANN001
    """Lengths positive, three leg angles, a non-empty joint range; the error names the robot. On symbols
    (``fmus.native``) the conditions are recorded for the generated code (see :data:`delta.actuators.SCALAR`).
    ``names``: how the messages name each field (an FMU's parameter, ``geometry.rod_length``), instead of the
    robot and the field."""
    where = f"{type(robot).__name__} {robot.name!r}" if not xp.symbolic else "geometry"

    def label(field: str) -> str:
        return names[field] if names is not None and field in names else f"{where}: {field}"

    for name in LENGTHS[robot.kind]:
        value = getattr(robot, name)
        if not xp.check(value > 0.0, f"{label(name)} must be > 0"):
            raise RobotError(f"{label(name)} must be > 0, got {value!r}", name=label(name))
    if len(robot.leg_angles) != 3:
        raise RobotError(f"{where}: leg_angles needs 3 angles, got {len(robot.leg_angles)}")
    lo, hi = (names["q_min"], names["q_max"]) if names is not None and "q_min" in names else (label("q_min"), "q_max")
    if not xp.check(robot.q_min < robot.q_max, f"{lo} must be < {hi}"):
        raise RobotError(f"{lo} {robot.q_min} must be < {hi} {robot.q_max}", name=lo)


LENGTHS = {"linear": ("rail_radius", "platform_radius", "rod_length"),
           "rotary": ("base_radius", "arm_length", "forearm_length", "platform_radius")}
"""The lengths of each robot kind that must be positive."""


@dataclass(frozen=True)
class LinearDelta:
    """Linear (prismatic-input) delta robot with vertical rails.

    Attributes
    ----------
    rail_radius : float
        Planar distance from the base centre to each rail, m (thesis ``U_A``).
    platform_radius : float
        Planar distance from the platform centre to each platform joint, m (``u_b``).
    rod_length : float
        Length of the parallelogram rods, m (``l``).
    leg_angles : tuple of 3 float
        Angle of each rail about +z from +x, rad.
    q_min, q_max : float
        Carriage stroke limits (travel downward from the rail top), m.
    """

    name: str
    rail_radius: float
    platform_radius: float
    rod_length: float
    leg_angles: tuple[float, float, float]
    q_min: float
    q_max: float
    kind: str = "linear"

    def __post_init__(self) -> None:
        validate(self)

    @property
    def q_unit(self) -> str:
        return "m"

    def as_dict(self) -> dict[str, object]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class RotaryDelta:
    """Rotary (Clavel) delta robot.

    Attributes
    ----------
    base_radius : float
        Distance from the base centre to each motor axis, m (seed 004 ``OF``, seed 003 ``Ra``).
    arm_length : float
        Upper arm length, m (``rf``, ``La``).
    forearm_length : float
        Parallelogram forearm length, m (``re``, ``Lb``).
    platform_radius : float
        Distance from the platform centre to each forearm joint, m (``OE``, ``Rb``).
    leg_angles : tuple of 3 float
        Angle of each motor about +z from +x, rad; leg 1 lies on +x.
    q_min, q_max : float
        Arm angle limits, rad (0 = horizontal, positive = down).
    """

    name: str
    base_radius: float
    arm_length: float
    forearm_length: float
    platform_radius: float
    leg_angles: tuple[float, float, float]
    q_min: float
    q_max: float
    kind: str = "rotary"

    def __post_init__(self) -> None:
        validate(self)

    @property
    def q_unit(self) -> str:
        return "rad"

    @property
    def home_z(self) -> float:
        """Platform height with all arms horizontal (q = 0), m."""
        reach = self.base_radius + self.arm_length - self.platform_radius
        return -sqrt(self.forearm_length**2 - reach**2)

    def as_dict(self) -> dict[str, object]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


Robot = LinearDelta | RotaryDelta

# Thesis (seed 000) Table 1: U_A = 280 mm, u_b = 98 mm, l = 365 mm, L_min/L_max = 70/580 mm.
# Rails at 210, 330 and 90 degrees reproduce the thesis's inverse-kinematics Table 4.
linear_delta_thesis = LinearDelta(
    name="linear_delta_thesis",
    rail_radius=280.0 * MM,
    platform_radius=98.0 * MM,
    rod_length=365.0 * MM,
    leg_angles=(radians(210.0), radians(330.0), radians(90.0)),
    q_min=70.0 * MM,
    q_max=580.0 * MM,
)

# Seed 004 Table 2: rf 200, re 500, f 554.26, e 259.81 mm; OF = f / (2 sqrt 3) = 160 mm,
# OE = e / (2 sqrt 3) = 75 mm; joint limits -85..110 degrees (Table 7).
rotary_delta_prototype = RotaryDelta(
    name="rotary_delta_prototype",
    base_radius=554.26 / (2.0 * sqrt(3.0)) * MM,
    arm_length=200.0 * MM,
    forearm_length=500.0 * MM,
    platform_radius=259.81 / (2.0 * sqrt(3.0)) * MM,
    leg_angles=_DEFAULT_ANGLES,
    q_min=radians(-85.0),
    q_max=radians(110.0),
)

# Seed 003 Table 1: Ra 67, La 80, Lb 160, Rb 17 mm. The paper gives no joint limits;
# +-90 degrees keeps the arm from folding through the base plane.
rotary_delta_3rrr = RotaryDelta(
    name="rotary_delta_3rrr",
    base_radius=67.0 * MM,
    arm_length=80.0 * MM,
    forearm_length=160.0 * MM,
    platform_radius=17.0 * MM,
    leg_angles=_DEFAULT_ANGLES,
    q_min=radians(-90.0),
    q_max=radians(90.0),
)

PRESETS: dict[str, Robot] = {
    r.name: r for r in (linear_delta_thesis, rotary_delta_prototype, rotary_delta_3rrr)
}


def get_preset(name: str) -> Robot:
    """Return the preset called ``name``; the error lists the valid names."""
    try:
        return PRESETS[name]
    except KeyError:
        raise RobotError(f"unknown robot preset {name!r}; valid presets: {', '.join(PRESETS)}") from None
