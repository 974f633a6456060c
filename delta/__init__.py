"""Pure domain core of the delta co-simulation platform.

Geometry presets (:mod:`delta.robots`) and masses (:mod:`delta.masses`) compile into an
immutable :class:`~delta.model.Model` with a scratch :class:`~delta.model.Data`; free functions
over them give the kinematics (:mod:`delta.kinematics`) and the analytic dynamics
(:mod:`delta.dynamics`); the only per-kind code is the actuator path (:mod:`delta.actuators`).
Singularities, workspace, trajectories and control laws build on them. numpy/scipy only: no
I/O, no FMI, no Exudyn. Importing the package itself loads no numpy (the CLI's errors come from
:mod:`delta.errors`).
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
