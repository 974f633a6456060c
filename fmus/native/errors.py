"""Errors of the native build."""

from __future__ import annotations

from delta.errors import DeltaError

__all__ = ["NativeError", "CompilerMissingError"]


class NativeError(DeltaError, RuntimeError):
    """A native FMU could not be generated or compiled; the message names the FMU and the cause."""


class CompilerMissingError(NativeError):
    """No C compiler: the native build needs one (the python build keeps working)."""
