"""The time grid: communication points in integer nanoseconds, and the doubles an FMU is given for them.

Communication point ``k`` of ``n`` is ``t_k = start + k (stop - start) / n`` rounded to the nanosecond (``n`` the
number of base steps): the base step ``step_ns`` is ``(stop - start) / n`` rounded to the nanosecond, so a step
that is a whole number of nanoseconds gives ``t_k = start + k step_ns`` exactly, and one that is not (1/30 s)
gives points at most half a nanosecond from ``k`` exact steps, the last one on the stop time.

An FMU gets the double nearest ``t_k`` (:meth:`Grid.time`) and a step size ``h`` (:meth:`Grid.step_size`) chosen
so that the FMU's own ``t + h``, added in double arithmetic, is the double nearest ``t_{k+m}``: the step after
lands on the next point exactly, and the last one on the stop time given to the FMU, never past it (where no
double ``h`` does that, in a step from a point below half the next, ``t + h`` is the double just below:
:func:`step_between`). Computing ``h = m step_ns * 1e-9`` instead misses by an ulp: ``1.9999000000000002 + 1e-4
> 2.0``.

This module is the one place where nanoseconds become the doubles an FMU sees; every algorithm, the model
exchange integration and the offload worker take their times from it.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["Grid", "MAX_TIME_S", "MIN_STEP_ULPS", "NS_PER_S", "grid_error", "resolution_error", "seconds", "step_between"]

NS_PER_S = 1_000_000_000

MAX_TIME_S = 9e9
"""The latest time of a grid, s (285 years): its nanoseconds fit a signed 64-bit integer (9.2e18), as the log's
stamps (the run's wall-clock start, about 1.8e18 ns, added) fit MCAP's unsigned 64-bit ones."""


MIN_STEP_ULPS = 2
"""A step spans at least this many neighbouring doubles at the run's latest time: two grid times round to two
different doubles and ``fmi2DoStep`` never gets ``h = 0`` (a start of 8e9 s with a 1e-7 s step would)."""


def grid_error(start_ns: int, stop_ns: int, step_ns: int) -> str | None:
    """Why ``start_ns .. stop_ns`` cannot be divided into steps of ``step_ns`` (None: it can).

    It can when ``step_ns`` is ``(stop - start) / n`` rounded to the nanosecond for the nearest whole ``n``:
    ``|stop - start - n step_ns| <= n / 2``."""
    if step_ns <= 0:
        return f"the step must be at least 1 ns, got {step_ns} ns"
    span = stop_ns - start_ns
    if span <= 0:
        return f"the stop time ({stop_ns} ns) must be after the start time ({start_ns} ns)"
    n = max(1, round(span / step_ns))
    if 2 * abs(span - n * step_ns) > n:
        return (f"stop - start = {span} ns is not a whole number of steps of {step_ns} ns "
                f"(nor {n} steps of a step rounded to the nanosecond)")
    return resolution_error(start_ns, stop_ns, step_ns)


def resolution_error(start_ns: int, stop_ns: int, step_ns: int) -> str | None:
    """Why steps of ``step_ns`` are too short for the doubles an FMU gets its times in, up to the grid's latest time
    (None: they are not): a step spans at least :data:`MIN_STEP_ULPS` neighbouring doubles there."""
    latest = max(abs(start_ns), abs(stop_ns)) / NS_PER_S
    resolution = math.ulp(latest)
    if step_ns / NS_PER_S < MIN_STEP_ULPS * resolution:
        return (f"a step of {step_ns / NS_PER_S:g} s is below what a double tells apart at t = {seconds(max(start_ns, stop_ns))} s "
                f"({resolution:.3g} s between neighbouring doubles; a step spans at least {MIN_STEP_ULPS} of them): "
                "an FMU would be asked for steps of 0 s; take a longer step or an earlier start")
    return None


def seconds(t_ns: int) -> str:
    """``t_ns`` in seconds, written exactly (``8000000000.0001``, ``0.5``, ``3``)."""
    sign, t_ns = ("-" if t_ns < 0 else ""), abs(t_ns)
    whole, frac = divmod(t_ns, NS_PER_S)
    return sign + (f"{whole}.{frac:09d}".rstrip("0") if frac else str(whole))


def step_between(t: float, t_next: float) -> float:
    """The double ``h`` with ``t + h == t_next`` in double arithmetic (``t < t_next``), or, where no double does
    that, the one whose ``t + h`` is the double just below ``t_next`` (never past it).

    ``t_next - t`` is exact when ``t >= t_next / 2`` (Sterbenz's lemma): every step of a grid after its first
    point, whatever its length. Below that the rounded difference may miss by an ulp, and a neighbour of it hits;
    or no double hits, when ``t`` has a bit below the ulp of ``t_next`` and the sum rounds ties to even away from
    ``t_next`` (``0.007955549943174644 + h`` is never ``0.02486664982952393``). That happens only in a step from a
    point below half the next: from a start time that is not zero, or a multi-rate step from the first points."""
    h = t_next - t
    below = None
    for _ in range(4):
        s = t + h
        if s == t_next:
            return h
        if s < t_next:
            below = h if below is None or h > below else below
        h = math.nextafter(h, math.inf if s < t_next else -math.inf)
    if below is None:  # every candidate went past: step down until below
        below = h
        while t + below >= t_next:
            below = math.nextafter(below, 0.0)
    return below


class Grid:
    """``n_steps`` base steps from ``start_ns`` to ``stop_ns`` (integer nanoseconds) of ``step_ns`` each (the exact
    step rounded to the nanosecond: see :func:`grid_error`); raises ValueError for a span that is no whole number
    of steps."""

    __slots__ = ("start_ns", "stop_ns", "step_ns", "n_steps", "_uniform")

    def __init__(self, start_ns: int, stop_ns: int, step_ns: int):
        why = grid_error(start_ns, stop_ns, step_ns)
        if why is not None:
            # Refused (correctness): a span that is no whole number of steps: the last step would be cut short
            raise ValueError(why)
        self.start_ns, self.stop_ns, self.step_ns = start_ns, stop_ns, step_ns
        self.n_steps = max(1, round((stop_ns - start_ns) / step_ns))
        self._uniform = stop_ns - start_ns == self.n_steps * step_ns

    def t_ns(self, k: int) -> int:
        """Communication point ``k`` (0 .. n_steps), ns."""
        if self._uniform:
            return self.start_ns + k * self.step_ns
        span, n = self.stop_ns - self.start_ns, self.n_steps
        return self.start_ns + (2 * k * span + n) // (2 * n)  # k span / n, rounded (halves up)

    def index(self, t_ns: int) -> int:
        """The last communication point at or before ``t_ns`` (0 .. n_steps)."""
        k = min(self.n_steps, max(0, (t_ns - self.start_ns) // self.step_ns))
        while k < self.n_steps and self.t_ns(k + 1) <= t_ns:
            k += 1
        while k > 0 and self.t_ns(k) > t_ns:
            k -= 1
        return k

    def time(self, k: int) -> float:
        """The double nearest communication point ``k``, s (an integer true division rounds correctly)."""
        return self.t_ns(k) / NS_PER_S

    def end(self, k: int, m: int = 1) -> int:
        """The point a component with step multiple ``m`` active at base step ``k`` steps to: ``k + m``, or the
        last point when fewer than ``m`` base steps remain."""
        return min(k + m, self.n_steps)

    def chunk(self, k0: int, k1: int) -> tuple[list[float], list[float]]:
        """The doubles of points ``k0 .. k1 - 1`` and the base step size from each (``m = 1``), computed together
        for a run's hot loop: as :meth:`time` and :meth:`step_size` give them, at a few ns a point."""
        times, steps, _ = self.chunk_arrays(k0, k1)
        return times.tolist(), steps.tolist()

    def chunk_arrays(self, k0: int, k1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`chunk` as float64 arrays, with the end of each step, ns (:meth:`t_ns` of ``k0 + 1 .. k1``, int64):
        what the master's loop in C reads, copied into its arrays whole."""
        ks = range(k0, k1 + 1)
        if self.stop_ns < 2**53:  # the ns are exact doubles: the float64 division rounds correctly, as int / int
            ns = (self.start_ns + self.step_ns * np.arange(k0, k1 + 1, dtype=np.int64) if self._uniform
                  else np.array([self.t_ns(k) for k in ks], dtype=np.int64))
            t = ns / float(NS_PER_S)
        else:
            ns = np.array([self.t_ns(k) for k in ks], dtype=np.int64)
            t = np.array([self.time(k) for k in ks])
        h = np.diff(t)
        for i in np.flatnonzero(t[:-1] + h != t[1:]).tolist():
            h[i] = step_between(float(t[i]), float(t[i + 1]))
        return t[:-1], h, ns[1:]

    def step_size(self, k: int, m: int = 1, t: float | None = None) -> float:
        """The step size from point ``k`` (its double ``t``, when known) over ``m`` base steps: lands exactly on the
        double of point :meth:`end`."""
        return step_between(self.time(k) if t is None else t, self.time(self.end(k, m)))
