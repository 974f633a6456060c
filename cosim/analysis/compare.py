"""Regression comparisons: two run logs, or one scenario run on two plants.

``compare_logs(a, b)`` compares every signal the two logs share at the time stamps
both logged (their common grid: a 1 ms run against a 20 ms baseline is compared at the
baseline's stamps, in either order; logs that share no stamps are refused, never
interpolated), over the time both cover, and reports per signal the RMSE, the largest
absolute difference and when it happened. Signals with a tolerance (``Regression.tolerances`` in a
scenario, or ``--tol`` options) pass or fail; the others are reported only.
Comparing a run with its baseline, the tolerances default to the ``regression``
section of the scenario attached to the baseline (``logged_tolerances``).

``compare_plants(scenario, ("exudyn", "analytic"))`` runs one scenario once per
plant (the plant component's FMU swapped, everything else unchanged), logs each
run, and compares the logs.
"""

from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from fmus import registry

from ..engine.bounded_yaml import load_yaml
from ..engine.scenario import load_scenario
from ..errors import CosimError, Issue, ScenarioError
from ..io.runlog import RunLog, Signal, read_run
from ..observers.stats import ErrorStats
from ..run import run_scenario

__all__ = ["Comparison", "compare_logs", "compare_plants", "tolerance_for", "parse_tolerances",
           "logged_tolerances", "PLANTS"]


@dataclass
class Comparison:
    """Everything ``compare_logs`` found; ``ok`` when no tolerance is exceeded and the coverage matches."""

    a: str
    b: str
    diffs: list[ErrorStats]
    t_start: float
    t_stop: float
    only_a: list[str] = field(default_factory=list)
    only_b: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)  # failures that are not a signal's tolerance
    # against a recording (cosim.analysis.recording_compare): its time minus the run's, s, and how it was found
    offset: float | None = None
    offset_how: str = ""
    notes: list[str] = field(default_factory=list)

    @property
    def failed(self) -> list[ErrorStats]:
        return [d for d in self.diffs if not d.ok]

    @property
    def ok(self) -> bool:
        return not self.failed and not self.problems

    def as_dict(self) -> dict:
        if self.offset is not None:  # a run against a recording: each signal names its recorded one and the offset
            return {"run": self.a, "recording": self.b, "ok": self.ok, "t_start": self.t_start,
                    "t_stop": self.t_stop, "offset_s": self.offset, "offset_how": self.offset_how,
                    "signals": [{**d.as_dict(*_SIGNAL_KEYS[:1], "reference", *_SIGNAL_KEYS[1:], max_error="max_abs"),
                                 "offset_s": self.offset} for d in self.diffs],
                    "notes": self.notes, "failed": [d.name for d in self.failed]}
        return {"a": self.a, "b": self.b, "ok": self.ok, "t_start": self.t_start, "t_stop": self.t_stop,
                "signals": [d.as_dict(*_SIGNAL_KEYS, max_error="max_abs") for d in self.diffs], "only_a": self.only_a,
                "only_b": self.only_b, "problems": self.problems,
                "failed": [d.name for d in self.failed]}

    @property
    def checked(self) -> int:
        """Signals compared against a tolerance."""
        return sum(d.tolerance is not None for d in self.diffs)

    def text(self, only_checked: bool = False) -> str:
        """A readable table, failures first; ``only_checked`` leaves out signals without a tolerance."""
        rows = sorted(self.diffs, key=lambda d: (d.ok, d.tolerance is None))
        if only_checked:
            rows = [d for d in rows if d.tolerance is not None]
        width = max([len(d.name) for d in rows] + [6])
        head = (f"A = {self.a}\nB = {self.b}\n{len(self.diffs)} common signals over "
                f"t = {self.t_start:.3f} .. {self.t_stop:.3f} s")
        if self.offset is not None:
            head = (f"A = {self.a} (run)\nB = {self.b} (recording)\n{len(self.diffs)} signals over run time "
                    f"t = {self.t_start:.3f} .. {self.t_stop:.3f} s\noffset (recording - run): {self.offset:.9g} s "
                    f"({self.offset_how})" + "".join(f"\n{n}" for n in self.notes))
        lines = [head, f"{'signal':<{width}}  {'unit':<5} {'RMSE':>10} {'max|A-B|':>10} {'at t/s':>8} "
                       f"{'tolerance':>10}  verdict"]
        for d in rows:
            tol = "-" if d.tolerance is None else f"{d.tolerance:.3g}"
            verdict = "" if d.tolerance is None else ("ok" if d.ok else "FAILED")
            lines.append(f"{d.name:<{width}}  {d.unit:<5} {d.rmse:>10.4g} {d.max_error:>10.4g} {d.t_max:>8.3f} "
                         f"{tol:>10}  {verdict}".rstrip())
        if self.only_a:
            lines.append(f"only in A: {', '.join(self.only_a)}")
        if self.only_b:
            lines.append(f"only in B: {', '.join(self.only_b)}")
        lines += [f"FAILED: {p}" for p in self.problems]
        lines += [f"FAILED: {d.message()}" for d in self.failed]
        checked = self.checked
        if not checked and self.ok:
            lines.append("nothing checked: no signal has a tolerance (--tol NAME=VALUE, or the scenario's "
                         "regression.tolerances); the differences are listed only")
        else:
            lines.append(("ok" if self.ok else "FAILED") + f": {checked} signals checked against a tolerance, "
                         f"{len(self.failed)} exceeded")
        return "\n".join(lines)


# one signal in ``compare --json`` (its keys since the first release, max_error as max_abs; the sides are
# the logs ``a`` and ``b``, not signals)
_SIGNAL_KEYS = ("name", "unit", "rmse", "max_error", "t_max", "samples", "tolerance", "ok")


# --------------------------------------------------------------------------- tolerances


def _matches(pattern: str, name: str) -> int:
    """How specifically ``pattern`` matches ``name``: 0 no match; higher is more specific."""
    if pattern == name:
        return 3
    if name.startswith(pattern) and name[len(pattern)] in ".[":
        return 2
    if ("*" in pattern or "?" in pattern) and _glob(pattern).fullmatch(name):
        return 1
    return 0


@functools.lru_cache(maxsize=256)
def _glob(pattern: str) -> re.Pattern:
    """``*`` and ``?`` are wildcards; brackets are literal (they are part of names like ``u[1]``)."""
    return re.compile(re.escape(pattern).replace(r"\*", ".*").replace(r"\?", "."))


def tolerance_for(name: str, tolerances: Mapping[str, float]) -> float | None:
    """The tolerance of ``name``: exact name, else the longest prefix, else a glob."""
    best, best_key = None, (0, 0)
    for pattern, tol in tolerances.items():
        m = _matches(pattern, name)
        if m and (m, len(pattern)) > best_key:
            best, best_key = tol, (m, len(pattern))
    return best


def parse_tolerances(items: Sequence[str]) -> dict[str, float]:
    """``["plant.p=1e-6", "ctl.u=0.01"]`` -> dict; a malformed item raises CosimError naming it."""
    out: dict[str, float] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        try:
            value = float(raw)
        except ValueError:
            value = math.nan
        if not sep or not key or not 0 < value < math.inf:  # nan and inf are no tolerance
            # Refused (correctness): a tolerance we cannot read: the verdict would use a guess
            raise CosimError(f"--tol {item!r}: expected SIGNAL_PATTERN=POSITIVE_NUMBER (finite), e.g. plant.p=1e-6")
        out[key.strip()] = value
    return out


def logged_tolerances(log: RunLog) -> dict[str, float]:
    """``regression.tolerances`` of the scenario attached to ``log`` ({} when it has none)."""
    import yaml  # lazy: --help loads this module without it


    for name, data in log.attachments.items():
        if name.startswith("scenario/") and not name.endswith(".ssp"):  # a YAML scenario, not an SSP archive
            try:
                doc = load_yaml(data)[0] or {}
            except yaml.YAMLError:
                return {}
            tol = (doc.get("regression") or {}).get("tolerances") or {}
            return {str(k): float(v) for k, v in tol.items()}
    return {}


# --------------------------------------------------------------------------- logs


def _aligned(sa: Signal, sb: Signal, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The samples of A and B at the time stamps both logged in [lo, hi] ns (exact, never interpolated).

    On one grid that is every sample; a 1 ms run against a 20 ms baseline compares at the
    baseline's stamps, whichever log comes first, so the verdict does not depend on the order.
    """
    keep_a = (sa.t_ns >= lo) & (sa.t_ns <= hi)
    keep_b = (sb.t_ns >= lo) & (sb.t_ns <= hi)
    t_ns, ia, ib = np.intersect1d(sa.t_ns[keep_a], sb.t_ns[keep_b], assume_unique=False, return_indices=True)
    return t_ns, sa.y[keep_a][ia], sb.y[keep_b][ib]


def _period(t_ns: np.ndarray) -> int:
    return int(np.median(np.diff(t_ns))) if len(t_ns) > 1 else 0


def compare_logs(a: RunLog | str | Path, b: RunLog | str | Path, tolerances: Mapping[str, float] | None = None,
                 signals: Sequence[str] | None = None, labels: tuple[str, str] | None = None) -> Comparison:
    """Compare two run logs signal by signal (see the module docstring).

    ``signals``: patterns (as for tolerances) selecting what to compare; default all common
    signals. A tolerance pattern that matches no common signal is an error (a typo would
    otherwise silently check nothing). Each log must cover the other's time span (within one
    step of the coarser grid), else the comparison fails; the verdict is the same in either order.
    """
    a = a if isinstance(a, RunLog) else read_run(a)
    b = b if isinstance(b, RunLog) else read_run(b)
    tolerances = dict(tolerances or {})
    names_a, names_b = list(a.signals), set(b.signals)
    common = [n for n in names_a if n in names_b]
    unused = [p for p in tolerances if not any(_matches(p, n) for n in common)]
    if unused:
        # Refused (correctness): a tolerance that applies to nothing: the signal meant is judged by another
        raise CosimError(f"tolerance pattern(s) {', '.join(unused)} match no signal of both logs "
                         f"(e.g. {', '.join(common[:4])})")
    if signals:
        common = [n for n in common if any(_matches(p, n) for p in signals)]
        if not common:
            # Refused (correctness): nothing to compare: a pass would say nothing
            raise CosimError(f"no common signal of {a.path} and {b.path} matches {', '.join(signals)}")
    if not common:
        # Refused (correctness): nothing to compare: a pass would say nothing
        raise CosimError(f"{a.path} and {b.path} share no signal (components {', '.join(a.components)} vs "
                         f"{', '.join(b.components)})")
    first, other = a.signals[common[0]], b.signals[common[0]]
    lo = max(int(first.t_ns[0]), int(other.t_ns[0]))
    hi = min(int(first.t_ns[-1]), int(other.t_ns[-1]))
    problems = []
    if hi < lo:
        # Refused (correctness): no common time: a pass would say nothing
        raise CosimError(f"{a.path} covers t = {first.t[0]:.3f} .. {first.t[-1]:.3f} s and {b.path} "
                         f"t = {other.t[0]:.3f} .. {other.t[-1]:.3f} s: no overlap")
    step = max(_period(first.t_ns), _period(other.t_ns))  # the coarser grid
    for label, sig, them in (("B", other, first), ("A", first, other)):
        if hi < them.t_ns[-1] - step or lo > them.t_ns[0] + step:
            problems.append(f"{label} covers t = {sig.t[0]:.3f} .. {sig.t[-1]:.3f} s of "
                            f"{'A' if label == 'B' else 'B'}'s {them.t[0]:.3f} .. {them.t[-1]:.3f} s "
                            f"(a run stopped early?)")
            break
    diffs = []
    for name in common:
        sa, sb = a.signals[name], b.signals[name]
        t_ns, ya, yb = _aligned(sa, sb, lo, hi)
        if len(t_ns) < 2 and min(len(sa.t_ns), len(sb.t_ns)) >= 2:
            # Refused (correctness): no common stamps: values would have to be interpolated, which compare never does
            raise CosimError(f"{name}: {a.path} (every {_period(sa.t_ns) * 1e-9:.6g} s) and {b.path} (every "
                             f"{_period(sb.t_ns) * 1e-9:.6g} s) share {len(t_ns)} time stamp(s) over t = "
                             f"{lo * 1e-9:.3f} .. {hi * 1e-9:.3f} s: no common grid to compare them on "
                             f"(logs are compared where both have a sample, never interpolated)")
        e = ya - yb
        both_nan = np.isnan(ya) & np.isnan(yb)
        e[both_nan] = 0.0
        e[np.isnan(e)] = np.inf  # a value on one side only is an unbounded difference
        diffs.append(ErrorStats.of(e, t_ns * 1e-9, name=name, unit=sa.unit or sb.unit,
                                   tolerance=tolerance_for(name, tolerances)))
    la, lb = labels or (str(a.path), str(b.path))
    return Comparison(la, lb, diffs, lo * 1e-9, hi * 1e-9, [n for n in names_a if n not in names_b],
                      sorted(names_b.difference(names_a)), problems)


# --------------------------------------------------------------------------- plants

# plant name -> (the plant FMU's variant in the registry, extra component settings)
PLANTS: dict[str, tuple[str, dict]] = {
    "exudyn": ("exudyn", {"parameters": {"model.fidelity": "full"}}),
    "exudyn_lumped": ("exudyn", {"parameters": {"model.fidelity": "lumped"}}),
    "analytic": ("analytic", {}),
    # integrated as scenarios/helix_ctc_me.yaml integrates it: its effort input changes every step, so a one-step
    # method (DOP853) restarts for free where CVode's BDF restarts at order 1; rtol 1e-10 (benchmarks/model_exchange.py)
    "analytic_me": ("analytic_me", {"interface": "me", "solver": "dop853", "rtol": 1e-10}),
}


def _plant_component(scenario, component: str | None) -> tuple[str, str]:
    """(component name, robot kind) of the scenario's plant: the component that is one of our plant FMUs."""
    plants = {e.name: e for e in registry.find("plant")}
    found = {n: plants[c.fmu] for n, c in scenario.components.items() if c.fmu in plants}
    if component is not None:
        if component not in scenario.components:
            # Refused (correctness): a component the scenario does not have
            raise ScenarioError(Issue("--component", f"unknown component {component!r}; components: "
                                      f"{', '.join(scenario.components)}", scenario.source))
        if component not in found:
            # Refused (correctness): the plant comparison needs one of our plants: another's values mean other things
            raise ScenarioError(Issue(f"components.{component}", "is not one of our plant FMUs "
                                      f"({', '.join(plants)}); its plant cannot be swapped", scenario.source))
        return component, found[component].kind
    if len(found) != 1:
        # Refused (correctness): which plant is meant is a guess
        raise ScenarioError(Issue("components", f"{'no' if not found else 'more than one'} plant component "
                                  f"({', '.join(found) or 'none of our plant FMUs'}); name it with --component",
                                  scenario.source))
    name, entry = next(iter(found.items()))
    return name, entry.kind


def _plant_overrides(scenario, component: str, kind: str, plant: str) -> tuple[dict, list[str]]:
    """Loader overrides that put ``plant`` in ``component``, and the parameters it had to drop."""
    from fmpy import read_model_description  # lazy: --help loads this module without it


    variant, extra = PLANTS[plant]
    fmu = registry.find("plant", kind, variant)[0].name
    md = read_model_description(str(registry.build(fmu)))
    variables = {v.name for v in md.modelVariables}
    base = dict(scenario.components[component].parameters)
    base.update(extra.get("parameters", {}))
    kept = {k: v for k, v in base.items() if k in variables or f"{k}[1]" in variables}
    dropped = sorted(set(base) - set(kept))
    comp = ("components", component)
    overrides = {comp + ("fmu",): fmu, comp + ("parameters",): kept,
                 comp + ("interface",): extra.get("interface", "auto")}
    for key in ("solver", "rtol"):  # the integrator a model-exchange plant is run with, not the defaults
        if key in extra:
            overrides[comp + (key,)] = extra[key]
    return overrides, dropped


def compare_plants(path: str | Path, plants: Sequence[str] = ("exudyn", "analytic"), out_dir: str | Path = "runs",
                   tolerances: Mapping[str, float] | None = None, signals: Sequence[str] | None = None,
                   overrides: dict | None = None, component: str | None = None, progress: bool = False,
                   on_run: Callable[[str, object], None] | None = None) -> tuple[Comparison, list]:
    """Run the scenario at ``path`` on each of two plants and compare their logs.

    Tolerances: the scenario's ``regression.plant_tolerances`` updated with ``tolerances``.
    Logs go to ``out_dir/<scenario>.<plant>.mcap``. ``on_run(plant, RunResult)`` is called
    after each run. Returns (comparison, [RunResult, RunResult]).
    """

    if len(plants) != 2:
        # Refused (correctness): a comparison is of two
        raise CosimError(f"--plants needs exactly two plants, got {len(plants)}: {', '.join(plants)}")
    unknown = [p for p in plants if p not in PLANTS]
    if unknown:
        # Refused (correctness): a plant we do not have
        raise CosimError(f"unknown plant {', '.join(unknown)}; valid: {', '.join(PLANTS)}")
    base = load_scenario(path, overrides)
    comp, kind = _plant_component(base, component)
    tol = {**base.regression.plant_tolerances, **(tolerances or {})}
    results, logs, labels = [], [], []
    for plant in plants:
        swap, dropped = _plant_overrides(base, comp, kind, plant)
        scenario = load_scenario(path, {**(overrides or {}), **swap})
        out = Path(out_dir) / f"{base.name}.{plant}.mcap"
        res = run_scenario(scenario, out=out, log=True, progress=progress)
        if on_run is not None:
            on_run(plant, res)
        results.append(res)
        logs.append(read_run(out))
        note = f" (dropped {', '.join(dropped)})" if dropped else ""
        how = (f" ({swap[('components', comp, 'solver')]}, rtol {swap[('components', comp, 'rtol')]:g})"
               if ("components", comp, "solver") in swap else "")
        labels.append(f"{plant}: {swap[('components', comp, 'fmu')]}{how}{note} -> {out}")
    return compare_logs(logs[0], logs[1], tol, signals, (labels[0], labels[1])), results
