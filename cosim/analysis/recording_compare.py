"""A run compared with a recording of the robot: ``compare_recording(run, recording, {run_signal: spec})``.

Each run signal is compared at the run's own time stamps with the recorded signal it is mapped to, sampled at the
same instant (linear interpolation between the recording's samples), over the times both cover. The recording's
clock is not the run's: ``offset`` is the recording's time minus the run's (a run sample at t is compared with
the recording at t + offset), given, or estimated by :func:`estimate_offset` (``align``). Units: a recorded unit
is converted to the run signal's unit; a signal recorded without one is taken to be in it (said in ``notes``).
Tolerances are those of ``compare`` (``--tol``, else the ``regression.tolerances`` of the scenario attached to
the run's log), matched against the run signal's name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..errors import CosimError
from ..io.recordings import Recording, read_recording, unit_factor
from ..io.runlog import RunLog, read_run
from ..observers.stats import ErrorStats
from .compare import Comparison, logged_tolerances, tolerance_for

__all__ = ["compare_recording", "compared_traces", "estimate_offset", "Alignment", "Trace", "parse_maps",
           "MAX_GRID"]

_SLACK_S = 1e-9  # stamps are whole ns: a run stamp within 1 ns of the recording's span is inside it

MAX_GRID = 200_000
"""Most points of the common grid the cross-correlation runs on (its step grows to keep within it)."""


@dataclass(frozen=True)
class Alignment:
    """The recording's time minus the run's, s: ``offset``; ``coarse`` the correlation peak on the grid of
    step ``step`` (s); ``correlation`` the normalised correlation at the peak (1: the same shape)."""

    offset: float
    coarse: float
    step: float
    correlation: float


@dataclass(frozen=True)
class Trace:
    """One mapped signal as compared, for drawing it: the run's ``t_run``, ``y_run`` (s, ``unit``); the recording's
    ``t_rec``, ``y_rec`` (its own clock, s; converted to ``unit``); the residual ``e`` = run - recording at the run
    stamps ``t`` (s, run time) that the comparison used."""

    name: str
    spec: str
    unit: str
    t_run: np.ndarray
    y_run: np.ndarray
    t_rec: np.ndarray
    y_rec: np.ndarray
    t: np.ndarray
    e: np.ndarray


def parse_maps(items: Sequence[str]) -> dict[str, str]:
    """``["ctl.q[1]=/joint_states.position[joint1]", ...]`` -> {run signal: recording spec}."""
    out: dict[str, str] = {}
    for item in items:
        run, sep, rec = item.partition("=")
        if not sep or not run.strip() or not rec.strip():
            # Refused (correctness): a mapping we cannot read: which signals pair is a guess
            raise CosimError(f"--map {item!r}: expected RUN_SIGNAL=RECORDING_SIGNAL, e.g. "
                             "plant.q[1]=/joint_states.position[joint1]")
        if run.strip() in out:
            # Refused (correctness): which recorded signal is meant is a guess
            raise CosimError(f"--map: {run.strip()} is mapped twice")
        out[run.strip()] = rec.strip()
    return out


def _grid(t: np.ndarray, y: np.ndarray, t0: float, step: float, n: int) -> np.ndarray:
    return np.interp(t0 + step * np.arange(n), t, y)


def _residual(pairs: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]], offset: float) -> float:
    """Mean over the signals of the mean squared difference run - recording(t + offset) over their overlap, each
    over its run signal's variance (so metres and radians weigh alike)."""
    total = 0.0
    for t_run, y_run, t_rec, y_rec, scale in pairs:
        keep = (t_run + offset >= t_rec[0]) & (t_run + offset <= t_rec[-1])
        if keep.sum() < 2:
            return math.inf
        e = y_run[keep] - np.interp(t_run[keep] + offset, t_rec, y_rec)
        total += float(np.mean(e * e)) / scale
    return total / len(pairs)


def estimate_offset(run: Sequence[tuple[np.ndarray, np.ndarray]], rec: Sequence[tuple[np.ndarray, np.ndarray]],
                    max_offset: float | None = None) -> Alignment:
    """The recording's time minus the run's that best lines the signals up: (t, y) pairs of the run and of the
    recording, in the same order and unit.

    The normalised cross-correlation of the signals (mean removed), summed over the signals, on a common grid of
    the finer sampling step, gives the peak to a step; a parabola through the peak and its neighbours, then a
    bounded scalar minimisation (Brent) of the residual within a step either side, place it below the step.
    ``max_offset`` (s) bounds |offset| (default: half the shorter signal's span)."""
    from scipy.signal import correlate  # lazy: 0.6 s of imports that a comparison without --align never needs
    from scipy.optimize import minimize_scalar  # lazy: 1 s of imports that a report without a recording never needs

    ta0, ta1 = max(t[0] for t, _ in run), min(t[-1] for t, _ in run)
    tb0, tb1 = max(t[0] for t, _ in rec), min(t[-1] for t, _ in rec)
    span_run, span_rec = ta1 - ta0, tb1 - tb0
    if span_run <= 0 or span_rec <= 0:
        # Refused (correctness): no common span: the offset found would be a guess
        raise CosimError("--align: the signals share no time span to correlate (run "
                         f"{ta0:.3f} .. {ta1:.3f} s, recording {tb0:.3f} .. {tb1:.3f} s)")
    steps = [float(np.median(np.diff(t))) for t, _ in (*run, *rec)]
    step = max(min(steps), max(span_run, span_rec) / MAX_GRID)
    limit = 0.5 * min(span_run, span_rec) if max_offset is None else max_offset
    na, nb = int(span_run / step) + 1, int(span_rec / step) + 1
    score = np.zeros(na + nb - 1)
    for (ta, ya), (tb, yb) in zip(run, rec):
        ga = _grid(ta, ya, ta0, step, na)
        gb = _grid(tb, yb, tb0, step, nb)
        ga, gb = ga - ga.mean(), gb - gb.mean()
        # c[j] = sum_k gb[k + m] ga[k], m = j - (na - 1): the recording at tb0 + (k + m) step against the run at
        # ta0 + k step, an offset of tb0 - ta0 + m step; divided by both signals' energies over that overlap
        c = correlate(gb, ga, mode="full", method="auto")
        ea = correlate(np.ones(nb), ga * ga, mode="full", method="auto")
        eb = correlate(gb * gb, np.ones(na), mode="full", method="auto")
        with np.errstate(invalid="ignore", divide="ignore"):
            r = c / np.sqrt(np.clip(ea, 0, None) * np.clip(eb, 0, None))
        r[~np.isfinite(r)] = 0.0
        score += r
    lags = tb0 - ta0 + (np.arange(na + nb - 1) - (na - 1)) * step
    allowed = np.abs(lags) <= limit
    if not allowed.any():
        # Refused (correctness): no offset to try: the alignment would be a guess
        raise CosimError(f"--align: no offset within {limit:g} s to try (run span {span_run:.3f} s, recording "
                         f"{span_rec:.3f} s)")
    score = np.where(allowed, score / len(run), -np.inf)
    m = int(np.argmax(score))
    coarse = float(lags[m])
    if 0 < m < len(score) - 1 and np.isfinite(score[m - 1]) and np.isfinite(score[m + 1]):
        a, b, c0 = score[m - 1], score[m], score[m + 1]
        denom = a - 2 * b + c0
        coarse += float(0.5 * (a - c0) / denom * step) if denom < 0 else 0.0
    pairs = [(ta, ya, tb, yb, max(float(np.var(ya)), 1e-300)) for (ta, ya), (tb, yb) in zip(run, rec)]
    best = minimize_scalar(lambda x: _residual(pairs, x), bounds=(coarse - step, coarse + step), method="bounded",
                           options={"xatol": step * 1e-6})
    offset = float(best.x) if best.success and best.fun <= _residual(pairs, coarse) else coarse
    return Alignment(round(offset, 12), float(lags[m]), step, float(score[m]))  # below 1 ps: rounding noise


def _read(recording: str | Path, maps: Mapping[str, str], run: RunLog, units: Mapping[str, str], time: str,
          time_origin: str) -> tuple[Recording, list[str]]:
    """The recording's mapped signals, named by their run signal, each in its run signal's unit."""
    notes = []
    rec = read_recording(recording, maps, time=time, time_origin=time_origin, units=dict(units))
    for name in maps:
        want = run.signal(name).unit
        have = rec.units[name]
        if have and want:
            rec.values[name] = rec.values[name] * unit_factor(have, want, f"{recording}: {maps[name]} -> {name}")
        elif want:
            notes.append(f"{maps[name]} has no unit: taken as {name}'s {want} (give --unit {name}=UNIT)")
        rec.units[name] = want or have
    return rec, notes


def compare_recording(run: RunLog | str | Path, recording: str | Path, maps: Mapping[str, str], *,
                      tolerances: Mapping[str, float] | None = None, units: Mapping[str, str] | None = None,
                      time: str = "header", time_origin: str = "first", align: bool = False,
                      offset: float = 0.0, max_offset: float | None = None) -> Comparison:
    """Compare the run's signals with the recorded ones they are mapped to (see the module docstring).

    ``maps``: run signal -> recording spec; ``units``: run signal -> the recording's unit where the recording
    has none (or to override it); ``offset``: the recording's time minus the run's, s, used as given unless
    ``align`` estimates it (``max_offset`` bounds the search). The result's ``offset`` and ``notes`` say which."""
    return compared_traces(run, recording, maps, tolerances=tolerances, units=units, time=time,
                           time_origin=time_origin, align=align, offset=offset, max_offset=max_offset)[0]


def compared_traces(run: RunLog | str | Path, recording: str | Path, maps: Mapping[str, str], *,
                    tolerances: Mapping[str, float] | None = None, units: Mapping[str, str] | None = None,
                    time: str = "header", time_origin: str = "first", align: bool = False,
                    offset: float = 0.0, max_offset: float | None = None) -> tuple[Comparison, list[Trace]]:
    """:func:`compare_recording`'s comparison, and each mapped signal's :class:`Trace` (what a figure draws)."""
    run = run if isinstance(run, RunLog) else read_run(run)
    if not maps:
        # Refused (correctness): no signal paired: a pass would say nothing
        raise CosimError("compare with a recording needs --map RUN_SIGNAL=RECORDING_SIGNAL (one per signal)")
    for name in maps:
        run.signal(name)  # an unknown run signal: one line with the closest names
    tol = dict(tolerances or {}) or {k: v for k, v in logged_tolerances(run).items()}
    rec, notes = _read(recording, maps, run, units or {}, time, time_origin)
    if rec.end_note:
        notes.append(f"warning: {rec.end_note}")
    pairs_run = [(run.signal(n).t, np.asarray(run.signal(n).y, dtype=float)) for n in maps]
    pairs_rec = [(rec.times[n], rec.values[n]) for n in maps]
    how = "given"
    if align:
        found = estimate_offset(pairs_run, pairs_rec, max_offset)
        offset, how = found.offset, (f"estimated: correlation peak {found.coarse:.6g} s on a {found.step:.3g} s "
                                     f"grid (r = {found.correlation:.4f}), refined below the step")
    diffs, traces, lo, hi = [], [], math.inf, -math.inf
    for (name, spec), (t_run, y_run) in zip(maps.items(), pairs_run):
        t_rec = rec.times[name]
        keep = (t_run + offset >= t_rec[0] - _SLACK_S) & (t_run + offset <= t_rec[-1] + _SLACK_S)
        if not keep.any():
            # Refused (correctness): past the recording's ends the compared values would be made up
            raise CosimError(f"{name}: the run covers t = {t_run[0]:.3f} .. {t_run[-1]:.3f} s and {recording}'s "
                             f"{spec} {t_rec[0]:.3f} .. {t_rec[-1]:.3f} s (offset {offset:.6g} s): no overlap; "
                             "try --align, --time-origin or --time")
        t = t_run[keep]
        e = y_run[keep] - rec.sample(name, t + offset)
        lo, hi = min(lo, float(t[0])), max(hi, float(t[-1]))
        diffs.append(ErrorStats.of(e, t, name=name, actual=name, reference=spec, unit=rec.units[name],
                                   tolerance=tolerance_for(name, tol)))
        traces.append(Trace(name, spec, rec.units[name], t_run, y_run, t_rec, rec.values[name], t, e))
    cmp = Comparison(str(run.path), str(recording), diffs, lo, hi)
    cmp.offset, cmp.offset_how, cmp.notes = offset, how, notes
    return cmp, traces
