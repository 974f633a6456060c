"""Pure domain core of the delta co-simulation platform.

Geometry presets, kinematics, workspace, singularities (and, as they land,
analytic dynamics, trajectories and control laws). numpy/scipy only: no I/O,
no FMI, no Exudyn.
"""

from .errors import CosimError, ParameterError, RobotError, UnreachableError
from .robots import PRESETS, LinearDelta, Robot, RotaryDelta, get_preset

__all__ = [
    "CosimError",
    "ParameterError",
    "RobotError",
    "UnreachableError",
    "PRESETS",
    "LinearDelta",
    "Robot",
    "RotaryDelta",
    "get_preset",
]
