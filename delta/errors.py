"""The robot core's errors: one root, :class:`DeltaError`; every subclass also inherits the builtin that matches
its meaning so callers can catch either.

The core knows nothing of the co-simulation master (it runs inside our FMUs too, where the master is not
installed). The master shows these errors as one line, as its own (:class:`cosim.errors.CosimError`): the robot
layer (:mod:`cosim.robot`) registers :class:`DeltaError` as a domain error root with it.
"""

from __future__ import annotations

__all__ = ["DeltaError", "RobotError", "UnreachableError", "ParameterError"]


class DeltaError(Exception):
    """Root of every error raised by the robot's packages (``delta``, ``fmus``, ``multibody``).
    ``exit_kind``: what a command calls it when it ends on it (``"error"``); ``name``: the one parameter it is about,
    as its message names it (None: not one parameter), so that a caller can place it where that was given."""

    exit_kind = "error"
    name: str | None = None

    def __init__(self, *args: object, name: str | None = None) -> None:
        super().__init__(*args)
        self.name = name


class RobotError(DeltaError, ValueError):
    """A robot description or a kinematic query is invalid."""


class UnreachableError(RobotError):
    """A pose or trajectory leaves the workspace; the message says why."""

    exit_kind = "unreachable"


class ParameterError(DeltaError, ValueError):
    """A model, controller or trajectory parameter is out of its valid range."""
