"""Pure domain core of the delta co-simulation platform.

Geometry presets (:mod:`delta.robots`) and masses (:mod:`delta.masses`) compile into an
immutable :class:`~delta.model.Model` with a scratch :class:`~delta.model.Data`; free functions
over them give the kinematics (:mod:`delta.kinematics`) and the analytic dynamics
(:mod:`delta.dynamics`); the only per-kind code is the actuator path (:mod:`delta.actuators`).
Singularities, workspace, trajectories and control laws build on them. numpy/scipy only: no
I/O, no FMI, no Exudyn. Importing the package itself loads no numpy (the CLI's errors come from
:mod:`delta.errors`).
"""

from importlib import import_module

from .errors import DeltaError, ParameterError, RobotError, UnreachableError

_ROBOTS = ("PRESETS", "LinearDelta", "Robot", "RotaryDelta", "get_preset")

__all__ = [
    "DeltaError",
    "ParameterError",
    "RobotError",
    "UnreachableError",
    "PRESETS",
    "LinearDelta",
    "Robot",
    "RotaryDelta",
    "get_preset",
]


def __getattr__(name: str):
    """The robot names from :mod:`delta.robots`, imported on first use (it loads numpy; this package must not:
    the log's writer process and ``--help`` import :mod:`delta.errors` through it)."""
    if name in _ROBOTS:
        return getattr(import_module(".robots", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
