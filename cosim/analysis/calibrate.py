"""A scenario's parameters fitted to a robot recording: ``calibrate(scenario, recording, maps, fits)``.

The residual is each mapped run signal sampled at the recording's times shifted by the offset (the recording's
time minus the run's, as ``compare`` counts it: the recorded sample at tau meets the run at tau - offset, linear
interpolation between the run's steps) minus the recorded value, over the recorded samples that fall inside the
run at the start values (a fixed set, so the residual keeps its length while the offset moves). Signals of
different units are made comparable by dividing each one's residuals by the spread (standard deviation) of the
recorded signals of its unit (the largest among them, so signals of one unit keep their relative weight): metres
and radians then weigh by how far the robot moved in them. Reported RMS values are per signal, in its unit.

The fit is SciPy's ``least_squares`` (trust region reflective, bounds), ``x_scale="jac"`` (each parameter scaled
by its Jacobian column: a payload in kg, a gain in N/m and an offset in s have no common magnitude), and a
forward-difference Jacobian with ``diff_step`` 1e-3 relative for the scenario's values (a step far above a run's
rounding, its effect on the run still linear) and a tenth of the recording's sampling step for the offset.

Runs: each is the scenario with the values set at their addresses (``--set`` names: ``plant.mass.payload``,
``trajectory.params.rx``; a linked name ``a,b`` sets both to one value), run here with no log
(:func:`cosim.run.run_scenario`, ``log=False``) and a :class:`~cosim.observers.recorders.Probe` keeping the mapped
signals; the FMUs are built once and stay extracted for the whole fit. A run is made only for values of the
scenario's parameters not run before: the offset's Jacobian column, and every evaluation that changes only the
offset, reuse the last run (``runs`` counts the runs made). Why not the sweep's pool for the Jacobian's runs: a
forward-difference Jacobian costs one run per scenario value, which could run side by side, but a fit of one value
and the offset (the payload of docs/recordings.md) has one such run per iteration, nothing to run beside it; and
for two values, two runs of 2 s of helix_ctc_analytic took 0.28-0.59 s here against 0.39-0.44 s on the sweep's
pool of two kept open (0.73-1.47x) and 0.86-1.57 s on one started for them (0.32-0.42x), with other work on the
2-core machine (``python benchmarks/calibration.py --pool``): no gain worth a second way to run a fit's runs.

Standard errors and correlations come from the Jacobian at the solution: cov = (J^T J)^-1 s^2 (through J's singular
values), s^2 the weighted residual's sum of squares over (samples - parameters). They describe the noise's effect
only, with the model taken as right.

Generic: it imports nothing of ``delta``, ``fmus`` or ``multibody``; parameters are scenario values by address.
"""

from __future__ import annotations

import datetime
import difflib
import math
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ..engine.overrides import DOTTED, Overrides, apply_overrides, resolve_name
from ..engine.prepare import locate_fmus
from ..engine.scenario import read_scenario
from ..engine.system import build_plan
from ..engine.wiring import find_variable
from ..errors import CosimError, UnknownSignalError, written_by_rename
from ..fmi import Extractions
from ..io.recordings import read_recording, unit_factor
from ..observers.recorders import Probe
from ..run import run_scenario
from .recording_compare import estimate_offset
from .sweep import prebuild

__all__ = ["Calibration", "CalibrationError", "Fit", "OFFSET", "calibrate", "parse_fits", "write_fitted",
           "offset_component"]

OFFSET = "offset"
"""The fit name of the time offset between the run and the recording (the recording's time minus the run's, s)."""

DIFF_STEP = 1e-3
"""Relative forward-difference step of the scenario's values (see the module docstring)."""


class CalibrationError(CosimError, ValueError):
    """A calibration that cannot be made as asked: a bad --fit, --map or recording against the run (exit 2)."""


@dataclass(frozen=True)
class Fit:
    """One fitted value: the addresses it sets (several for a linked name ``a,b``), its bounds."""

    names: tuple[str, ...]
    low: float = -math.inf
    high: float = math.inf

    @property
    def label(self) -> str:
        return ",".join(self.names)

    @property
    def is_offset(self) -> bool:
        return self.names == (OFFSET,)


def parse_fits(items: Sequence[str]) -> list[Fit]:
    """``["plant.mass.payload=0:1", "offset", "plant.mass.payload,ctl.mass.payload"]`` -> fits (bounds checked)."""
    fits: list[Fit] = []
    seen: set[str] = set()
    for item in items:
        label, sep, bounds = item.partition("=")
        names = tuple(n.strip() for n in label.split(","))
        if not label.strip() or not all(names):
            # Refused (correctness): a fit we cannot read: what is fitted is a guess
            raise CalibrationError(f"--fit {item!r}: expected NAME[=LOW:HIGH] (plant.mass.payload=0:1, offset, "
                                   "a,b=LOW:HIGH for one value set at both)")
        if OFFSET in names and len(names) > 1:
            # Refused (correctness): the offset is no parameter of a component: a link would be dropped
            raise CalibrationError(f"--fit {item!r}: offset is the recording's clock, it cannot be linked to a "
                                   "scenario value")
        low, high = -math.inf, math.inf
        if sep:
            lo, colon, hi = bounds.partition(":")
            try:
                low, high = float(lo) if lo.strip() else -math.inf, float(hi) if hi.strip() else math.inf
            except ValueError:
                colon = ""
            if not colon or math.isnan(low) or math.isnan(high):
                # Refused (correctness): bounds we cannot read: the fit's range would be a guess
                raise CalibrationError(f"--fit {item!r}: bounds are LOW:HIGH, two numbers (either may be empty: "
                                       "unbounded), e.g. plant.mass.payload=0:1")
            if not low < high:
                # Refused (correctness): no value lies between them
                raise CalibrationError(f"--fit {item!r}: the lower bound {low:g} is not below the upper {high:g}")
        twice = seen.intersection(names)
        if twice:
            # Refused (correctness): which bounds are meant is a guess
            raise CalibrationError(f"--fit {item!r}: {', '.join(sorted(twice))} is fitted twice")
        seen.update(names)
        fits.append(Fit(names, low, high))
    if not fits:
        # Refused (correctness): nothing to fit
        raise CalibrationError("calibrate needs at least one --fit NAME[=LOW:HIGH]")
    return fits


@dataclass
class Calibration:
    """What a calibration found. ``parameters``: per fit its label, start, value, standard error, bounds;
    ``correlation``: between the fits (in their order); RMS per mapped run signal, in its unit, at the start
    values and at the fitted ones; ``runs``: the scenario's runs made; ``converged`` and ``message``: SciPy's
    verdict (or the run budget's)."""

    scenario: str
    recording: str
    parameters: list[dict[str, Any]]
    correlation: list[list[float]]
    rms_before: dict[str, float]
    rms_after: dict[str, float]
    units: dict[str, str]
    cost_before: float
    cost_after: float
    samples: int
    runs: int
    evaluations: int
    wall_time: float
    converged: bool
    message: str
    weighting: str
    notes: list[str] = field(default_factory=list)
    run_time: float = 0.0  # s of the wall time in the runs

    @property
    def values(self) -> dict[str, float]:
        """Fitted value by address (a linked fit's at each of its names; the offset under ``offset``)."""
        return {n: p["value"] for p in self.parameters for n in p["names"]}

    def as_dict(self) -> dict[str, Any]:
        return {"scenario": self.scenario, "recording": self.recording, "converged": self.converged,
                "message": self.message, "parameters": self.parameters, "correlation": self.correlation,
                "rms_before": self.rms_before, "rms_after": self.rms_after, "units": self.units,
                "weighted_rms_before": self.cost_before, "weighted_rms_after": self.cost_after,
                "samples": self.samples, "runs": self.runs, "evaluations": self.evaluations,
                "wall_time_s": self.wall_time, "run_time_s": self.run_time, "weighting": self.weighting,
                "notes": self.notes}

    def text(self) -> str:
        width = max(len(p["label"]) for p in self.parameters)
        lines = [f"calibrated {self.scenario} against {self.recording}: "
                 + ("converged" if self.converged else "DID NOT CONVERGE") + f" ({self.message})",
                 f"{'parameter':<{width}}  {'start':>12} {'fitted':>14} {'std error':>10}  bounds"]
        for p in self.parameters:
            se = "-" if p["stderr"] is None or not math.isfinite(p["stderr"]) else f"{p['stderr']:.3g}"
            lines.append(f"{p['label']:<{width}}  {p['start']:>12.6g} {p['value']:>14.9g} {se:>10}  "
                         f"[{p['low']:g}, {p['high']:g}]")
        if len(self.parameters) > 1 and self.correlation:
            lines.append("correlations: " + "; ".join(
                f"{a['label']} ~ {b['label']} {self.correlation[i][j]:+.3f}" for i, a in enumerate(self.parameters)
                for j, b in enumerate(self.parameters) if j > i))
        w = max(len(n) for n in self.rms_before)
        lines.append(f"{'signal':<{w}}  {'unit':<5} {'RMS before':>11} {'RMS after':>11}")
        for name in self.rms_before:
            lines.append(f"{name:<{w}}  {self.units[name]:<5} {self.rms_before[name]:>11.4g} "
                         f"{self.rms_after[name]:>11.4g}")
        lines.append(f"weighted RMS {self.cost_before:.4g} -> {self.cost_after:.4g} over {self.samples} samples "
                     f"({self.weighting}); {self.runs} runs of the scenario, {self.evaluations} evaluations, "
                     f"{self.wall_time:.1f} s ({self.run_time:.1f} s in the runs)")
        lines += self.notes
        return "\n".join(lines)


class _Budget(Exception):
    """The run budget (``max_runs``) is spent."""


class _Runner:
    """The scenario run at given values of its fitted parameters (cached by those values), the mapped run
    signals kept by a probe; every run counted."""

    def __init__(self, scenario: str | Path, sets: Sequence[str], fits: list[Fit], signals: list[str],
                 max_runs: int, on_run: Callable[[int], None] | None):
        self.source = read_scenario(scenario)
        self.sets = apply_overrides(list(sets))
        self.fits, self.signals, self.max_runs, self.on_run = fits, signals, max_runs, on_run
        self.base = self.source.load(self.sets)
        self.fmu_files = prebuild([self.base])  # the sweep's FMU build: once for every run
        self.cache: dict[tuple[float, ...], tuple[np.ndarray, dict[str, np.ndarray]]] = {}
        self.runs = 0
        self.run_time = 0.0
        self.notes: list[str] = []

    def scenario(self, values: Sequence[float]):
        """The scenario with ``values`` (one per fit, in order) at their addresses, after ``--set``."""
        ov = Overrides()
        for path, value in self.sets.items():
            ov.put(path, value, self.sets.origins[path])
        for fit, value in zip(self.fits, values):
            for name in fit.names:
                ov.put((DOTTED, name), float(value), f"--fit {fit.label}")
        return self.source.load(ov)

    def __call__(self, values: Sequence[float]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        key = tuple(float(v) for v in values)
        if key in self.cache:
            return self.cache[key]
        if self.runs >= self.max_runs:
            raise _Budget
        sc = replace(self.scenario(key).structure(), parallel="off")  # serial
        probe = Probe(self.signals)
        t0 = time.perf_counter()
        run_scenario(sc, log=False, progress=False, observers=[probe], read_all=True, fmu_files=self.fmu_files)
        self.run_time += time.perf_counter() - t0
        self.runs += 1
        t = np.asarray(probe.t_ns, dtype=np.int64) * 1e-9
        out = (t, {s: np.asarray(probe.values[s], dtype=float) for s in self.signals})
        if len(self.cache) > 64:  # a fit revisits the last few points only
            self.cache.pop(next(iter(self.cache)))
        self.cache[key] = out
        if self.on_run is not None:
            self.on_run(self.runs)
        return out


def _start_values(runner: _Runner, fits: list[Fit]) -> tuple[list[float], dict[str, str]]:
    """Each scenario fit's start (the scenario's value after --set, else its FMU's start value) and the run
    signals' units; an unknown fit name or run signal is one line with the close names."""
    infos = locate_fmus(runner.base.structure(), runner.fmu_files)
    plan = build_plan(runner.base.structure(), infos)
    units = {}
    for name in runner.signals:
        try:
            units[name] = plan.port(name).var.unit or ""
        except UnknownSignalError as exc:
            comp = name.split(".", 1)[0]
            known = [f"{comp}.{v}" for v in infos[comp].variables] if comp in infos else []
            close = difflib.get_close_matches(name, known, n=3, cutoff=0.5)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            # Refused (correctness): a signal the run does not have
            raise CalibrationError(f"--map {name}=...: not a signal of the run: {exc.args[0] if exc.args else exc}"
                                   f"{hint}") from None
    data = runner.base.model_dump(mode="json", by_alias=True)
    starts = []
    for fit in fits:
        values = [_value_at(runner, data, infos, name, fit.label) for name in fit.names]
        starts.append(values[0])
        if any(v != values[0] for v in values):
            runner.notes.append(f"{fit.label}: linked names start from {fit.names[0]}'s {values[0]:g} (the "
                                f"scenario has {', '.join(f'{v:g}' for v in values)})")
    return starts, units


def _value_at(runner: _Runner, data: dict, infos: Mapping[str, Any], name: str, label: str) -> float:
    """The scenario's value at address ``name`` (a component parameter not set: its FMU's start value)."""
    path = resolve_name(name, runner.source.data, f"--fit {label}")  # an unknown section or component: did you mean
    if path[0] == "components" and len(path) == 4 and path[2] == "parameters":
        value = data["components"][path[1]]["parameters"].get(path[3])
        var, element, _ = find_variable(infos[path[1]], path[3])
        if var is None or var.causality not in ("parameter", "input"):
            settable = [v.name for v in infos[path[1]].variables.values() if v.causality in ("parameter", "input")]
            close = difflib.get_close_matches(path[3], settable, n=3, cutoff=0.5)
            hint = f"; did you mean {', '.join(f'{path[1]}.{c}' for c in close)}?" if close else ""
            # Refused (correctness): a parameter the component does not have
            raise CalibrationError(f"--fit {label}: {path[1]} has no parameter {path[3]!r}{hint}")
        if value is None:
            value = var.start
            if isinstance(value, (list, tuple)) and element is not None:
                value = value[element]
    else:
        value = data
        for key in path:
            value = value.get(key) if isinstance(value, dict) else (
                value[key] if isinstance(value, list) and isinstance(key, int) and key < len(value) else None)
    try:
        number = float(value)
        if isinstance(value, bool) or not math.isfinite(number):
            raise ValueError
    except (TypeError, ValueError):
        # Refused (correctness): no fit starts from a value that is no number
        raise CalibrationError(f"--fit {label}: {name} is {value!r} in the scenario, not a finite number to start "
                               f"the fit from (give one with --set {name}=VALUE)") from None
    return number


@dataclass
class _Problem:
    """The recorded samples the residual covers (fixed at the start), per mapped run signal, and their weights."""

    tau: dict[str, np.ndarray]  # recording times, s
    y: dict[str, np.ndarray]  # recorded values, in the run signal's unit
    scale: dict[str, float]  # each signal's residual is divided by this

    def residuals(self, t: np.ndarray, ys: Mapping[str, np.ndarray], offset: float,
                  weighted: bool = True) -> dict[str, np.ndarray]:
        return {n: (np.interp(self.tau[n] - offset, t, ys[n]) - self.y[n]) / (self.scale[n] if weighted else 1.0)
                for n in self.tau}


def _recorded(recording: str | Path, maps: Mapping[str, str], units: Mapping[str, str], given: Mapping[str, str],
              time_stamps: str, time_origin: str, notes: list[str]):
    """The mapped recorded signals, named by run signal, each converted to its run signal's unit."""
    rec = read_recording(recording, dict(maps), time=time_stamps, time_origin=time_origin, units=dict(given))
    for name, spec in maps.items():
        have, want = rec.units[name], units[name]
        if have and want:
            rec.values[name] = rec.values[name] * unit_factor(have, want, f"{recording}: {spec} -> {name}")
        elif want:
            notes.append(f"{spec} has no unit: taken as {name}'s {want} (give --unit {name}=UNIT)")
    if rec.end_note:
        notes.append(f"warning: {rec.end_note}")
    return rec


def _problem(rec, t: np.ndarray, offset: float, recording: str | Path, maps: Mapping[str, str]) -> _Problem:
    """The recorded samples inside the start run (at the start offset), and the weights by unit."""
    tau, y = {}, {}
    for name, spec in maps.items():
        keep = (rec.times[name] - offset >= t[0]) & (rec.times[name] - offset <= t[-1])
        if keep.sum() < 2:
            times = rec.times[name]
            # Refused (correctness): past the recording's ends the fitted values would be made up
            raise CalibrationError(f"{name}: the run covers t = {t[0]:.3f} .. {t[-1]:.3f} s and {recording}'s {spec} "
                                   f"{times[0]:.3f} .. {times[-1]:.3f} s (offset {offset:.6g} s): no overlap; try "
                                   "--fit offset, --offset, --time-origin or --time")
        tau[name], y[name] = rec.times[name][keep], rec.values[name][keep]
    return _Problem(tau, y, {})


def _weigh(problem: _Problem, units: Mapping[str, str]) -> str:
    """Each signal's residual over the largest spread (std) of the recorded signals of its unit."""
    spread: dict[str, float] = {}
    for name, y in problem.y.items():
        spread[units[name]] = max(spread.get(units[name], 0.0), float(np.std(y)))
    for name in problem.y:
        problem.scale[name] = spread[units[name]] if spread[units[name]] > 0 else 1.0
    return "residuals over the recorded spread of their unit: " + ", ".join(
        f"{u or '(none)'} {s:.3g}" for u, s in spread.items())


def calibrate(scenario: str | Path, recording: str | Path, maps: Mapping[str, str], fits: Sequence[Fit], *,
              sets: Sequence[str] = (), units: Mapping[str, str] | None = None, time_stamps: str = "header",
              time_origin: str = "first", offset: float = 0.0, max_runs: int = 60,
              on_run: Callable[[int], None] | None = None) -> Calibration:
    """Fit ``fits`` so that the scenario's run matches ``recording`` (see the module docstring).

    ``maps``: run signal -> recording spec; ``units``: run signal -> the recorded signal's unit where the recording
    has none; ``offset``: the recording's time minus the run's, s, used when ``offset`` is not fitted (fitted,
    it starts from :func:`~cosim.analysis.recording_compare.estimate_offset`'s estimate at the start values);
    ``max_runs``: the runs of the scenario the fit may make; ``on_run(runs)`` after each. Raises
    :class:`CalibrationError` (or ScenarioError, RecordingError) for bad input; a fit that does not converge is a
    result with ``converged`` False."""
    t_start = time.perf_counter()
    if not maps:
        # Refused (correctness): no signal paired: nothing to fit against
        raise CalibrationError("calibrate needs --map RUN_SIGNAL=RECORDING_SIGNAL (one per signal)")
    fits = list(fits)
    scen = [f for f in fits if not f.is_offset]
    off_fit = next((f for f in fits if f.is_offset), None)
    runner = _Runner(scenario, sets, scen, list(maps), max_runs, on_run)
    held = Extractions()
    try:
        with held:  # extracted once, for every run of the fit
            for info in locate_fmus(runner.base.structure(), runner.fmu_files).values():
                getattr(info, "unzipdir", None)  # an FMU's: extracted on first use (a recording component has none)
        starts, run_units = _start_values(runner, scen)
        for f, s in zip(scen, starts):
            if not f.low <= s <= f.high:
                # Refused (correctness): a start outside the bounds: the fit would start from another value than given
                raise CalibrationError(f"--fit {f.label}={f.low:g}:{f.high:g}: the start value {s:g} (the "
                                       f"scenario's) is outside the bounds; give another with --set")
        rec = _recorded(recording, maps, run_units, units or {}, time_stamps, time_origin, runner.notes)
        return _fit(runner, rec, scen, off_fit, starts, offset, run_units, str(scenario), str(recording), maps,
                    t_start)
    finally:
        held.release()


def _rms(parts: Mapping[str, np.ndarray]) -> dict[str, float]:
    return {n: float(np.sqrt(np.mean(e * e))) for n, e in parts.items()}


def _uncertainty(jac: np.ndarray | None, r: np.ndarray, n: int) -> tuple[list[float | None], list[list[float]], str]:
    """Standard errors and correlations from the weighted Jacobian at the solution: cov = (J^T J)^-1 s^2, through
    J's singular values (J = U S V^T, cov = V S^-2 V^T s^2: forming J^T J squares J's condition, and a value the
    signals barely show, next to the offset, lost all its digits there)."""
    if jac is None:
        return [None] * n, [], ""
    m = len(r)
    s2 = float(r @ r) / max(1, m - n)
    _, sv, vt = np.linalg.svd(jac, full_matrices=False)
    tol = sv.max(initial=0.0) * max(jac.shape) * np.finfo(float).eps
    rank = int((sv > tol).sum())
    note = ""
    if rank < n:
        note = (f"the Jacobian has rank {rank} for {n} fitted values: some are not identifiable from these signals "
                "(they change the run alike, or not at all); their errors are unbounded")
        return [math.inf] * n, [], note
    cov = (vt.T / sv ** 2) @ vt * s2
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    return [float(v) for v in se], [[float(v) for v in row] for row in np.nan_to_num(corr)], note


def _start_offset(t: np.ndarray, ys: Mapping[str, np.ndarray], rec, fit: Fit) -> float:
    """The offset to start from: :func:`estimate_offset` at the start values. Unbounded, it searches the offsets
    at which the shorter of the run and the recording lies within the longer (a recording holds the robot before
    and after the run, as robots are recorded), and a quarter of the shorter span and two samples beyond: centred
    there (the recording's times shifted for the search), as the correlation of a sliver of overlap at an edge
    is meaningless; bounded, within the bounds."""
    names = list(rec.times)
    if math.isfinite(fit.low) and math.isfinite(fit.high):
        centre, limit = 0.0, max(abs(fit.low), abs(fit.high))
    else:
        rec0 = max(float(rec.times[n][0]) for n in names)
        rec1 = min(float(rec.times[n][-1]) for n in names)
        a, b = rec0 - float(t[0]), rec1 - float(t[-1])
        step = max(float(np.median(np.diff(rec.times[n]))) for n in names)
        centre = 0.5 * (a + b)
        limit = max(0.5 * abs(a - b), 0.25 * min(rec1 - rec0, float(t[-1] - t[0]))) + 2 * step
    with warnings.catch_warnings():  # Brent's parabola through an infinite residual (no overlap there): no use
        warnings.simplefilter("ignore", RuntimeWarning)
        found = estimate_offset([(t, ys[n]) for n in names], [(rec.times[n] - centre, rec.values[n]) for n in names],
                                limit)
    return min(max(found.offset + centre, fit.low), fit.high)


def _fit(runner: _Runner, rec, scen: list[Fit], off_fit: Fit | None, starts: list[float], offset: float,
         units: Mapping[str, str], scenario: str, recording: str, maps: Mapping[str, str],
         t_start: float) -> Calibration:
    """The least-squares fit from the start values (the module docstring says how)."""
    from scipy.optimize import least_squares  # lazy: --help loads this module without it

    t, ys = runner(starts)
    n_s = len(scen)
    if off_fit is not None:
        offset = _start_offset(t, ys, rec, off_fit)
        runner.notes.append(f"offset started from {offset:.9g} s (cross-correlation at the start values)")
    problem = _problem(rec, t, offset, recording, maps)
    weighting = _weigh(problem, units)
    x0 = np.array(starts + ([offset] if off_fit is not None else []), dtype=float)
    fits = scen + ([off_fit] if off_fit is not None else [])
    if sum(len(v) for v in problem.tau.values()) <= len(fits):
        # Refused (correctness): fewer samples than fitted values: the fit is not determined
        raise CalibrationError(f"{sum(len(v) for v in problem.tau.values())} recorded samples inside the run for "
                               f"{len(fits)} fitted values: too few to fit")
    best = {"cost": math.inf, "x": x0.copy()}
    evaluations = 0

    def fun(x: np.ndarray) -> np.ndarray:
        nonlocal evaluations
        tr, yr = runner(x[:n_s])
        r = np.concatenate(list(problem.residuals(tr, yr, x[n_s] if off_fit is not None else offset).values()))
        evaluations += 1
        if float(r @ r) < best["cost"]:
            best.update(cost=float(r @ r), x=x.copy())
        return r

    r0 = fun(x0)
    before = _rms(problem.residuals(t, ys, offset, weighted=False))
    rec_step = min(float(np.median(np.diff(v))) for v in problem.tau.values())
    diff_step = np.array([DIFF_STEP] * n_s + ([0.1 * rec_step / max(abs(offset), 1e-300)] if off_fit else []))
    try:
        res = least_squares(fun, x0, bounds=([f.low for f in fits], [f.high for f in fits]), method="trf",
                            x_scale="jac", diff_step=diff_step, max_nfev=10 * runner.max_runs)
        x, jac, r = res.x, res.jac, res.fun
        converged, message = res.status > 0, res.message
    except _Budget:
        x, jac = best["x"], None
        r = fun(x)
        converged, message = False, (f"stopped after {runner.runs} runs (--max-runs {runner.max_runs}); the "
                                     "values below are the best found")
    t1, y1 = runner(x[:n_s])
    after = _rms(problem.residuals(t1, y1, x[n_s] if off_fit is not None else offset, weighted=False))
    se, corr, note = _uncertainty(jac, r, len(fits))
    if note:
        runner.notes.append(note)
    for f, v in zip(fits, x):
        if v in (f.low, f.high):
            runner.notes.append(f"{f.label} ended on its bound {v:g}: the fit would go beyond it (a value the "
                                "signals do not show, or bounds too narrow)")
    params = [{"label": f.label, "names": list(f.names), "start": float(s), "value": float(v), "stderr": e,
               "low": f.low, "high": f.high} for f, s, v, e in zip(fits, x0, x, se)]
    return Calibration(scenario, recording, params, corr, before, after, dict(units),
                       float(np.sqrt(np.mean(r0 * r0))), float(np.sqrt(np.mean(r * r))), len(r0), runner.runs,
                       evaluations, time.perf_counter() - t_start, bool(converged), message, weighting, runner.notes,
                       runner.run_time)


def offset_component(scenario: str | Path, sets: Sequence[str], recording: str | Path, time_stamps: str,
                     time_origin: str) -> str | None:
    """The component of the scenario (after ``sets``) that replays ``recording`` read as the calibration read it
    (the same file, ``time`` and ``time_origin``), whose ``offset`` is then the fitted offset; None without one."""
    sc = read_scenario(scenario).load(apply_overrides(list(sets)))
    base = Path(scenario).parent
    for name, comp in sc.components.items():
        if comp.recording is not None and (base / comp.recording).resolve() == Path(recording).resolve() and \
                (comp.time, comp.time_origin) == (time_stamps, time_origin):
            return name
    return None


def write_fitted(cal: Calibration, out: str | Path, command: str, offset_at: str | None = None) -> Path:
    """The fitted values as a file of values that a scenario names with ``parameters: FILE`` (``name: value`` by the
    addresses ``--fit`` took; a linked fit's value at each of its names; the offset as ``components.<offset_at>.offset``
    when ``offset_at`` names the scenario's component that replays the recording, else in the header only: it is
    the recording's clock), written atomically (a temporary file renamed over ``out``). Its header comments say what
    made it: ``command``, the date, the scenario and the recording, the fit's verdict, each value with its standard
    error, the residual RMS before and after."""
    import yaml  # lazy: --help loads this module without it

    out = Path(out)
    values = {n: float(v) for n, v in cal.values.items() if n != OFFSET}
    if OFFSET in cal.values and offset_at is not None:
        values[f"components.{offset_at}.offset"] = float(cal.values[OFFSET])
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    head = [f"# Values of the scenario {cal.scenario} fitted to the recording {cal.recording}",
            f"# Written by: {command}", f"# On: {now}",
            f"# Fit: {'converged' if cal.converged else 'DID NOT CONVERGE'} ({cal.message}); {cal.runs} runs of the "
            f"scenario, {cal.samples} recorded samples", "# Fitted (start -> value, standard error):"]
    for p in cal.parameters:
        se = "" if p["stderr"] is None else f", +- {p['stderr']:.3g}"
        where = ""
        if p["label"] == OFFSET:
            where = (f" s, the recording's time minus the run's: components.{offset_at}.offset below" if offset_at
                     else " s, the recording's time minus the run's (the scenario replays no such recording: "
                          "not a value of it)")
        head.append(f"#   {p['label']}: {p['start']!r} -> {p['value']!r}{se}{where}")
    head.append("# Residual RMS before -> after: " + ", ".join(
        f"{n} {cal.rms_before[n]:.4g} -> {cal.rms_after[n]:.4g} {cal.units[n]}" for n in cal.rms_before))
    head.append("# A scenario takes these values with the key  parameters: <this file, relative to the scenario's "
                "folder>  (over its own values, under --set)")
    body = yaml.safe_dump(values, sort_keys=False, default_flow_style=False) if values else ""
    with written_by_rename(out) as tmp:
        tmp.write_text("\n".join(head) + "\n" + body, encoding="utf-8")
    return out
