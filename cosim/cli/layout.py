"""``python -m cosim layout SCENARIO``: a Foxglove layout (JSON) for the scenario's channels: the 3D scene and the
joint plots, to import in the Foxglove app beside a run's log or its live view (:mod:`cosim.observers.layout`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from .common import EXIT_OK, emit

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """The ``layout`` command."""
    p = sub.add_parser("layout", help="a Foxglove layout (JSON) for a scenario's channels: 3D scene and joint plots",
                       description="`layout SCENARIO` writes a Foxglove layout for the channels a run of SCENARIO "
                                   "logs and serves (--live): a 3D panel on /scene, /scene/reference and /tf, a plot "
                                   "of the joint positions q[i] against the controller's reference q_ref[i] and one "
                                   "of the joint torques or forces u[i]. In the Foxglove app: Layouts, Import from "
                                   "file. The file is written whole or not at all.")
    p.add_argument("scenario", help="scenario file (.yaml) or SSP 1.0 archive (.ssp)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override by dotted name (repeatable), as for run (logging.signals=all: every variable)")
    p.add_argument("--out", help="the layout's path (default: runs/<name>.layout.json)")
    p.add_argument("--json", action="store_true", help="the file written, as JSON")
    p.set_defaults(handler=_cmd_layout)


def _cmd_layout(args: argparse.Namespace) -> int:
    from ..engine import plugins
    from ..engine.names import safe_stem
    from ..engine.overrides import apply_overrides
    from ..engine.prepare import input_files, prepare
    from ..errors import written_by_rename
    from ..io.output import check_output
    from ..observers.layout import channels_of, layout
    from .run import _open_system

    args.step = args.from_log = None  # what _open_system reads of a run's options
    with _open_system(args, apply_overrides(args.set)) as system:
        plan, _ = prepare(system)  # the channels a run logs: its components' logged variables
        drawing = plugins.scene(system)
        made = layout(channels_of(plan), drawing is not None and bool(drawing.position), system.name)
        out = Path(args.out) if args.out is not None else Path("runs") / f"{safe_stem(system.name)}.layout.json"
        check_output(out, input_files(system))
        text = made.to_json()
        with written_by_rename(out) as tmp:
            tmp.write_text(text, encoding="utf-8")
    emit(args, {"scenario": system.name, "written": str(out)}, f"wrote {out} (Foxglove layout)")
    return EXIT_OK
