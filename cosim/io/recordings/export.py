"""A run's log exported for other tools: one CSV per component (as OSP's cosim-cli writes its results: a time
column in seconds first, then one column per variable; here with the unit in the header, ``q[1] [m]``) and one
Parquet table (``pyarrow``) of every signal.

CSV: ``DIR/<component>.csv``, header ``Time [s],<variable> [unit],...`` (no unit: the name alone), one row per
logged sample, numbers written with 17 significant digits (they read back exactly; :mod:`.csvfile` reads the
files as recordings). cosim-cli's ``StepCount`` column is left out: a log holds times, not step counts. A variable
that is an array of numbers gets one column per element, ``name[1]``...

Parquet: one table, a row per time stamp any component logged: ``time_ns`` (int64, exact), ``time`` (s) and one
column per signal ``component.variable`` (null where that component logged nothing at that time); each field's
metadata holds its ``unit`` and ``description``, the table's the log's path and scenario name.

Every file is written whole or not at all (:func:`cosim.errors.written_by_rename`)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ...errors import CosimError, written_by_rename
from ..output import check_output
from ..runlog import RunLog, Signal, read_run
from .csvfile import column_header

__all__ = ["export_csv", "export_parquet"]


def _columns(sig: Signal, variable: str) -> list[tuple[str, np.ndarray]]:
    """(header name, values) of one signal: an (n, count) array gives one column per element."""
    y = sig.y
    if y.ndim == 2:
        return [(f"{variable}[{k + 1}]", y[:, k]) for k in range(y.shape[1])]
    return [(variable, y)]


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, (float, np.floating)):
        return repr(float(value)) if np.isfinite(value) else str(float(value))
    return str(value)


def export_csv(log: RunLog | str | Path, out_dir: str | Path) -> list[Path]:
    """One CSV per component of ``log`` in ``out_dir`` (created if its parent exists); the files written."""
    log = log if isinstance(log, RunLog) else read_run(log)
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        # Refused (correctness): the output folder cannot be made there
        raise CosimError(f"--csv {out_dir}: is a file, not a folder")
    if not out_dir.parent.resolve().is_dir():
        # Refused (correctness): the output folder cannot be made there
        raise CosimError(f"--csv {out_dir}: no folder {out_dir.parent} to make it in")
    out_dir.mkdir(exist_ok=True)
    written = []
    for comp in log.components:
        sigs = {n.split(".", 1)[1]: s for n, s in log.signals.items() if n.split(".", 1)[0] == comp}
        t_ns = np.unique(np.concatenate([s.t_ns for s in sigs.values()]))
        header, cols = [column_header("Time", "s")], [t_ns * 1e-9]
        for variable, sig in sigs.items():
            for name, y in _columns(sig, variable):
                header.append(column_header(name, sig.unit))
                col = np.full(len(t_ns), None, dtype=object)  # None: no sample then (an empty cell)
                col[np.searchsorted(t_ns, sig.t_ns)] = y
                cols.append(col)
        target = out_dir / f"{comp}.csv"
        check_output(target, (log.path,))
        try:
            with written_by_rename(target) as tmp, open(tmp, "w", newline="", encoding="utf-8") as f:
                w = csv.writer(f)
                w.writerow(header)
                for row in zip(*cols):
                    w.writerow([_cell(v) for v in row])
        except OSError as exc:
            # Refused (correctness): the file could not be written whole
            raise CosimError(f"--csv: cannot write {target}: {exc.strerror or exc}") from None
        written.append(target)
    return written


def export_parquet(log: RunLog | str | Path, out: str | Path) -> Path:
    """Every numeric signal of ``log`` in one Parquet table at ``out`` (see the module docstring)."""
    import pyarrow as pa  # lazy: pyarrow's import is a second that the CSV export and --help never need
    import pyarrow.parquet as pq  # lazy: with pyarrow above

    log = log if isinstance(log, RunLog) else read_run(log)
    out = Path(out)
    if not out.parent.resolve().is_dir():
        # Refused (correctness): the output file cannot be made there
        raise CosimError(f"--parquet {out}: no folder {out.parent} to write it in")
    check_output(out, (log.path,))
    t_ns = np.unique(np.concatenate([s.t_ns for s in log.signals.values()]))
    fields = [pa.field("time_ns", pa.int64(), metadata={"unit": "ns"}),
              pa.field("time", pa.float64(), metadata={"unit": "s"})]
    arrays = [pa.array(t_ns), pa.array(t_ns * 1e-9)]
    for name, sig in log.signals.items():
        for col, y in _columns(sig, name):
            if y.dtype.kind not in "fiub":
                continue  # strings and binaries: not a signal a table of numbers holds
            full = np.full(len(t_ns), np.nan)
            mask = np.ones(len(t_ns), dtype=bool)
            at = np.searchsorted(t_ns, sig.t_ns)
            full[at], mask[at] = y, False
            fields.append(pa.field(col, pa.float64(), metadata={"unit": sig.unit, "description": sig.description}))
            arrays.append(pa.array(full, mask=mask))
    table = pa.Table.from_arrays(arrays, schema=pa.schema(fields, metadata={"log": str(log.path),
                                                                           "scenario": log.name}))
    try:
        with written_by_rename(out) as tmp:
            pq.write_table(table, tmp)
    except OSError as exc:
        # Refused (correctness): the file could not be written whole
        raise CosimError(f"--parquet: cannot write {out}: {exc.strerror or exc}") from None
    return out
