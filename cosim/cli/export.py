"""``python -m cosim export``: a run's log as CSV files (one per component, as OSP's cosim-cli writes) and a
Parquet table, for other tools (:mod:`cosim.io.recordings.export`)."""

from __future__ import annotations

import argparse

from ..errors import CosimError
from .common import EXIT_OK, emit

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """The ``export`` command."""
    p = sub.add_parser("export", help="a run log as CSV files (one per component) and/or a Parquet table",
                       description="`export RUN.mcap --csv DIR` writes DIR/<component>.csv (a `Time [s]` column, "
                                   "then `variable [unit]` columns); `--parquet FILE` one table of every signal "
                                   "(time_ns, time, component.variable; units in the field metadata). Each file "
                                   "is written whole or not at all.")
    p.add_argument("log", help="the run's .mcap log")
    p.add_argument("--csv", metavar="DIR", help="folder for one CSV per component (made if missing)")
    p.add_argument("--parquet", metavar="FILE", help="Parquet file of every numeric signal")
    p.add_argument("--json", action="store_true", help="the files written, as JSON")
    p.set_defaults(handler=_cmd_export)


def _cmd_export(args: argparse.Namespace) -> int:
    from ..io.recordings.export import export_csv, export_parquet
    from ..io.runlog import read_run

    if not args.csv and not args.parquet:
        raise CosimError("export: give --csv DIR and/or --parquet FILE")
    log = read_run(args.log)
    written = []
    if args.csv:
        written += [str(p) for p in export_csv(log, args.csv)]
    if args.parquet:
        written.append(str(export_parquet(log, args.parquet)))
    emit(args, {"log": args.log, "written": written}, "\n".join(f"wrote {w}" for w in written))
    return EXIT_OK
