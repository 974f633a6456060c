"""Reports of a run log: figures and a markdown summary, and the controller table (thesis Table 5).

``make_report(run)`` reads a run's MCAP log (:mod:`cosim.io.runlog`) and writes, into
``<log stem>_report/`` next to the log unless told otherwise:

- ``path_3d.png``: the platform path, desired vs actual, in 3D;
- ``position.png``: x, y, z desired vs actual over time;
- ``errors.png``: position error per axis and, when the log has them, velocity error
  per axis (actual ``plant.v`` vs ``traj.v_ref``), scaled to mm / um / nm / pm / fm as suits
  (tick labels are plain numbers: no offset, no exponent);
- ``joints.png``: joint-space tracking: each joint ``q[i]`` of the plant against its reference
  ``q_ref[i]`` (the IK's output, else the controller's input), and the error, in mm or deg;
- ``efforts.png``: the actuator efforts ``u[1..3]`` in the log's unit;
- ``report.md``: scenario, robot, status, duration, per-axis RMSE and max error (with
  its time) and the figures.

``controller_table(runs)`` gives RMSE per axis per run, in m and um, as markdown,
with the thesis's Table 5 values as extra, labelled rows when the runs are the thesis
helix.

The signals compared are those of the ``compare`` section of the scenario attached to
the log (``plant.p`` vs ``traj.p_ref`` when there is none). Errors are ``actual -
reference`` at the time stamps both signals carry: for a single-rate run that is the
start sample and every step, the samples the run's own summary
(:class:`cosim.observers.recorders.ErrorObserver`) used, so the RMSE here equals the summary's.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from delta.paper_data import THESIS_TABLE_5_M
from fmus import registry

from ..engine.bounded_yaml import load_yaml
from ..engine.schema import Compare, expand_signal
from ..errors import CosimError, written_by_rename
from ..io.output import output_dir
from ..io.runlog import AXES, RunLog, read_run
from ..observers.stats import ErrorStats

__all__ = ["ReportError", "Pair", "Tracking", "Report", "TableRow", "Table", "tracking", "make_report",
           "controller_table", "register"]

_DEFAULT_ACTUAL, _DEFAULT_REFERENCE = "plant.p", "traj.p_ref"
_JOINTS = ["q[1]", "q[2]", "q[3]"]
_DPI = 120
_THESIS_ROBOT = "linear_delta_thesis"
_THESIS_SOURCE = "thesis Table 5 (MATLAB controller, ADAMS prototype)"


class ReportError(CosimError, ValueError):
    """A run log cannot be reported on: a signal is missing, or the log holds no samples of it."""


# --------------------------------------------------------------------------- data


def _stats(axes: Sequence[str], actual: Sequence[str], reference: Sequence[str], unit: str, t: np.ndarray,
           e: np.ndarray) -> list[ErrorStats]:
    return [ErrorStats.of(e[:, j], t, name=ax, actual=a, reference=r, unit=unit)
            for j, (ax, a, r) in enumerate(zip(axes, actual, reference))]


@dataclass(frozen=True)
class Pair:
    """Actual and reference signals on the stamps they share: t (n,) s, actual/reference (n, k)."""

    actual_names: list[str]
    reference_names: list[str]
    unit: str
    t: np.ndarray
    actual: np.ndarray
    reference: np.ndarray

    @property
    def error(self) -> np.ndarray:
        return self.actual - self.reference


@dataclass(frozen=True)
class Tracking:
    """What a run tracked: position (and velocity when logged) actual vs reference, and the efforts."""

    run: RunLog
    source: str  # where the signal names came from
    axes: list[str]  # "x", "y", "z" (or the signal names when they are not a platform vector)
    position: Pair
    velocity: Pair | None
    efforts: tuple[list[str], str, np.ndarray, np.ndarray] | None  # names, unit, t (n,), values (n, k)
    joints: Pair | None = None  # joint positions q[1..3] vs their references q_ref[1..3]

    @property
    def is_platform(self) -> bool:
        return self.axes == list(AXES)

    def position_stats(self) -> list[ErrorStats]:
        p = self.position
        return _stats(self.axes, p.actual_names, p.reference_names, p.unit, p.t, p.error)

    def velocity_stats(self) -> list[ErrorStats]:
        v = self.velocity
        return [] if v is None else _stats(self.axes, v.actual_names, v.reference_names, v.unit, v.t, v.error)

    def joint_stats(self) -> list[ErrorStats]:
        q = self.joints
        return [] if q is None else _stats(_JOINTS, q.actual_names, q.reference_names, q.unit, q.t, q.error)


def _scenario_doc(run: RunLog) -> tuple[str | None, dict]:
    """The attached scenario file (name, parsed YAML mapping), or (None, {})."""
    import yaml  # lazy: --help loads this module without it


    for name, data in run.attachments.items():
        if name.startswith("scenario/"):
            try:
                doc = load_yaml(data)[0]
            except yaml.YAMLError as exc:
                raise ReportError(f"{run.path}: attachment {name} is not valid YAML ({exc})") from None
            return name, doc if isinstance(doc, dict) else {}
    return None, {}


def _compare_spec(run: RunLog) -> tuple[list[str], list[str], str]:
    from pydantic import ValidationError  # lazy: --help loads this module without it


    att, doc = _scenario_doc(run)
    section = doc.get("compare")
    if section is None:
        why = f"no compare section in {att}" if att else "no scenario attached"
        return (expand_signal(_DEFAULT_ACTUAL), expand_signal(_DEFAULT_REFERENCE),
                f"default {_DEFAULT_ACTUAL} vs {_DEFAULT_REFERENCE} ({why})")
    try:
        cmp = Compare.model_validate(section)
    except ValidationError as exc:
        raise ReportError(f"{run.path}: the compare section of {att} is invalid: "
                          f"{exc.errors()[0]['msg']}") from None
    actual, reference = expand_signal(cmp.actual), expand_signal(cmp.reference)
    if len(actual) != len(reference):
        raise ReportError(f"{run.path}: the compare section of {att} pairs {len(actual)} actual signals with "
                          f"{len(reference)} reference signals")
    return actual, reference, f"compare section of {att}"


def _get(run: RunLog, name: str, role: str, source: str):
    if name not in run:
        try:
            run.signal(name)
        except CosimError as exc:
            raise ReportError(f"{exc} (the {role} signal, from the {source})") from None
    return run.signals[name]


def _pair(run: RunLog, actual: list[str], reference: list[str], source: str) -> Pair:
    a = [_get(run, n, "actual", source) for n in actual]
    r = [_get(run, n, "reference", source) for n in reference]
    stamps = a[0].t_ns
    for s in a[1:] + r:
        stamps = np.intersect1d(stamps, s.t_ns, assume_unique=True)
    if stamps.size == 0:
        raise ReportError(f"{run.path}: {actual[0]} and {reference[0]} share no time stamp")

    def on_stamps(s) -> np.ndarray:
        return s.y[np.searchsorted(s.t_ns, stamps)]

    units = {s.unit for s in a + r}
    return Pair(actual, reference, a[0].unit if len(units) == 1 else "", stamps * 1e-9,
                 np.column_stack([on_stamps(s) for s in a]), np.column_stack([on_stamps(s) for s in r]))


def _velocity_name(name: str) -> str | None:
    """``plant.p.x`` -> ``plant.v.x``, ``traj.p_ref.x`` -> ``traj.v_ref.x``; other names have none."""
    comp, _, var = name.partition(".")
    head, _, axis = var.rpartition(".")
    if head in ("p", "p_ref") and axis in AXES:
        return f"{comp}.{'v' + head[1:]}.{axis}"
    return None


def _efforts(run: RunLog, actual_component: str):
    """The efforts the plant received (``<plant>.u[i]``), else a controller's ``u[i]`` output."""
    candidates = [actual_component] + [n.split(".", 1)[0] for n in run.find("u[1]")
                                       if run.signals[n].causality == "output"]
    for comp in dict.fromkeys(candidates):
        names = [f"{comp}.u[{i}]" for i in range(1, 4)]
        if all(n in run for n in names):
            parts = [run.signals[n] for n in names]
            if all(np.array_equal(p.t_ns, parts[0].t_ns) for p in parts):
                return names, parts[0].unit, parts[0].t, np.column_stack([p.y for p in parts])
    return None


def _joints(run: RunLog, actual_component: str) -> Pair | None:
    """The plant's joint positions ``q[1..3]`` against their references ``q_ref[1..3]``.

    The reference is the component that outputs ``q_ref`` (the inverse kinematics), else one
    that receives it (the controller's input); None when the log has no such signals.
    """
    actual = [f"{actual_component}.{q}" for q in _JOINTS]
    if not all(n in run for n in actual):
        return None
    candidates = sorted(run.find("q_ref[1]"), key=lambda n: run.signals[n].causality != "output")
    for name in candidates:
        reference = [f"{name.split('.', 1)[0]}.q_ref[{i}]" for i in range(1, 4)]
        if all(n in run for n in reference):
            return _pair(run, actual, reference, "joint signals")
    return None


def tracking(run: RunLog | str | Path) -> Tracking:
    """The signals a report shows, aligned in time. Raises ReportError naming the file and a missing signal."""
    run = run if isinstance(run, RunLog) else read_run(run)
    actual, reference, source = _compare_spec(run)
    position = _pair(run, actual, reference, source)
    axes = [n.rpartition(".")[2] for n in actual]
    if axes != list(AXES):
        axes = list(actual)
    v_act, v_ref = [_velocity_name(n) for n in actual], [_velocity_name(n) for n in reference]
    velocity = None
    if all(v_act + v_ref) and all(n in run for n in v_act + v_ref):
        velocity = _pair(run, v_act, v_ref, "velocity of the compared signals")
    comp = actual[0].split(".", 1)[0]
    return Tracking(run, source, axes, position, velocity, _efforts(run, comp), _joints(run, comp))


# --------------------------------------------------------------------------- figures

_PREFIXES = ((1.0, ""), (1e-3, "m"), (1e-6, "µ"), (1e-9, "n"), (1e-12, "p"), (1e-15, "f"))


def _scaled_unit(values: np.ndarray, unit: str) -> tuple[float, str]:
    """(factor, unit) showing ``values`` so that they read as 1..1000, with no offset or exponent.

    m and m/s as mm / um / nm / pm / fm (never m: a delta's positions read best in mm); rad and
    rad/s as deg / mdeg / udeg ...; other units unchanged.
    """
    scale = 1.0
    if unit in ("rad", "rad/s"):
        scale, unit, ladder = 180.0 / math.pi, unit.replace("rad", "deg"), _PREFIXES
    elif unit in ("m", "m/s"):
        ladder = _PREFIXES[1:]
    else:
        return 1.0, unit
    finite = values[np.isfinite(values)]
    peak = float(np.abs(finite).max()) * scale if finite.size else 0.0
    for size, prefix in ladder:
        if peak >= size:
            return scale / size, prefix + unit
    size, prefix = ladder[-1]
    return scale / size, prefix + unit


def _plain(ax) -> None:
    """Tick labels as plain numbers: no offset (``1e-5 +``) and no exponent above the axis."""
    ax.ticklabel_format(axis="y", style="plain", useOffset=False)


def _pretty_unit(unit: str) -> str:
    return unit.replace("N.m", "N·m").replace("m/s2", "m/s²") or "-"


def _fig(width: float, height: float, layout: str | None = "constrained"):
    from matplotlib.figure import Figure  # lazy: --help loads this module without it

    return Figure(figsize=(width, height), dpi=_DPI, layout=layout)


def _auto(value: float, unit: str) -> str:
    """``0.00465, "m/s"`` -> ``"4.65 mm/s"``."""
    f, u = _scaled_unit(np.array([value]), unit)
    return f"{value * f:.3g} {_pretty_unit(u)}"


def _plot_path(tr: Tracking, title: str, out: Path) -> Path:
    from matplotlib.ticker import (  # lazy: --help loads this module without it
        MaxNLocator,
        ScalarFormatter,
    )

    p = tr.position
    fig = _fig(7.5, 6.0, layout=None)  # constrained layout clips 3D axis labels
    fig.subplots_adjust(left=0.02, right=0.9, bottom=0.06, top=0.9)
    ax = fig.add_subplot(projection="3d")
    ref_mm, act_mm = p.reference * 1e3, p.actual * 1e3
    ax.plot(*ref_mm.T, color="tab:blue", lw=2.5, alpha=0.45, label=f"desired ({p.reference_names[0][:-2]})")
    ax.plot(*act_mm.T, color="tab:red", lw=0.9, label=f"actual ({p.actual_names[0][:-2]})")
    both = np.vstack([ref_mm, act_mm])
    lo, hi = np.nanmin(both, axis=0), np.nanmax(both, axis=0)
    # true proportions, except that a flat axis (a planar path, a vertical stroke) keeps half of the
    # widest span: a narrower box crowds its tick labels and pushes the axis labels out of the figure
    span = np.maximum(hi - lo, 0.5 * max(float((hi - lo).max()), 1e-6))
    # start and end: a hollow circle and a cross, both visible when the path is closed
    closed = float(np.linalg.norm(act_mm[-1] - act_mm[0])) < 0.01 * float(span.max())
    ax.scatter(*act_mm[0], s=90, facecolors="none", edgecolors="tab:green", linewidths=1.8, depthshade=False,
               label=f"start (t = {p.t[0]:.3g} s)")
    ax.scatter(*act_mm[-1], s=45, color="k", marker="x", linewidths=1.8, depthshade=False,
               label=f"end (t = {p.t[-1]:.3g} s)" + (", back at the start" if closed else ""))
    mid = 0.5 * (lo + hi)
    ax.set_xlim(mid[0] - span[0] / 2, mid[0] + span[0] / 2)
    ax.set_ylim(mid[1] - span[1] / 2, mid[1] + span[1] / 2)
    ax.set_zlim(mid[2] - span[2] / 2, mid[2] + span[2] / 2)
    ax.set_box_aspect(span.copy(), zoom=0.9)  # a copy: matplotlib scales it in place
    for j, (axis, label) in enumerate(zip((ax.xaxis, ax.yaxis, ax.zaxis), AXES)):
        # ticks in proportion to the axis's length on screen, so that narrow axes' labels do not overlap
        axis.set_major_locator(MaxNLocator(max(1, round(5 * span[j] / span.max())), steps=[1, 2, 2.5, 5, 10]))
        fmt = ScalarFormatter(useOffset=False)
        fmt.set_scientific(False)
        axis.set_major_formatter(fmt)
        axis.set_label_text(f"{label} (mm)")
        axis.labelpad = 12  # clear of the tick labels
    err = float(np.nanmax(np.abs(p.error)))
    hint = ", not visible at this scale" if err * 1e3 < 0.005 * span.max() else ""
    fig.suptitle(f"{title}: platform path, desired vs actual\n(largest position error {_auto(err, p.unit)}{hint}; "
                 "see errors.png)", fontsize=10)
    ax.legend(loc="upper left", fontsize=8)
    path = out / "path_3d.png"
    return _save(fig, path)


def _mark_events(tr: Tracking, axs) -> None:
    """A dotted vertical line at each scenario event of the run (the log's /events channel, fields t and event;
    a model-exchange component's own events are not drawn), labelled with its index (#0, #1, ...) on the top axis."""
    fired = [e for e in tr.run.events if "event" in e]
    if not fired:
        return
    axs = list(np.ravel(axs))
    for ax in axs:
        for e in fired:
            ax.axvline(float(e["t"]), color="0.35", lw=0.8, ls=":", zorder=0)
    top = axs[0]
    for e in fired:
        top.annotate(f"#{e['event']}", (float(e["t"]), 1.0), xycoords=("data", "axes fraction"),
                     xytext=(2, -2), textcoords="offset points", fontsize=7, color="0.3", va="top")


def _plot_position(tr: Tracking, title: str, out: Path) -> Path:
    p = tr.position
    n = len(tr.axes)
    fig = _fig(9, 2.2 * n + 1.0)
    axs = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    f, unit = (1e3, "mm") if p.unit == "m" else (1.0, _pretty_unit(p.unit))
    _values_column(axs, p, f, unit, tr.axes)
    _mark_events(tr, axs)
    axs[-1].set_xlabel("time (s)")
    names = (p.reference_names[0][:-2], p.actual_names[0][:-2]) if tr.is_platform else ("reference", "actual")
    axs[0].legend(axs[0].lines, [f"desired ({names[0]})", f"actual ({names[1]})"], loc="lower center",
                  bbox_to_anchor=(0.5, 1.0), ncol=2, fontsize=8, frameon=False)
    fig.suptitle(f"{title}: platform position, desired vs actual")
    path = out / "position.png"
    return _save(fig, path)


_FLAT = 0.05  # an axis whose values span less than this share of the widest axis's span is drawn at that share


def _values_column(axs, pair: Pair, f: float, unit: str, labels: Sequence[str]) -> None:
    """Reference (wide, pale) and actual (thin) values per row, ``f`` times the logged unit.

    A coordinate that barely moves (the x and y of a vertical z-steps motion, constant up to
    rounding) gets the same minimum span as a share of the widest one, so it reads as the
    flat line it is rather than as its rounding noise magnified.
    """
    both = np.concatenate([pair.reference, pair.actual]) * f
    spans = np.nanmax(both, axis=0) - np.nanmin(both, axis=0)
    least = _FLAT * float(np.nanmax(spans)) if np.isfinite(spans).any() else 0.0
    for j, ax in enumerate(axs):
        ax.plot(pair.t, pair.reference[:, j] * f, color="tab:blue", lw=2.5, alpha=0.45)
        ax.plot(pair.t, pair.actual[:, j] * f, color="tab:red", lw=0.9)
        if least > 0 and spans[j] < least:
            mid = 0.5 * (np.nanmax(both[:, j]) + np.nanmin(both[:, j]))
            ax.set_ylim(mid - 0.6 * least, mid + 0.6 * least)
        ax.set_ylabel(f"{labels[j]} ({unit})")
        _plain(ax)
        ax.grid(True, alpha=0.3)


_ROUNDING = 1e-12  # m or m/s: below this an error is floating-point rounding of positions of order 0.1-1 m
_OFF_SCALE = 4.0  # a peak this many times the 0.5..99.5 percentile band is drawn off scale (a start transient)


def _error_column(axs, pair: Pair, stats: list[ErrorStats], axes: list[str], what: str) -> None:
    e = pair.error
    colors = ("tab:red", "tab:green", "tab:blue")
    for j, (ax, st) in enumerate(zip(axs, stats)):
        col = e[:, j]
        lo, hi = np.nanpercentile(col, [0.5, 99.5]) if np.isfinite(col).any() else (0.0, 0.0)
        band = max(abs(lo), abs(hi))
        clipped = band > 0 and st.max_error > _OFF_SCALE * band
        f, unit = _scaled_unit(np.array([band if clipped else st.max_error]), pair.unit)
        unit = _pretty_unit(unit)
        k = int(np.searchsorted(pair.t, st.t_max))
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.plot(pair.t, col * f, color=colors[j % 3], lw=0.9)
        ax.set_ylabel(f"e_{axes[j]} ({unit})")
        _plain(ax)
        ax.set_title(f"{what} {axes[j]}: RMSE {_auto(st.rmse, pair.unit)}, max |e| {_auto(st.max_error, pair.unit)} "
                     f"at {st.t_max:.3g} s" + (" (rounding level)" if st.max_error < _ROUNDING and pair.unit in
                                              ("m", "m/s") else ""), fontsize=9)
        if clipped:
            lo, hi = min(lo, 0.0), max(hi, 0.0)
            pad = 0.15 * (hi - lo)
            ax.set_ylim((lo - pad) * f, (hi + pad) * f)
            peak = ("-" if col[k] < 0 else "") + _auto(abs(col[k]), pair.unit)
            ax.text(0.99, 0.04, f"off scale: {peak} at {st.t_max:.3g} s", transform=ax.transAxes, ha="right",
                    va="bottom", fontsize=8, bbox=dict(boxstyle="round", fc="w", ec="0.6", alpha=0.9))
        else:
            ax.plot([st.t_max], [col[k] * f], "kx", ms=6)
        ax.grid(True, alpha=0.3)
    axs[-1].set_xlabel("time (s)")


def _plot_errors(tr: Tracking, title: str, out: Path) -> Path:
    n = len(tr.axes)
    cols = 2 if tr.velocity is not None else 1
    fig = _fig(6.5 * cols, 2.2 * n + 0.8)
    axs = fig.subplots(n, cols, sharex=True, squeeze=False)
    _error_column(axs[:, 0], tr.position, tr.position_stats(), tr.axes, "position error")
    if tr.velocity is not None:
        _error_column(axs[:, 1], tr.velocity, tr.velocity_stats(), tr.axes, "velocity error")
    _mark_events(tr, axs)
    note = "" if tr.velocity is not None else " (no velocity signals logged)"
    fig.suptitle(f"{title}: tracking error, actual - desired{note}")
    path = out / "errors.png"
    return _save(fig, path)


def _plot_joints(tr: Tracking, title: str, out: Path) -> Path | None:
    """Joint space: q against q_ref per joint (left) and the error q - q_ref (right)."""
    q = tr.joints
    if q is None:
        return None
    fig = _fig(13, 7.4)
    axs = fig.subplots(3, 2, sharex=True, squeeze=False)
    f, unit = {"m": (1e3, "mm"), "rad": (180.0 / math.pi, "deg")}.get(q.unit, (1.0, _pretty_unit(q.unit)))
    _values_column(axs[:, 0], q, f, unit, _JOINTS)
    for j, ax in enumerate(axs[:, 0]):
        ax.set_title(f"joint {j + 1}: {q.reference_names[j]} (desired) vs {q.actual_names[j]} (actual)", fontsize=9)
    axs[-1, 0].set_xlabel("time (s)")
    axs[0, 0].legend(axs[0, 0].lines[:2], ["desired", "actual"], loc="best", fontsize=8)
    _error_column(axs[:, 1], q, tr.joint_stats(), _JOINTS, "joint error")
    _mark_events(tr, axs)
    kind = {"m": "carriage travel", "rad": "arm angle"}.get(q.unit, "joint value")
    fig.suptitle(f"{title}: joint-space tracking ({kind}), desired vs actual and error")
    path = out / "joints.png"
    return _save(fig, path)


def _plot_efforts(tr: Tracking, title: str, out: Path) -> Path | None:
    if tr.efforts is None:
        return None
    names, unit, t, u = tr.efforts
    fig = _fig(9, 2.0 * len(names) + 0.8)
    axs = fig.subplots(len(names), 1, sharex=True, sharey=True, squeeze=False)[:, 0]
    colors = ("tab:blue", "tab:orange", "tab:green")
    for j, (ax, name) in enumerate(zip(axs, names)):
        ax.plot(t, u[:, j], lw=1.0, color=colors[j % 3])
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.set_ylabel(f"{name.split('.', 1)[1]} ({_pretty_unit(unit)})")
        _plain(ax)
        ax.set_title(f"{name} (leg {j + 1}): range {np.nanmin(u[:, j]):.3g} .. {np.nanmax(u[:, j]):.3g} "
                     f"{_pretty_unit(unit)}", fontsize=9)
        ax.grid(True, alpha=0.3)
    _mark_events(tr, axs)
    axs[-1].set_xlabel("time (s)")
    fig.suptitle(f"{title}: actuator efforts")
    path = out / "efforts.png"
    return _save(fig, path)


# --------------------------------------------------------------------------- report


@dataclass
class Report:
    """Files written for one run and the numbers in them."""

    run: str  # the log's path
    name: str
    robot: str | None
    status: str
    duration: float  # s simulated (last - first stamp)
    out_dir: Path
    markdown: Path
    figures: dict[str, Path]
    position: list[ErrorStats]
    velocity: list[ErrorStats] = field(default_factory=list)
    source: str = ""
    joints: list[ErrorStats] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        def axes(stats: list[ErrorStats]) -> list[dict[str, Any]]:
            return [s.as_dict(*_AXIS_KEYS, name="axis") for s in stats]

        return {"run": self.run, "name": self.name, "robot": self.robot, "status": self.status,
                "duration_s": self.duration, "out_dir": str(self.out_dir), "markdown": str(self.markdown),
                "figures": {k: str(v) for k, v in self.figures.items()}, "compared": self.source,
                "position": axes(self.position), "velocity": axes(self.velocity), "joints": axes(self.joints)}


# one axis in ``report --json`` (its keys since the first release: name as axis; no tolerance)
_AXIS_KEYS = ("name", "actual", "reference", "unit", "rmse", "max_error", "t_max", "samples")


def _stats_table(stats: list[ErrorStats], unit: str) -> list[str]:
    """Markdown rows; lengths (m, m/s) also in um (um/s), other units as logged."""
    micro = unit in ("m", "m/s")
    u, small = unit or "-", f"u{unit}" if micro else unit or "-"
    rows = [f"| axis | actual - reference | RMSE ({u}) |" + (f" RMSE ({small}) |" if micro else "")
            + f" max abs error ({small}) | at t (s) |", "|---|---|---|" + ("---|" if micro else "") + "---|---|"]
    scale = 1e6 if micro else 1.0
    for s in stats:
        rows.append(f"| {s.name} | {s.actual} - {s.reference} | {s.rmse:.6e} |"
                    + (f" {s.rmse * scale:.4g} |" if micro else "") + f" {s.max_error * scale:.4g} | {s.t_max:.4g} |")
    return rows


def _markdown(tr: Tracking, rep: Report) -> str:
    run = tr.run
    sc = run.metadata.get("scenario", {})
    outcome = run.metadata.get("outcome", {})
    att, doc = _scenario_doc(run)
    p = tr.position
    lines = [f"# Run report: {rep.name}", ""]
    desc = doc.get("description")
    if desc:
        lines += [str(desc), ""]
    status = rep.status
    if outcome.get("completed_steps"):
        status += f", {outcome['completed_steps']} steps"
    if outcome.get("message"):
        status += f": {outcome['message']}"
    step = sc.get("step_s")
    rows = [("scenario", f"{rep.name}" + (f" (`{sc['file']}`)" if sc.get("file") else "")),
            ("robot", rep.robot or "-"),
            ("status", status),
            ("simulated", f"{p.t[0]:.6g} .. {p.t[-1]:.6g} s ({rep.duration:.6g} s"
                          + (f", step {float(step) * 1e3:.6g} ms" if step else "") + f", {len(p.t)} samples)"),
            ("log", f"`{run.path}`"),
            ("compared", f"{', '.join(p.actual_names)} vs {', '.join(p.reference_names)} ({tr.source})")]
    lines += ["| | |", "|---|---|"] + [f"| {k} | {v} |" for k, v in rows] + [""]
    lines += ["## Position error" if tr.is_platform else "## Error", "",
              f"Error = actual - reference at the {len(p.t)} time stamps both carry (the start sample and every "
              "step, as in the run's summary).", ""]
    lines += _stats_table(rep.position, p.unit) + [""]
    if rep.velocity:
        lines += ["## Velocity error", ""] + _stats_table(rep.velocity, tr.velocity.unit) + [""]
    if rep.joints:
        lines += ["## Joint error", ""] + _stats_table(rep.joints, tr.joints.unit) + [""]
    lines += ["## Figures", ""]
    captions = {"path_3d": "Platform path, desired vs actual", "position": "Position, desired vs actual",
                "errors": "Position and velocity errors", "joints": "Joint-space tracking, desired vs actual",
                "efforts": "Actuator efforts"}
    for key, path in rep.figures.items():
        lines += [f"### {captions.get(key, key)}", "", f"![{captions.get(key, key)}]({path.name})", ""]
    if tr.efforts is None:
        lines += ["No actuator efforts (`u[1..3]`) in the log.", ""]
    return "\n".join(lines)


def make_report(run: RunLog | str | Path, out_dir: str | Path | None = None) -> Report:
    """Write the figures and ``report.md`` of one run; return what was written.

    Parameters
    ----------
    run
        A run log path (MCAP written by :mod:`cosim.observers.mcap_log`) or a :class:`RunLog`.
    out_dir
        Where to write (created); default ``<log stem>_report/`` next to the log.

    Raises
    ------
    CosimError
        The log cannot be read; ReportError when a compared signal is missing (named).
    """
    tr = tracking(run)
    log = tr.run
    out = output_dir(Path(out_dir) if out_dir is not None else log.path.with_name(f"{log.path.stem}_report"))
    title = log.name
    figures: dict[str, Path] = {}
    if tr.is_platform:
        figures["path_3d"] = _plot_path(tr, title, out)
    figures["position"] = _plot_position(tr, title, out)
    figures["errors"] = _plot_errors(tr, title, out)
    joints = _plot_joints(tr, title, out)
    if joints is not None:
        figures["joints"] = joints
    eff = _plot_efforts(tr, title, out)
    if eff is not None:
        figures["efforts"] = eff
    p = tr.position
    rep = Report(str(log.path), title, log.robot, log.status, float(p.t[-1] - p.t[0]), out, out / "report.md",
                 figures, tr.position_stats(), tr.velocity_stats(), tr.source, tr.joint_stats())
    with written_by_rename(rep.markdown) as tmp:
        tmp.write_text(_markdown(tr, rep))
    return rep


def _save(fig, path: Path) -> Path:
    """``fig`` as the PNG ``path``, written by rename (never half a figure there)."""
    with written_by_rename(path) as tmp:
        fig.savefig(tmp, format="png")
    return path


# --------------------------------------------------------------------------- controller table


@dataclass(frozen=True)
class TableRow:
    """One row: a run's RMSE per axis (m), or the thesis's (``source`` says which)."""

    label: str
    controller: str
    plant: str
    rmse: tuple[float, float, float]  # m, x y z
    source: str  # the log's path, or _THESIS_SOURCE
    samples: int = 0

    @property
    def from_thesis(self) -> bool:
        return self.source == _THESIS_SOURCE


def _fmt_m(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{x:.3e}"


def _fmt_um(x: float) -> str:
    if not math.isfinite(x):
        return "-"
    v = x * 1e6
    return f"{v:.0f}" if v >= 100 else f"{v:.1f}" if v >= 10 else f"{v:.2f}" if v >= 0.1 else f"{v:.3g}"


@dataclass
class Table:
    """RMSE per axis per run (thesis Table 5 layout: rows = runs, columns x, y, z)."""

    rows: list[TableRow]

    def markdown(self, units: Sequence[str] = ("m", "um")) -> str:
        """The table in markdown; ``units`` picks the column groups, any of ``"m"`` and ``"um"``."""
        bad = [u for u in units if u not in ("m", "um")]
        if bad or not units:
            raise ReportError(f"table units must be among m, um; got {', '.join(bad) or 'none'}")
        head = ["run", "controller", "plant"] + [f"{a} ({u})" for u in units for a in AXES]
        out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for r in self.rows:
            cells = [f"**{r.label}**" if r.from_thesis else r.label, r.controller, r.plant]
            for u in units:  # the thesis's values as printed there; ours to 4 significant digits
                fmt = (lambda v: f"{v:g}") if r.from_thesis and u == "m" else _fmt_m if u == "m" else _fmt_um
                cells += [fmt(v) for v in r.rmse]
            out.append("| " + " | ".join(cells) + " |")
        notes = ["", "RMSE of the platform position, actual - reference, over the start sample and every step "
                     "of each run (as in the run's summary)."]
        if any(r.from_thesis for r in self.rows):
            notes.append(f"Rows in bold are not computed here: they are the values printed in {_THESIS_SOURCE}.")
        return "\n".join(out + notes)

    def as_dict(self) -> dict[str, Any]:
        return {"rows": [{"label": r.label, "controller": r.controller, "plant": r.plant, "source": r.source,
                          "from_thesis": r.from_thesis, "samples": r.samples,
                          "rmse_m": dict(zip(AXES, r.rmse))} for r in self.rows]}


def _describe(run: RunLog, actual_component: str) -> tuple[str, str, bool]:
    """(controller, plant, is the thesis helix) from the attached scenario."""
    _, doc = _scenario_doc(run)
    comps = doc.get("components") or {}
    controller, plant, default_helix = "-", actual_component, False
    for name, c in comps.items():
        if not isinstance(c, dict):
            continue
        fmu = str(c.get("fmu") or c.get("path") or "")
        entry = registry.REGISTRY.get(fmu)
        if entry is not None and entry.role == "controller":
            controller = entry.label
        if name == actual_component and fmu:
            fidelity = (c.get("parameters") or {}).get("model.fidelity")
            plant = fmu + (f" ({fidelity})" if fidelity else "")
        if fmu == "helix" and not c.get("parameters"):
            default_helix = True
    return controller, plant, default_helix and run.robot == _THESIS_ROBOT


def controller_table(paths: Sequence[str | Path | RunLog], thesis: bool | None = None) -> Table:
    """RMSE per axis of each run (platform position vs reference), in thesis Table 5's layout.

    Parameters
    ----------
    paths
        Run logs (paths or :class:`RunLog`), one row each, in order.
    thesis
        Append the thesis's Table 5 rows for the controllers among the thesis-helix runs (all
        three when none of them is PD, PID or CTC). ``None`` (default): when at least one run is
        the thesis helix (the default helix on ``linear_delta_thesis``).

    Raises
    ------
    CosimError
        A log cannot be read or lacks its compared signals; ReportError when a run's compared
        signals are not a platform vector x, y, z.
    """

    if not paths:
        raise ReportError("controller table: no run logs given")
    rows: list[TableRow] = []
    helix_controllers: list[str] = []
    for item in paths:
        tr = tracking(item)
        if not tr.is_platform:
            raise ReportError(f"{tr.run.path}: the table needs a platform vector x, y, z; the run compares "
                              f"{', '.join(tr.position.actual_names)}")
        controller, plant, is_helix = _describe(tr.run, tr.position.actual_names[0].split(".", 1)[0])
        if is_helix:
            helix_controllers.append(controller)
        st = tr.position_stats()
        rows.append(TableRow(tr.run.name, controller, plant, tuple(s.rmse for s in st), str(tr.run.path),
                             st[0].samples))
    if thesis is None:
        thesis = bool(helix_controllers)
    if thesis:
        labels = {e.variant: e.label for e in registry.find("controller") if e.variant in THESIS_TABLE_5_M}
        wanted = [k for k, label in labels.items() if label in helix_controllers]
        for key in wanted or list(labels):
            rows.append(TableRow(f"thesis Table 5, {labels[key]}", labels[key], "ADAMS prototype",
                                 tuple(THESIS_TABLE_5_M[key]), _THESIS_SOURCE))
    return Table(rows)


# --------------------------------------------------------------------------- CLI


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``report`` and ``table`` commands to the platform CLI."""
    p = subparsers.add_parser("report", help="figures and a markdown summary of a run log")
    p.add_argument("run", help="run log (MCAP written by `python -m cosim run`)")
    p.add_argument("--out", default=None, help="output directory (default <log stem>_report/ next to the log)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(handler=_cmd_report)
    p = subparsers.add_parser("table", help="RMSE per axis per run, as thesis Table 5 (markdown)")
    p.add_argument("runs", nargs="+", help="run logs, one row each")
    p.add_argument("--units", choices=("both", "m", "um"), default="both", help="RMSE columns (default both)")
    p.add_argument("--thesis", action=argparse.BooleanOptionalAction, default=None,
                   help="add thesis Table 5 rows (default: when a run is the thesis helix)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(handler=_cmd_table)


def _cmd_report(args: argparse.Namespace) -> int:
    rep = make_report(args.run, args.out)
    if args.json:
        print(json.dumps(rep.as_dict(), indent=2))
        return 0
    print(f"{rep.name}: {rep.status}, {rep.duration:.6g} s simulated -> {rep.markdown}")
    for s in rep.position:
        print(f"  {s.name}: RMSE {s.rmse:.4e} {s.unit}, max |e| {s.max_error:.4e} {s.unit} at t = {s.t_max:.4g} s")
    print("  figures: " + ", ".join(p.name for p in rep.figures.values()))
    return 0


def _cmd_table(args: argparse.Namespace) -> int:
    table = controller_table(args.runs, args.thesis)
    if args.json:
        print(json.dumps(table.as_dict(), indent=2))
    else:
        print(table.markdown(("m", "um") if args.units == "both" else (args.units,)))
    return 0
