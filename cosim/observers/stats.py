"""One record for the difference of two signals: what a run's error observer accumulates
(:class:`cosim.observers.recorders.ErrorObserver`), what a report computes from the log
(:mod:`cosim.analysis.report`) and what ``compare`` finds between two logs (:mod:`cosim.analysis.compare`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

__all__ = ["ErrorStats"]


@dataclass(frozen=True, kw_only=True)
class ErrorStats:
    """Statistics of ``actual - reference`` over ``samples`` time stamps, in ``unit``.

    ``name`` says what was compared: an axis (``x``), a signal (``plant.p.x``) or the actual
    signal of a pair; ``actual`` and ``reference`` name the two sides when they are signals
    (empty when the sides are two logs, A and B). ``max_error`` is the largest
    |actual - reference| and ``t_max`` (s) when it occurs; ``tolerance`` bounds ``max_error``
    (None: not checked).
    """

    name: str
    actual: str = ""
    reference: str = ""
    unit: str = ""
    rmse: float
    max_error: float
    t_max: float = math.nan
    samples: int
    tolerance: float | None = None

    @classmethod
    def of(cls, e: Any, t: Any, **fields: Any) -> "ErrorStats":
        """The statistics of the differences ``e`` (n,) at times ``t`` (n,), s; ``fields`` name the rest.
        No sample: NaN statistics."""

        e = np.asarray(e, dtype=float)
        if not len(e):
            return cls(rmse=math.nan, max_error=math.nan, t_max=math.nan, samples=0, **fields)
        absd = np.abs(e)
        k = int(np.argmax(absd))
        return cls(rmse=float(np.sqrt(np.mean(e * e))), max_error=float(absd[k]), t_max=float(t[k]),
                   samples=int(len(e)), **fields)

    @property
    def ok(self) -> bool:
        """True without a tolerance; else ``max_error <= tolerance`` (NaN fails)."""
        return self.tolerance is None or self.max_error <= self.tolerance

    def message(self) -> str:
        """One line: what differs, by how much, when, against which tolerance."""
        diff = f"{self.actual} - {self.reference}" if self.actual else "A - B"
        tol = "" if self.tolerance is None else f" (tolerance {self.tolerance:.3g} {self.unit})".replace(" )", ")")
        return (f"{self.name}: max |{diff}| = {self.max_error:.4g} {self.unit} at t = {self.t_max:.3f} s, "
                f"RMSE {self.rmse:.4g}{tol}").replace("  ", " ")

    def as_dict(self, *names: str, **keys: str) -> dict[str, Any]:
        """The fields ``names`` (``ok`` among them if wanted; none given: every field and ``ok``), in that
        order, each under its field name or the key ``keys`` gives it (``as_dict("name", "max_error",
        max_error="max_abs")``: the keys a JSON output has always used). Each output names what it
        publishes, so a new field is not published by accident."""
        names = names or (*(f.name for f in fields(self)), "ok")
        return {keys.get(n, n): getattr(self, n) for n in names}
