"""``sweep-report``: a figure of a sweep's metric against its swept parameters (:func:`report`)."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import file_problem, written_by_rename
from ..io.output import check_output
from .cases import SweepError
from .results import RESULTS, WARM_COLUMNS, read_results

__all__ = ["report"]


def _sweep_meta(out: Path, rows: list[dict[str, str]]) -> dict:
    """The sweep.json of the sweep in ``out``, its ``parameters`` (those it swept) each a column of ``rows`` (its
    results.csv)."""
    meta_path = out / "sweep.json"
    meta = {}
    if os.path.lexists(meta_path):
        problem = file_problem(meta_path)
        if problem is not None:
            # Refused (security): a FIFO or a device named as sweep.json would be read for ever
            raise SweepError(f"{meta_path}: {problem}")
        try:
            meta = json.loads(meta_path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
            # Refused (correctness): the sweep's description cannot be read: columns would be a guess
            raise SweepError(f"{meta_path}: not the sweep's JSON ({str(exc)[:120]})") from None
    params = meta.get("parameters") if isinstance(meta, dict) else None
    if not params or not isinstance(params, list) or not all(isinstance(p, str) and p in rows[0] for p in params):
        # Refused (correctness): the sweep's description cannot be read: columns would be a guess
        raise SweepError(f"{meta_path}: missing or without parameters (the columns of results.csv "
                         "it swept); it is written by the sweep next to results.csv")
    return meta


def report(out: str | Path, metric: str = "rmse", fig: str | Path | None = None) -> Path:
    """A figure of ``metric`` over the swept parameters of ``out/results.csv``: a line against one
    parameter (several lines when a second one has few values), a heatmap against two (a scatter
    for random draws). Failed cases are left out (and counted in the title). Returns the PNG path."""
    import matplotlib  # lazy: --help loads this module without it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: --help loads this module without it

    rows = read_results(out)
    if not rows:
        # Refused (correctness): no results: nothing to report
        raise SweepError(f"{Path(out) / RESULTS}: no results")
    meta = _sweep_meta(Path(out), rows)
    params = meta["parameters"]
    if metric not in rows[0]:
        valid = [c for c in rows[0] if c not in ("case", "status", "checks", "mcap", "message", *WARM_COLUMNS,
                                                 *params)]
        # Refused (correctness): a metric the table does not have
        raise SweepError(f"--metric {metric}: not a column; valid: {', '.join(valid)}")
    ok = [r for r in rows if r["status"] == "ok"]
    n_bad = len(rows) - len(ok)
    swept = [p for p in params if len({r[p] for r in rows}) > 1] or params[:1]
    fig_path = Path(fig) if fig is not None else Path(out) / f"sweep_{metric}.png"
    check_output(fig_path, (Path(out) / RESULTS,))  # a regular file or nothing, never a FIFO, a device or the table
    try:
        y = np.array([float(r[metric]) for r in ok])
    except (TypeError, ValueError):
        bad = next(r for r in ok if not _is_number(r[metric]))
        # Refused (correctness): a value that is no number would be plotted as a made-up one
        raise SweepError(f"{Path(out) / RESULTS}: case {bad['case']}: {metric} = {bad[metric]!r} is not a "
                         "number") from None
    f, ax = plt.subplots(figsize=(6.4, 4.6), layout="constrained")

    def axis(name: str) -> tuple[np.ndarray, list[str]]:
        """Numbers, or the positions of list values (``[1e4, 1e4, 1e4]``) ordered by their first element."""
        cells = [r[name] for r in ok]
        try:
            return np.array([float(c) for c in cells]), []
        except ValueError:
            labels = sorted(set(cells), key=_first_element)
            return np.array([labels.index(c) for c in cells], dtype=float), [_short(c) for c in labels]

    if len(swept) == 1:
        x, labels = axis(swept[0])
        order = np.argsort(x)
        ax.plot(x[order], y[order], "o-")
        if labels:
            ax.set_xticks(range(len(labels)), labels)
        ax.set_xlabel(swept[0])
        ax.set_ylabel(metric)
    else:
        a, b = swept[:2]
        (xa, la), (xb, lb) = axis(a), axis(b)
        ua, ub = np.unique(xa), np.unique(xb)
        if len(ua) * len(ub) == len(ok):  # a full grid: heatmap
            grid = np.full((len(ub), len(ua)), np.nan)
            for va, vb, v in zip(xa, xb, y):
                grid[np.searchsorted(ub, vb), np.searchsorted(ua, va)] = v
            finite = grid[np.isfinite(grid)]
            log = finite.size and finite.min() > 0 and finite.max() > 100 * finite.min()
            from matplotlib.colors import LogNorm  # lazy: --help loads this module without it

            im = ax.imshow(grid, origin="lower", aspect="auto", cmap="viridis", norm=LogNorm() if log else None)
            ax.set_xticks(range(len(ua)), la or [f"{v:g}" for v in ua])
            ax.set_yticks(range(len(ub)), lb or [f"{v:g}" for v in ub])
            for i in range(len(ub)):
                for j in range(len(ua)):
                    if not math.isnan(grid[i, j]):
                        ax.text(j, i, f"{grid[i, j]:.3g}", ha="center", va="center", color="w", fontsize=8)
        else:
            im = ax.scatter(xa, xb, c=y, cmap="viridis")
        f.colorbar(im, ax=ax, label=metric)
        ax.set_xlabel(a)
        ax.set_ylabel(b)
    scenario = Path(meta.get("scenario", "")).stem
    warm = meta.get("warm_start")
    start = ""
    if isinstance(warm, dict) and _is_number(warm.get("time")):  # a warm sweep: its metrics are those after the start
        start = f"\nwarm-started at t = {float(warm['time']):g} s from {Path(str(warm.get('checkpoint', ''))).name}"
    ax.set_title(f"{scenario}: {metric}, {len(ok)} cases" + (f" ({n_bad} failed, not shown)" if n_bad else "") + start,
                 fontsize="medium" if start else None)
    try:
        with written_by_rename(fig_path) as tmp:
            f.savefig(tmp, dpi=120, format="png")
    except OSError as exc:
        # Refused (correctness): the figure could not be written whole
        raise SweepError(f"{fig_path}: cannot write the figure: {exc.strerror or exc}") from None
    finally:
        plt.close(f)
    return fig_path


def _is_number(cell: Any) -> bool:
    try:
        float(cell)
    except (TypeError, ValueError):
        return False
    return True


def _first_element(cell: str) -> tuple:
    """The order of list values (``[1e4, 1e4, 1e4]``) by their first element; other text after them, as text."""
    try:
        first = json.loads(cell)[0] if cell.startswith("[") else None
        return (0, float(first), "") if first is not None else (1, 0.0, cell)
    except (ValueError, TypeError, IndexError, KeyError, RecursionError):
        return (1, 0.0, cell)


def _short(cell: str) -> str:
    """A list value as a tick label: ``[2500.0, 2500.0, 2500.0]`` -> ``2500 (x3)``."""
    try:
        values = json.loads(cell)
    except (ValueError, RecursionError):
        return cell
    if isinstance(values, list) and values and len(set(map(str, values))) == 1:
        return f"{values[0]:g} (x{len(values)})" if isinstance(values[0], (int, float)) else cell
    return cell
