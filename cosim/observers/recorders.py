"""Observers that only watch: tracking error statistics (RMSE, max error) and recorded values."""

from __future__ import annotations

import math
import re
from typing import Sequence

from ..engine.execution import Execution
from ..engine.system import Port
from ..fmi import REAL
from .stats import ErrorStats

__all__ = ["ErrorObserver", "PeakEffort", "Probe"]


class ErrorObserver:
    """Accumulates actual - reference at every macro step (after it) and at the start;
    :meth:`result` gives one :class:`~cosim.observers.stats.ErrorStats` per pair."""

    error_sums = True  # its stepped is cosim.engine.cloop.ErrorSums: a loop in C sums for it

    def __init__(self, actual: list[str], reference: list[str]):
        self.actual = actual
        self.reference = reference

    def start(self, rt: Execution) -> None:
        self.pairs = []
        self.units = []
        for a, r in zip(self.actual, self.reference):
            pa, pr = rt.plan.port(a), rt.plan.port(r)
            self.pairs.append((rt.where(pa), rt.where(pr)))
            self.units.append(pa.var.unit or pr.var.unit or "")
        n = len(self.pairs)
        self.sq = [0.0] * n
        self.mx = [0.0] * n
        self.t_mx = [rt.now_ns] * n
        self.n = 0
        self.stepped(-1, rt.now_ns, ())

    def stepped(self, k: int, t_ns: int, active: Sequence[int]) -> None:
        sq, mx = self.sq, self.mx
        for j, ((av, ai), (rv, ri)) in enumerate(self.pairs):
            e = av[ai] - rv[ri]
            sq[j] += e * e
            if abs(e) > mx[j]:
                mx[j] = abs(e)
                self.t_mx[j] = t_ns
        self.n += 1

    def finish(self, rt: Execution, error: BaseException | None) -> None:
        return None

    def result(self) -> list[ErrorStats]:
        """Per pair, named by its actual signal."""
        return [ErrorStats(name=a, actual=a, reference=r, unit=u, rmse=math.sqrt(s / self.n) if self.n else math.nan,
                           max_error=m, t_max=t * 1e-9, samples=self.n)
                for a, r, s, m, t, u in zip(self.actual, self.reference, self.sq, self.mx, self.t_mx, self.units)]


class Probe:
    """Keeps every value of the given signals in memory (tests, small runs)."""

    def __init__(self, signals: list[str]):
        self.signals = signals
        self.t_ns: list[int] = []
        self.values: dict[str, list[float]] = {s: [] for s in signals}

    def start(self, rt: Execution) -> None:
        self._src = []
        for s in self.signals:
            self._src.append(rt.where(rt.plan.port(s)))
        self.stepped(-1, rt.now_ns, ())

    def stepped(self, k: int, t_ns: int, active: Sequence[int]) -> None:
        self.t_ns.append(t_ns)
        for s, (arr, i) in zip(self.signals, self._src):
            self.values[s].append(arr[i])

    def finish(self, rt: Execution, error: BaseException | None) -> None:
        return None


_EFFORT = re.compile(r"^u(\[\d+\])?$")  # actuator effort u[i] (conventions), N or N*m


class PeakEffort:
    """Observer: the largest |u[i]| of every component output named ``u`` or ``u[i]``."""

    def __init__(self) -> None:
        self.peak = math.nan

    def start(self, rt: Execution) -> None:
        self._src = []
        for c, outs in enumerate(rt.plan.outputs):
            for var in outs:
                if _EFFORT.match(var.name) and var.kind == REAL:
                    arr, i = rt.where(Port(c, var))
                    self._src += [(arr, i + e) for e in range(var.count)]
        self.peak = 0.0 if self._src else math.nan
        self.stepped(-1, rt.now_ns, ())

    def stepped(self, k: int, t_ns: int, active: Sequence[int]) -> None:
        for arr, i in self._src:
            v = abs(arr[i])
            self.peak = max(self.peak, v)

    def finish(self, rt: Execution, error: BaseException | None) -> None:
        return None
