"""The errors of the Exudyn plants (rooted in :class:`delta.errors.DeltaError`, each also its builtin)."""

from __future__ import annotations

from delta.errors import DeltaError

__all__ = ["PlantError", "RobotTypeError"]


class PlantError(DeltaError, RuntimeError):
    """A plant could not be stepped (wrong time, solver failure); the message names the time."""


class RobotTypeError(DeltaError, TypeError):
    """A plant was asked for a robot of a kind it does not model."""
