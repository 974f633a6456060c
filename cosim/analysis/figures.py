"""The figures of a run report (:mod:`cosim.analysis.report`): the platform path in 3D, position, errors, joints and
efforts over time, each a PNG written by rename; values scaled to read as 1..1000 with plain tick labels."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import written_by_rename
from ..io.runlog import AXES
from ..observers.stats import ErrorStats
from .tracking import JOINTS, Pair, Tracking

__all__ = ["figures"]

_DPI = 120


def figures(tr: Tracking, title: str, out: Path) -> dict[str, Path]:
    """Every figure ``tr`` has data for, written into ``out``: name (``path_3d``, ``position``, ``errors``,
    ``joints``, ``efforts``) -> PNG path."""
    written: dict[str, Path] = {}
    if tr.is_platform:
        written["path_3d"] = _plot_path(tr, title, out)
    written["position"] = _plot_position(tr, title, out)
    written["errors"] = _plot_errors(tr, title, out)
    joints = _plot_joints(tr, title, out)
    if joints is not None:
        written["joints"] = joints
    eff = _plot_efforts(tr, title, out)
    if eff is not None:
        written["efforts"] = eff
    return written


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
    _values_column(axs[:, 0], q, f, unit, JOINTS)
    for j, ax in enumerate(axs[:, 0]):
        ax.set_title(f"joint {j + 1}: {q.reference_names[j]} (desired) vs {q.actual_names[j]} (actual)", fontsize=9)
    axs[-1, 0].set_xlabel("time (s)")
    axs[0, 0].legend(axs[0, 0].lines[:2], ["desired", "actual"], loc="best", fontsize=8)
    _error_column(axs[:, 1], q, tr.joint_stats(), JOINTS, "joint error")
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


def _save(fig, path: Path) -> Path:
    """``fig`` as the PNG ``path``, written by rename (never half a figure there)."""
    with written_by_rename(path) as tmp:
        fig.savefig(tmp, format="png")
    return path
