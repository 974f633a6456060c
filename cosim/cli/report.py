"""``python -m cosim report|table``: figures and a markdown summary of a run log (:mod:`cosim.analysis.report`), and
the RMSE per axis of several runs as thesis Table 5 (:mod:`cosim.analysis.table`)."""

from __future__ import annotations

import argparse
import json

__all__ = ["register"]


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
    from ..analysis.report import make_report

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
    from ..analysis.table import controller_table

    table = controller_table(args.runs, args.thesis)
    if args.json:
        print(json.dumps(table.as_dict(), indent=2))
    else:
        print(table.markdown(("m", "um") if args.units == "both" else (args.units,)))
    return 0
