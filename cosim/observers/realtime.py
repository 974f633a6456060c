"""Real-time pacing: an observer that holds simulated time to the wall clock.

``python -m cosim run SCENARIO --realtime [FACTOR]`` adds a :class:`RealTime` observer. After
each macro step ending at simulated time ``t`` it waits until the wall clock reaches
``wall_0 + (t - t_0) / factor``. The due times are absolute (from the start of the loop), so a
late step (a slow FMU call, a busy machine) is caught up by the next steps running without
waiting: the run does not drift. The objects alive at the start are frozen out of the garbage
collector for the run (``gc.freeze``): its full passes over them would stall a step by tens of
milliseconds. The lag of a step is how far past its due time it ended
(0 when it ended early and waited); the summary gives the achieved factor (simulated over
wall time) and the lag's maximum and 99th percentile. Without ``--realtime`` no observer
waits and runs stay as fast as possible.
"""

from __future__ import annotations

import gc
import math
import time
from collections.abc import Sequence

import numpy as np

from ..engine.execution import Execution
from ..errors import CosimError, shown

__all__ = ["RealTime", "parse_factor"]


def parse_factor(text: str | float | None) -> float:
    """``"1"``, ``"0.5"``, ``"2"`` or None (1) -> factor; CosimError unless finite and > 0."""
    if text is None:
        return 1.0
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise CosimError(f"--realtime: the factor must be a number > 0 (simulated s per wall s), got {shown(repr(text))}")
    return value


class RealTime:
    """Observer pacing the run at ``factor`` simulated seconds per wall second (see the module docstring)."""

    def __init__(self, factor: float = 1.0):
        self.factor = parse_factor(factor)
        self.lags_s = np.empty(0)
        self.achieved = math.nan
        self.wall_s = 0.0

    def start(self, rt: Execution) -> None:
        # Everything alive now (FMUs, their modules, the plan) lives as long as the run: keep it out of
        # the garbage collector's full passes, which otherwise stall a step by 20-50 ms every few seconds
        gc.freeze()
        self._t0 = rt.now_ns
        self._lags = np.zeros(max(1, rt.n_steps - rt.k_done), dtype=np.int64)
        self._n = 0
        self._t_last = rt.now_ns
        self._w0 = time.perf_counter_ns()

    def stepped(self, k: int, t_ns: int, active: Sequence[int]) -> None:
        due = self._w0 + (t_ns - self._t0) / self.factor
        now = time.perf_counter_ns()
        if now < due:
            time.sleep((due - now) * 1e-9)
            now = time.perf_counter_ns()
        if self._n < len(self._lags):
            self._lags[self._n] = max(0, now - due)
            self._n += 1
        self._t_last = t_ns

    def finish(self, rt: Execution | None, error: BaseException | None) -> None:
        gc.unfreeze()
        self.wall_s = (time.perf_counter_ns() - self._w0) * 1e-9
        self.lags_s = self._lags[:self._n] * 1e-9
        sim = (self._t_last - self._t0) * 1e-9
        self.achieved = sim / self.wall_s if self.wall_s > 0 else math.nan

    def figures(self) -> dict[str, float]:
        """factor asked and achieved, lag max and 99th percentile (s), steps paced."""
        lags = self.lags_s
        return {"factor": self.factor, "achieved_factor": self.achieved, "wall_s": self.wall_s,
                "lag_max_s": float(lags.max()) if lags.size else 0.0,
                "lag_p99_s": float(np.percentile(lags, 99)) if lags.size else 0.0, "steps": int(lags.size)}

    def summary(self) -> str:
        f = self.figures()
        return (f"real time: factor {f['achieved_factor']:.4g} achieved ({f['factor']:g} asked), lag max "
                f"{f['lag_max_s'] * 1e3:.3g} ms, 99th percentile {f['lag_p99_s'] * 1e3:.3g} ms over "
                f"{f['steps']} steps")
