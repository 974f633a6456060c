"""A sweep's table, ``DIR/results.csv`` (one row per case, see :mod:`cosim.analysis.sweep`), and its description
``DIR/sweep.json`` (the scenario, the swept parameters, a warm sweep's start)."""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path
from typing import Any

from ..errors import file_problem
from .cases import SweepError

__all__ = ["RESULTS", "WARM_COLUMNS", "cell", "read_meta", "read_results", "started", "table_columns"]

RESULTS = "results.csv"
WARM_COLUMNS = ("start_time_s", "checkpoint")
"""The columns a warm sweep's table has besides a cold one's: the checkpoint's time, s, and its path."""


def read_results(out: str | Path) -> list[dict[str, str]]:
    """The rows of ``out/results.csv`` (strings, as written)."""
    path = Path(out) / RESULTS
    if not os.path.lexists(path):
        return []
    problem = file_problem(path)  # a directory, or a FIFO read for ever
    if problem is not None:
        # Refused (security): a FIFO or a device named as a results table would be read for ever
        raise SweepError(f"{path}: {problem}; use another --out")
    try:
        with path.open(newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        # Refused (correctness): another file: its rows would be taken as this sweep's cases
        raise SweepError(f"{path}: not a sweep's results table ({exc}); use another --out") from None
    if rows and (None in rows[0] or not {"case", "status"} <= set(rows[0])):
        # Refused (correctness): another file: its rows would be taken as this sweep's cases
        raise SweepError(f"{path}: not a sweep's results table (no case and status columns); use another --out")
    return rows


def table_columns(params: list[str], metric_names: list[str], warm: bool = False) -> list[str]:
    return ["case", "status", *params, *metric_names, *(WARM_COLUMNS if warm else ()), "checks", "mcap", "message"]


def read_meta(out: Path) -> dict[str, Any]:
    """``out/sweep.json`` as written by an earlier sweep; {} when it is missing or unreadable."""
    path = out / "sweep.json"
    if not os.path.lexists(path) or file_problem(path) is not None:
        return {}
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        return {}
    return meta if isinstance(meta, dict) else {}


def started(record: Any) -> str:
    """The start a ``sweep.json``'s ``warm_start`` record names, in words."""
    if isinstance(record, dict) and {"checkpoint", "time", "stop_time"} <= set(record):
        return f"warm-started from {record['checkpoint']} at t = {record['time']} s to {record['stop_time']} s"
    return "its sweep.json names no warm start"


def cell(v: Any) -> str:
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, dict)):
        return json.dumps(v)
    return "" if v is None else str(v)
