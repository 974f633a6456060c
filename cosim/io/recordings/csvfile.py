"""CSV recordings: a time column and named, unit-annotated columns.

The format (docs/recordings.md): lines starting with ``#`` are comments (a header citing the source, say), blank
lines are skipped; the first other line names the columns, comma-separated; a column's unit follows its name
after a space in square brackets (``q1 [deg]``, ``ctl.q[1] [rad]``: brackets right after a name are part of it).
The time column is the one named ``time``, ``Time`` or ``t`` (its unit, default s, may be ms, us, ns), else the
first column. What ``python -m cosim export --csv`` writes reads back as it is.
"""

from __future__ import annotations

import csv
import difflib
import math
import re
from pathlib import Path
from typing import Mapping

import numpy as np

from .errors import RecordingError
from .units import unit_factor

__all__ = ["read_csv", "column_header", "split_header"]

_UNIT = re.compile(r"^(.*\S)\s+\[([^\]]*)\]$")
TIME_NAMES = ("time", "t")


def split_header(cell: str) -> tuple[str, str]:
    """``"q1 [deg]"`` -> ("q1", "deg"); ``"ctl.q[1]"`` -> ("ctl.q[1]", "")."""
    cell = cell.strip()
    m = _UNIT.match(cell)
    return (m.group(1), m.group(2).strip()) if m else (cell, "")


def column_header(name: str, unit: str) -> str:
    """The header cell :func:`split_header` reads back: ``name [unit]``, or the name alone."""
    return f"{name} [{unit}]" if unit else name


def read_csv(path: Path, names: Mapping[str, str]) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, str]]:
    """(times s (n,), values by name (n,), units by name) of the columns ``names`` maps to (name -> column).

    One line naming the file and line for: no header, an unknown column (with the closest), a row of another
    length, a cell that is not a number, a time unit that is not one."""
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = [(i, r) for i, r in enumerate(csv.reader(f), start=1)
                    if r and not r[0].lstrip().startswith("#") and any(c.strip() for c in r)]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        # Refused (correctness): nothing of the file can be read
        raise RecordingError(f"{path}: cannot read the CSV file: {exc}") from None
    if not rows:
        # Refused (correctness): no column names: which column is which would be a guess
        raise RecordingError(f"{path}: no header line (the column names, e.g. time [s],q1 [rad])")
    head_line, head = rows[0]
    cols = [split_header(c) for c in head]
    labels = [c[0] for c in cols]
    time_col = next((i for i, (n, _) in enumerate(cols) if n.lower() in TIME_NAMES), 0)
    t_unit = cols[time_col][1] or "s"
    t_factor = unit_factor(t_unit, "s", f"{path}:{head_line}: time column {labels[time_col]!r}")
    index: dict[str, int] = {}
    for name, column in names.items():
        if column not in labels:
            close = difflib.get_close_matches(column, labels, n=2)
            hint = f"; did you mean {' or '.join(close)}?" if close else ""
            # Refused (correctness): a signal asked for is not in the file
            raise RecordingError(f"{path}:{head_line}: no column {column!r}{hint} (columns: {', '.join(labels)})")
        index[name] = labels.index(column)
    data = np.empty((len(rows) - 1, len(cols)))
    for k, (line, row) in enumerate(rows[1:]):
        if len(row) != len(cols):
            # Refused (correctness): a row of another width: which cell is which column would be a guess
            raise RecordingError(f"{path}:{line}: {len(row)} cells where the header names {len(cols)} columns")
        for j, cell in enumerate(row):
            try:
                data[k, j] = float(cell)
            except ValueError:
                data[k, j] = math.nan if cell.strip().lower() == "nan" else _bad_cell(path, line, labels[j], cell)
    times = data[:, time_col] * t_factor
    return times, {n: data[:, j] for n, j in index.items()}, {n: cols[j][1] for n, j in index.items()}


def _bad_cell(path: Path, line: int, column: str, cell: str) -> float:
    shown = cell if len(cell) <= 40 else cell[:40] + "..."
    # Refused (correctness): a cell that is no number would be replayed as a made-up value
    raise RecordingError(f"{path}:{line}: column {column!r}: {shown!r} is not a number")
