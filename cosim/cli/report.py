"""``python -m cosim report|table``: figures and a markdown summary of a run log (:mod:`cosim.analysis.report`), with
``--recording`` the run against a robot recording too (``compare``'s options: :func:`.compare.add_recording_options`),
and the RMSE per axis of several runs as thesis Table 5 (:mod:`cosim.analysis.table`)."""

from __future__ import annotations

import argparse
import json

from ..errors import CosimError
from .compare import add_recording_options, recording_options

__all__ = ["register"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``report`` and ``table`` commands to the platform CLI."""
    p = subparsers.add_parser("report", help="figures and a markdown summary of a run log",
                              description="Figures and report.md of a run log; with --recording RECORDING --map "
                                          "RUN_SIGNAL=RECORDING_SIGNAL ..., also per mapped signal the run over the "
                                          "recording and the residual, as `compare` computes them "
                                          "(docs/recordings.md).")
    p.add_argument("run", help="run log (MCAP written by `python -m cosim run`)")
    p.add_argument("--out", default=None, help="output directory (default <log stem>_report/ next to the log)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    g = p.add_argument_group("against a recording (`report RUN.mcap --recording RECORDING --map ...`, "
                             "docs/recordings.md)")
    g.add_argument("--recording", metavar="RECORDING",
                   help="a robot recording (ROS 2 bag folder, .mcap, .db3, ROS 1 .bag, .csv, or a run log) to draw "
                        "the run against")
    add_recording_options(g)
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

    rep = make_report(args.run, args.out, **_against(args))
    if args.json:
        print(json.dumps(rep.as_dict(), indent=2))
        return 0
    print(f"{rep.name}: {rep.status}, {rep.duration:.6g} s simulated -> {rep.markdown}")
    for s in rep.position:
        print(f"  {s.name}: RMSE {s.rmse:.4e} {s.unit}, max |e| {s.max_error:.4e} {s.unit} at t = {s.t_max:.4g} s")
    cmp = rep.recording
    if cmp is not None:
        print(f"  against {cmp.b}: offset (recording - run) {cmp.offset + 0.0:.9g} s, {cmp.offset_how}")
        for n in cmp.notes:
            print(f"  {n}")
        for d in cmp.diffs:
            u = f" {d.unit}" if d.unit else ""
            print(f"  {d.name} - {d.reference}: RMSE {d.rmse:.4e}{u}, max |e| {d.max_error:.4e}{u} at "
                  f"t = {d.t_max:.4g} s")
    print("  figures: " + ", ".join(p.name for p in rep.figures.values()))
    return 0


def _against(args: argparse.Namespace) -> dict:
    """make_report's recording arguments from the options; CosimError (one line) for a recording option without
    ``--recording``."""
    if args.recording is None:
        given = [o for o, v in (("--map", args.map), ("--unit", args.unit), ("--align", args.align),
                                ("--offset", args.offset), ("--max-offset", args.max_offset),
                                ("--time", args.time != "header"), ("--time-origin", args.time_origin != "first"))
                 if v]
        if given:
            raise CosimError(f"{', '.join(given)}: only with --recording RECORDING (the recording the run is drawn "
                             "against)")
        return {}
    return {"recording": args.recording, **recording_options(args)}


def _cmd_table(args: argparse.Namespace) -> int:
    from ..analysis.table import controller_table

    table = controller_table(args.runs, args.thesis)
    if args.json:
        print(json.dumps(table.as_dict(), indent=2))
    else:
        print(table.markdown(("m", "um") if args.units == "both" else (args.units,)))
    return 0
