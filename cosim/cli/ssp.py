"""``python -m cosim ssp export SCENARIO -o SYSTEM.ssp``: a scenario written as an SSP 1.0 archive
(:mod:`cosim.io.ssp`; ``run X.ssp`` runs one)."""

from __future__ import annotations

import argparse
import json

from .common import NUMBER

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """``python -m cosim ssp export SCENARIO -o SYSTEM.ssp``."""
    p = sub.add_parser("ssp", help="export a scenario as an SSP 1.0 archive (run one with `cosim run X.ssp`)")
    ssub = p.add_subparsers(dest="ssp_command", required=True, metavar="COMMAND")
    e = ssub.add_parser("export", help="write SystemStructure.ssd, one .ssv per component and the FMUs",
                        description="Writes the scenario as an SSP 1.0 archive (SystemStructure.ssd, a parameter "
                                    "set per component with every start value the master sets, the FMUs in "
                                    "resources/) that OSP libcosim and other SSP tools run.")
    e.add_argument("scenario", help="scenario file (YAML)")
    e.add_argument("-o", "--out", required=True, help="the .ssp file to write")
    e.add_argument("--stop-time", type=NUMBER, help="override time.stop, s")
    e.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override by dotted name (repeatable): a component parameter (ctl.gain.kp[1]=4e4), the trajectory (trajectory.params.rx=0.05), the time grid (time.stop=0.5), any scenario key")
    e.add_argument("--json", action="store_true")
    e.set_defaults(handler=_cmd_export)


def _cmd_export(args: argparse.Namespace) -> int:
    from ..engine.overrides import apply_overrides
    from ..engine.scenario import load_scenario
    from ..io.ssp.write import export_ssp

    rep = export_ssp(load_scenario(args.scenario, apply_overrides(args.set, args.stop_time)), args.out)
    if args.json:
        print(json.dumps(rep.as_dict(), indent=2))
    else:
        print(rep.text())
    return 0
