"""The one error of a recording that cannot be read as asked: one line naming the file, the signal and what was
wrong (a ``CosimError``, so a command prints it as one line and exits 2)."""

from __future__ import annotations

from ...errors import CosimError

__all__ = ["RecordingError"]


class RecordingError(CosimError, ValueError):
    """A recording that cannot be read as asked: unknown topic, field or joint, no messages in range,
    non-monotonic time, NaN, units that do not convert, or a cut file with nothing readable."""
