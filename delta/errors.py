"""Error hierarchy shared by the whole platform.

One root, :class:`CosimError`; every subclass also inherits the builtin that
matches its meaning so callers can catch either.
"""

from __future__ import annotations

__all__ = ["CosimError", "RobotError", "UnreachableError", "ParameterError"]


class CosimError(Exception):
    """Root of every error raised by this project."""


class RobotError(CosimError, ValueError):
    """A robot description or a kinematic query is invalid."""


class UnreachableError(RobotError):
    """A pose or trajectory leaves the workspace; the message says why."""


class ParameterError(CosimError, ValueError):
    """A model, controller or trajectory parameter is out of its valid range."""
