"""Error hierarchy shared by the whole platform, and how outside text is shown in a message (:func:`printable`).

One root, :class:`CosimError`; every subclass also inherits the builtin that
matches its meaning so callers can catch either.
"""

from __future__ import annotations

import re

__all__ = ["CosimError", "RobotError", "UnreachableError", "ParameterError", "printable"]


class CosimError(Exception):
    """Root of every error raised by this project."""


class RobotError(CosimError, ValueError):
    """A robot description or a kinematic query is invalid."""


class UnreachableError(RobotError):
    """A pose or trajectory leaves the workspace; the message says why."""


class ParameterError(CosimError, ValueError):
    """A model, controller or trajectory parameter is out of its valid range."""


_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")


def printable(text: str) -> str:
    """Text from outside (an FMU's log, a name or description in its modelDescription.xml) as it may reach a
    terminal or a log: control characters (escape sequences that clear the screen or retitle the window, line
    breaks that fake a traceback) written as their escapes (``\\x1b``, ``\\n``), tabs as spaces."""
    return _CONTROL.sub(lambda m: " " if m.group() == "\t" else repr(m.group())[1:-1], text)
