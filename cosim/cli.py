"""Command line: ``python -m cosim <command> ...``.

The CLI is thin: each subcommand parses its options, calls one library
function and prints the result (readable, or JSON with ``--json``). Heavy
imports happen inside the command that needs them. Errors print one line on
stderr (one line per issue for a scenario) and exit non-zero: 2 for an
unreachable pose, bad input or a failed FMU, 1 for a failed acceptance check,
130 on Ctrl-C and 143 on SIGTERM (the MCAP log is finished first). With ``--json`` an
error is also a JSON object ``{"ok": false, "error": ...}`` on stdout.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shlex
import sys
from pathlib import Path
from typing import Callable, Sequence

from delta.errors import UnreachableError

from .errors import EXIT_BAD_INPUT, STOP_SIGNALS, CosimError, exit_status, exit_text, number_option, user_errors

NUMBER = number_option()
"""A finite number (every numeric option refuses nan and infinities: :func:`cosim.errors.number_option`)."""
MARGIN = number_option(ge=0, le=1)
POSITIVE = number_option(gt=0)

EXIT_OK = 0
EXIT_CHECK_FAILED = 1

Handler = Callable[[argparse.Namespace], int]


def _emit(args: argparse.Namespace, payload: dict, text: str) -> None:
    if getattr(args, "json", False):
        print(json.dumps(payload, indent=2))
    else:
        print(text)


# --------------------------------------------------------------------------- robot


def _robot_parser(sub: argparse._SubParsersAction) -> None:
    robot = sub.add_parser("robot", help="kinematics, workspace and singularities of a robot preset")
    rsub = robot.add_subparsers(dest="robot_command", required=True, metavar="COMMAND")

    def common(p: argparse.ArgumentParser) -> None:
        p.add_argument("--robot", required=True, help="preset name (see `python -m cosim robot presets`)")
        p.add_argument("--json", action="store_true", help="machine-readable output")

    p = rsub.add_parser("presets", help="list the robot presets")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_cmd_presets)

    p = rsub.add_parser("ik", help="inverse kinematics: platform position -> joint values")
    common(p)
    _three(p, "xyz", ("X", "Y", "Z"), "platform position {} (m, or mm with --mm)")
    p.add_argument("--mm", action="store_true", help="position given in millimetres (linear joints shown in mm)")
    p.add_argument("--deg", action="store_true", help="rotary delta: joint angles in degrees in the JSON output too")
    p.add_argument("--margin", type=MARGIN, default=None, help="margin on the singularity proximity (0..1)")
    p.set_defaults(handler=_cmd_ik)

    p = rsub.add_parser("fk", help="forward kinematics: joint values -> platform position")
    common(p)
    _three(p, "q", ("Q1", "Q2", "Q3"),
           "joint value {}: carriage travel in m (mm with --mm) or arm angle in rad (deg with --deg)")
    p.add_argument("--mm", action="store_true", help="linear delta: carriage travels given in millimetres")
    p.add_argument("--deg", action="store_true", help="rotary delta: arm angles given in degrees")
    p.set_defaults(handler=_cmd_fk)

    p = rsub.add_parser("workspace", help="sampled workspace, or a cylinder check")
    common(p)
    p.add_argument("--spacing", type=POSITIVE, default=0.01, help="grid step, m (default 0.01)")
    p.add_argument("--margin", type=MARGIN, default=None, help="margin on the singularity proximity (0..1)")
    p.add_argument("--cylinder", nargs=3, type=number_option(nan=True), metavar=("Z_BELOW", "Z_ABOVE", "R"),
                   help="check a cylinder around --centre instead (m, or mm with --mm); "
                        "give one value as 'nan' to find its largest reachable value")
    p.add_argument("--centre", nargs=3, type=NUMBER, metavar=("X", "Y", "Z"),
                   help="cylinder centre (default: home of a rotary delta, mid-stroke of a linear one)")
    p.add_argument("--surface", action="store_true", help="check the lateral surface only (seed 004's path)")
    p.add_argument("--no-limits", action="store_true", help="ignore joint limits (real solutions only)")
    p.add_argument("--mm", action="store_true", help="cylinder and centre in millimetres")
    p.set_defaults(handler=_cmd_workspace)

    p = rsub.add_parser("singularity", help="classify a pose (type 1 / type 2) and measure its proximity")
    common(p)
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--q", nargs=3, type=NUMBER, metavar=("Q1", "Q2", "Q3"),
                   help="joint values: m (mm with --mm) or rad (deg with --deg)")
    g.add_argument("--p", nargs=3, type=NUMBER, metavar=("X", "Y", "Z"), help="platform position, m (mm with --mm)")
    p.add_argument("--mm", action="store_true", help="--p, and a linear delta's --q, in millimetres")
    p.add_argument("--deg", action="store_true", help="a rotary delta's --q in degrees")
    p.add_argument("--margin", type=MARGIN, default=0.01, help="margin on the singularity proximity (default 0.01)")
    p.set_defaults(handler=_cmd_singularity)


def _three(p: argparse.ArgumentParser, dest: str, names: tuple[str, str, str], help: str) -> None:
    """Three positional numbers as three arguments: argparse's help and its 'missing argument'
    message cannot format one ``nargs=3`` positional with a tuple metavar."""
    for i, name in enumerate(names):
        p.add_argument(f"{dest}_{i}", type=NUMBER, metavar=name, help=help.format(name))


def _units(args: argparse.Namespace, robot, lengths: bool) -> None:
    """Reject a unit flag that applies to nothing in this command for this robot kind.

    ``--mm``: lengths (positions when ``lengths``, a linear delta's carriage travels);
    ``--deg``: a rotary delta's arm angles.
    """
    if getattr(args, "deg", False) and robot.q_unit != "rad":
        raise CosimError(f"--deg: {robot.name} is a {robot.kind} delta: its joint values are lengths "
                         f"(m, or mm with --mm), not angles")
    if getattr(args, "mm", False) and robot.q_unit != "m" and not lengths:
        raise CosimError(f"--mm: {robot.name} is a {robot.kind} delta: its joint values are angles "
                         f"(rad, or degrees with --deg), not lengths")


def _cmd_presets(args: argparse.Namespace) -> int:
    from delta.robots import PRESETS

    payload = {name: robot.as_dict() for name, robot in PRESETS.items()}
    lines = []
    for name, robot in PRESETS.items():
        d = {k: v for k, v in robot.as_dict().items() if k not in ("name", "kind", "leg_angles")}
        lines.append(f"{name} ({robot.kind}): " + ", ".join(f"{k}={v:.6g}" for k, v in d.items()))
    _emit(args, payload, "\n".join(lines))
    return EXIT_OK


def _preset(name: str):
    """The robot preset ``name``; an unknown name is one line with the closest presets."""
    import difflib

    from delta.robots import PRESETS

    if name not in PRESETS:
        close = difflib.get_close_matches(name, list(PRESETS), n=3)
        hint = f"did you mean {', '.join(close)}? " if close else ""
        raise CosimError(f"--robot: unknown preset {name!r}; {hint}valid presets: {', '.join(PRESETS)}")
    return PRESETS[name]


def _cmd_ik(args: argparse.Namespace) -> int:
    import numpy as np

    from delta.actuators import actuator_for
    from delta.workspace import check_point

    robot = _preset(args.robot)
    _units(args, robot, lengths=True)
    p = np.array([args.xyz_0, args.xyz_1, args.xyz_2]) * (1e-3 if args.mm else 1.0)
    res = check_point(robot, p, args.margin)
    if not res.ok:
        raise UnreachableError(f"{args.robot}: p = ({p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}) m: {res.reason}")
    shown, unit = actuator_for(robot).shown(res.q)
    q_out, q_unit = [float(x) for x in res.q], robot.q_unit
    if args.deg:
        q_out, q_unit = shown, "deg"
    elif args.mm and robot.q_unit == "m":
        shown, unit = [x * 1e3 for x in res.q], "mm"
        q_out, q_unit = shown, "mm"
    payload = {"robot": robot.name, "p": p.tolist(), "q": q_out, "q_unit": q_unit,
               "singularity_proximity": res.proximity}
    text = "q = (" + ", ".join(f"{x:.6g}" for x in shown) + f") {unit}"
    if robot.q_unit == "m":  # the thesis's Table 4 is in cm
        text += "   [" + ", ".join(f"{x * 100:.2f}" for x in res.q) + "] cm"
    text += f"\nsingularity proximity = {res.proximity:.4f}"
    _emit(args, payload, text)
    return EXIT_OK


def _cmd_fk(args: argparse.Namespace) -> int:
    import numpy as np

    from delta.kinematics import fk

    robot = _preset(args.robot)
    _units(args, robot, lengths=False)
    q = np.array([args.q_0, args.q_1, args.q_2], dtype=float)
    if args.mm:
        q = q * 1e-3
    if args.deg:
        q = np.radians(q)
    res = fk(robot, q)
    if not res.ok:
        raise UnreachableError(f"{args.robot}: q = {q.tolist()}: {res.reason}")
    p = res.p
    limits = bool(np.all((q >= robot.q_min) & (q <= robot.q_max)))
    payload = {"robot": robot.name, "q": q.tolist(), "p": p.tolist(), "within_limits": limits}
    text = f"p = ({p[0]:.6f}, {p[1]:.6f}, {p[2]:.6f}) m" + ("" if limits else "   (joint values outside the limits)")
    _emit(args, payload, text)
    return EXIT_OK


def _cmd_workspace(args: argparse.Namespace) -> int:
    import math

    import numpy as np

    from delta.actuators import actuator_for
    from delta.workspace import check_cylinder, largest_cylinder, sample_workspace

    robot = _preset(args.robot)
    scale = 1e-3 if args.mm else 1.0
    if args.cylinder is None:
        ws = sample_workspace(robot, args.spacing, args.margin)
        payload = {"robot": robot.name, "spacing": ws.spacing, "volume_m3": ws.volume,
                   "bbox_min": ws.bbox_min.tolist(), "bbox_max": ws.bbox_max.tolist(), "grid_counts": ws.counts}
        text = (f"volume = {ws.volume * 1e3:.3f} dm^3 (grid {ws.spacing * 1e3:g} mm, {len(ws.points)} points)\n"
                f"bbox min = {np.round(ws.bbox_min, 4).tolist()} m\nbbox max = {np.round(ws.bbox_max, 4).tolist()} m")
        _emit(args, payload, text)
        return EXIT_OK
    if args.centre is not None:
        centre = np.array(args.centre) * scale
    else:
        centre = np.array(actuator_for(robot).workspace_centre(robot))
    dims = [None if math.isnan(v) else v * scale for v in args.cylinder]
    options = {"surface_only": args.surface, "check_limits": not args.no_limits}
    if None in dims:
        names = ("z_below", "z_above", "radius")
        free = names[dims.index(None)]
        value = largest_cylinder(robot, centre, singularity_margin=args.margin, **dict(zip(names, dims)), **options)
        payload = {"robot": robot.name, "centre": centre.tolist(), "largest": {free: value}}
        _emit(args, payload, f"largest {free} = {value:.4f} m ({value * 1e3:.1f} mm) around {np.round(centre, 4).tolist()}")
        return EXIT_OK
    res = check_cylinder(robot, centre, *dims, args.margin, **options)
    payload = {"robot": robot.name, "centre": centre.tolist(), "cylinder": dims, "ok": res.ok,
               "reason": res.reason, "p": res.p.tolist()}
    if not res.ok:
        x, y, z = res.p
        raise UnreachableError(f"{args.robot}: cylinder not reachable at p = ({x:.4f}, {y:.4f}, {z:.4f}) m: {res.reason}")
    _emit(args, payload, "cylinder reachable")
    return EXIT_OK


def _cmd_singularity(args: argparse.Namespace) -> int:
    import numpy as np

    from delta.singularity import analyse_pose

    robot = _preset(args.robot)
    _units(args, robot, lengths=args.p is not None)
    q = p = None
    if args.q is not None:
        q = np.array(args.q, dtype=float)
        q = np.radians(q) if args.deg else q * (1e-3 if args.mm else 1.0)
    if args.p is not None:
        p = np.array(args.p, dtype=float) * (1e-3 if args.mm else 1.0)
    try:
        rep = analyse_pose(robot, q=q, p=p)
    except ValueError as exc:
        raise UnreachableError(f"{args.robot}: {exc}") from None
    payload = {"robot": robot.name, "q": rep.q.tolist(), "p": rep.p.tolist(), "kind": rep.kind,
               "type1_legs": list(rep.type1_legs), "type2": rep.type2, "serial": rep.serial.tolist(),
               "parallel": rep.parallel, "inverse_condition": rep.inverse_condition, "proximity": rep.proximity,
               "within_margin": rep.within_margin(args.margin)}
    if rep.theta2 is not None:
        payload["theta2_deg"] = np.degrees(rep.theta2).tolist()
        payload["theta3_deg"] = np.degrees(rep.theta3).tolist()
    text = (f"{rep.kind}\nserial measures |cos(rod, actuator)| = {np.round(rep.serial, 4).tolist()}\n"
            f"parallel measure |det rods| = {rep.parallel:.4f}\n1/cond(J) = {rep.inverse_condition:.4f}\n"
            f"proximity = {rep.proximity:.4f} "
            f"({'within' if rep.within_margin(args.margin) else 'below'} margin {args.margin:g})")
    _emit(args, payload, text)
    return EXIT_OK


# --------------------------------------------------------------------------- co-simulation


def _cosim_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run a co-simulation scenario (YAML or SSP archive) and log it to MCAP")
    p.add_argument("scenario", nargs="?", help="scenario file (.yaml) or SSP 1.0 archive (.ssp)")
    p.add_argument("--from-log", metavar="LOG", help="instead of a scenario file: run again the scenario a run's "
                                                     ".mcap log records, as it ran (every override applied)")
    p.add_argument("--out", help="MCAP output path (default: the scenario's logging.out or runs/<name>.mcap; with "
                                 "--from-log LOG, LOG's name with .rerun.mcap; with --resume FILE, FILE's with "
                                 ".resumed.mcap)")
    p.add_argument("--stop-time", type=NUMBER, help="override time.stop, s")
    p.add_argument("--step", type=NUMBER, help="override time.step (the base communication step), s")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override by dotted name (repeatable): a component parameter (ctl.gain.kp[1]=4e4), the trajectory (trajectory.params.rx=0.05), the time grid (time.stop=0.5), any scenario key")
    p.add_argument("--no-log", action="store_true", help="do not write an MCAP file")
    p.add_argument("--parallel", choices=("auto", "on", "off"),
                   help="override the scenario's parallel: run the feed-forward components (e.g. trajectory, IK) "
                        "ahead in a worker process (same values as serial)")
    p.add_argument("--live", nargs="?", const="8765", default=None, metavar="PORT",
                   help="serve the run over the Foxglove WebSocket protocol on PORT or HOST:PORT (default 8765, "
                        "localhost): the log's channels and 3D scene while it runs; the log is still written")
    p.add_argument("--realtime", nargs="?", const="1", default=None, metavar="FACTOR",
                   help="pace simulated time to the wall clock, FACTOR simulated s per wall s (default 1); "
                        "the summary gives the achieved factor and the lag")
    p.add_argument("--sim-stamps", action="store_true",
                   help="log times in pure simulation time (default: from the run's wall-clock start, so viewers "
                        "show the real date; the message field t is simulation time either way)")
    p.add_argument("--watchdog", type=number_option(ge=0), metavar="SECONDS",
                   help="override watchdog_s: wall-clock seconds a step may take before the run stops naming the "
                        "stalled component (0: no limit)")
    p.add_argument("--checkpoint-at", type=number_option(ge=0), metavar="T",
                   help="write a checkpoint (every component's state, the scenario as run) when the run reaches "
                        "simulation time T, s (the first grid point at or after it)")
    p.add_argument("--checkpoint-out", metavar="FILE",
                   help="the checkpoint's path (default: beside the log, suffix .ckpt)")
    p.add_argument("--resume", metavar="FILE",
                   help="continue the run a checkpoint holds from its time (to its stop time unless --stop-time); "
                        "--set NAME=VALUE then sets component.variable at that time, as an event; a scenario file "
                        "given too must be the checkpoint's")
    p.add_argument("--quiet", action="store_true", help="no progress bar and no summary")
    p.add_argument("--json", action="store_true", help="summary as JSON on stdout")
    p.set_defaults(handler=_cmd_run)

    p = sub.add_parser("check", help="validate a scenario (YAML or SSP) and run the pre-flight only")
    p.add_argument("scenario")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override by dotted name (repeatable): a component parameter (ctl.gain.kp[1]=4e4), the trajectory (trajectory.params.rx=0.05), the time grid (time.stop=0.5), any scenario key")
    p.add_argument("--stop-time", type=NUMBER, help="override time.stop, s")
    p.add_argument("--step", type=NUMBER, help="override time.step, s")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_cmd_check)

    p = sub.add_parser("schema", help="print the scenario JSON Schema (for editors)")
    p.set_defaults(handler=_cmd_schema)

    p = sub.add_parser("recover", help="rewrite an unfinished MCAP log into a valid, indexed one")
    p.add_argument("file")
    p.add_argument("--out", help="output path (default: FILE with .recovered.mcap)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_cmd_recover)


def _regression_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compare", help="compare two run logs, or one scenario run on two plants",
                       description="`compare A.mcap B.mcap` compares two logs; `compare SCENARIO.yaml --plants "
                                   "exudyn,analytic` runs the scenario on both plants and compares their logs. "
                                   "Exit code 1 when a tolerance is exceeded.")
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="two .mcap logs, or one scenario file")
    p.add_argument("--plants", default="exudyn,analytic",
                   help="with a scenario: the two plants, comma-separated (exudyn, exudyn_lumped, analytic, "
                        "analytic_me; default exudyn,analytic)")
    p.add_argument("--component", help="with a scenario: the plant component (default: the one plant FMU)")
    p.add_argument("--tol", action="append", default=[], metavar="PATTERN=VALUE",
                   help="largest |A - B| allowed for the signals matching PATTERN (plant.p, ctl.u[1], *.q[*]); "
                        "repeatable. Default: a scenario's regression.plant_tolerances; for two logs of one "
                        "scenario, regression.tolerances of the scenario attached to the first")
    p.add_argument("--signals", action="append", default=[], metavar="PATTERN",
                   help="compare only these signals (repeatable; default all common signals)")
    p.add_argument("--out-dir", default="runs", help="with a scenario: where the two logs go (default runs/)")
    p.add_argument("--stop-time", type=NUMBER, help="with a scenario: override time.stop, s")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="with a scenario: override by dotted name, as for run (both runs)")
    p.add_argument("--checked-only", action="store_true", help="list only signals that have a tolerance")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="the comparison as JSON on stdout")
    p.set_defaults(handler=_cmd_compare)

    p = sub.add_parser("baseline", help="decimate a run log into a small baseline for regression tests")
    p.add_argument("log", help="the run's .mcap log")
    p.add_argument("--out", required=True, help="baseline .mcap path")
    p.add_argument("--period", type=POSITIVE, default=0.01, help="one sample per component every PERIOD s "
                                                              "(default 0.01)")
    p.add_argument("--components", nargs="+", help="keep only these components' channels")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_cmd_baseline)


    p = sub.add_parser("validate-model", help="analytic inverse dynamics vs the Exudyn plant on a prescribed "
                                              "motion, against the leg mass split w",
                       description="Drives the Exudyn plant along a validation motion, compares its actuator "
                                   "efforts with the analytic model's inverse dynamics for a range of w and "
                                   "identifies the best w (and the best separate inertia / gravity splits).")
    p.add_argument("--robot", required=True, help="preset name (see `python -m cosim robot presets`)")
    p.add_argument("--trajectory", choices=("helix", "pick_place"), nargs="+", default=["pick_place"],
                   help="validation motion(s) (default pick_place: 25/305/25 mm, 0.5 s, about 7 g); with several, "
                        "the split is identified jointly over them")
    p.add_argument("--out", help="write the identified model (robot, motions, fitted parameters, fit figures) "
                                 "to this YAML file, for a scenario's `model:` key")
    p.add_argument("--w", type=MARGIN, nargs="+", metavar="W",
                   help="w values to sweep (default 0, 0.1, ..., 1)")
    p.add_argument("--no-separate", action="store_true", help="skip the separate inertia / gravity fit")
    p.add_argument("--w-rotation", type=MARGIN, default=None, metavar="W",
                   help="share of the rods' rotational inertia in the model, held during the fit (0: the thesis's "
                        "two point masses per rod; 1: uniform rods). Default: 1 when identifying (several "
                        "motions or --out), 0 for one motion's sweep")
    p.add_argument("--fidelity", choices=("full", "lumped"), default="full", help="Exudyn plant (default full)")
    p.add_argument("--step", type=POSITIVE, default=2e-4, help="plant step, s (default 2e-4)")
    p.add_argument("--duration", type=POSITIVE, help="simulated time, s (default: the whole motion)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_cmd_validate_model)


def _cmd_validate_model(args: argparse.Namespace) -> int:
    from delta.robots import PRESETS
    import shlex
    from dataclasses import asdict
    from pathlib import Path

    from multibody.validate import identify_model, validate_model

    if args.robot not in PRESETS:
        raise CosimError(f"--robot: unknown preset {args.robot!r}; valid: {', '.join(PRESETS)}")
    several = len(args.trajectory) > 1 or args.out is not None
    if several and (args.duration is not None or args.no_separate):
        raise CosimError("validate-model: --duration and --no-separate apply to one motion without --out")
    if args.out is not None and not Path(args.out).parent.resolve().is_dir():
        raise CosimError(f"--out: no folder {Path(args.out).parent} to write {Path(args.out).name} into")
    if args.out is not None:
        from .io.output import check_output  # lazy: the CLI imports each command's modules in the command

        check_output(Path(args.out))  # a regular file or nothing: never renamed over a FIFO or a device
    bar = None
    progress = None
    if not (args.quiet or args.json):
        from .run import progress_bar

        bar = progress_bar()
        task = bar.add_task(f"{args.robot} {' + '.join(args.trajectory)}", total=None)
        bar.start()
        progress = lambda done, total: bar.update(task, completed=done, total=total)  # noqa: E731
    try:
        if several:
            ident = identify_model(args.robot, args.trajectory, h=args.step, fidelity=args.fidelity, ws=args.w,
                                   progress=progress, w_rotation=1.0 if args.w_rotation is None else args.w_rotation)
        else:
            rep = validate_model(args.robot, args.trajectory[0], args.w, not args.no_separate, h=args.step,
                                 duration=args.duration, fidelity=args.fidelity, progress=progress,
                                 w_rotation=args.w_rotation)
    except ValueError as exc:
        raise CosimError(f"validate-model: {exc}") from None
    finally:
        if bar is not None:
            bar.stop()
    if not several:
        _emit(args, rep.as_dict(), rep.text())
        return EXIT_OK
    text = "\n\n".join([*(r.text() for r in ident.reports), ident.text()])
    payload = {"identified": {"w_inertia": ident.w_inertia, "w_gravity": ident.w_gravity,
                              "w_rotation": ident.w_rotation},
               "fits": [asdict(f) for f in ident.fits], "reports": [r.as_dict() for r in ident.reports]}
    if args.out is not None:
        from .robot.model_file import write_model_file

        command = (f"python -m cosim validate-model --robot {args.robot} --trajectory {' '.join(args.trajectory)}"
                   + (f" --step {args.step:g}" if args.step != 2e-4 else "")
                   + (f" --fidelity {args.fidelity}" if args.fidelity != "full" else "")
                   + (" --w " + " ".join(f"{w:g}" for w in args.w) if args.w else "")
                   + (f" --w-rotation {args.w_rotation:g}" if args.w_rotation is not None else "")
                   + f" --out {shlex.quote(args.out)}")
        fit = {f.trajectory: {"samples": f.samples, "duration_s": f.duration, "plant_rms": f.plant_rms,
                              "plant_peak": f.plant_peak, "rms_rel": f.identified.rms_rel,
                              "peak_rel": f.identified.peak_rel, "rms_abs": f.identified.rms_abs,
                              "peak_abs": f.identified.peak_abs,
                              "default_split": [f.default.w_inertia, f.default.w_gravity],
                              "rms_rel_at_default": f.default.rms_rel, "peak_rel_at_default": f.default.peak_rel}
               for f in ident.fits}
        fitted_on = {"trajectories": [f.trajectory for f in ident.fits],
                     "plant": f"{ident.fidelity} Exudyn plant, joints prescribed", "step_s": ident.h,
                     "effort_unit": ident.effort_unit, "weighting": "each motion's errors over its plant RMS"}
        try:
            write_model_file(args.out, ident.robot, {"model.w_inertia": ident.w_inertia,
                                                     "model.w_gravity": ident.w_gravity,
                                                     "model.w_rotation": ident.w_rotation}, fitted_on, fit, command)
        except OSError as exc:
            raise CosimError(f"--out: cannot write {args.out}: {exc.strerror or exc}") from None
        text += f"\nwrote {args.out}"
        payload["out"] = args.out
    _emit(args, payload, text)
    return EXIT_OK


def _cmd_compare(args: argparse.Namespace) -> int:
    from pathlib import Path

    from .analysis.compare import compare_logs, compare_plants, logged_tolerances, parse_tolerances
    from .engine.overrides import apply_overrides

    tol = parse_tolerances(args.tol)
    ins = args.inputs
    if len(ins) == 1 and Path(ins[0]).suffix in (".yaml", ".yml"):
        plants = [x.strip() for x in args.plants.split(",") if x.strip()]

        def said(plant, res) -> None:
            if not (args.json or args.quiet):
                print(f"{plant}: {res.steps} steps in {res.wall_time:.1f} s wall -> {res.mcap}", file=sys.stderr)

        cmp, _ = compare_plants(ins[0], plants, args.out_dir, tol, args.signals or None,
                                apply_overrides(args.set, args.stop_time), args.component,
                                progress=not (args.quiet or args.json), on_run=said)
    elif len(ins) == 2 and all(Path(x).suffix == ".mcap" for x in ins):
        if args.set or args.stop_time is not None:
            raise CosimError("--set and --stop-time apply to a scenario, not to two logs")
        from .io.runlog import read_run

        a, b = read_run(ins[0]), read_run(ins[1])
        if not tol and a.name == b.name:  # a run against its baseline: the scenario's own tolerances
            tol = logged_tolerances(a)
            if tol and not args.json:
                print(f"tolerances: regression.tolerances of the scenario attached to {ins[0]}", file=sys.stderr)
        cmp = compare_logs(a, b, tol, args.signals or None)
    else:
        raise CosimError(f"compare takes two .mcap logs or one scenario .yaml, got: {' '.join(ins)}")
    if args.checked_only and not cmp.checked:
        raise CosimError("--checked-only: no signal has a tolerance, so nothing was checked; give --tol NAME=VALUE "
                         "(or compare a run with its scenario's baseline, whose regression.tolerances apply)")
    _emit(args, cmp.as_dict(), cmp.text(args.checked_only))
    return EXIT_OK if cmp.ok else EXIT_CHECK_FAILED


def _cmd_baseline(args: argparse.Namespace) -> int:
    from .io.runlog import write_baseline

    out, n = write_baseline(args.log, args.out, args.period, args.components)
    _emit(args, {"out": str(out), "messages": n, "period_s": args.period},
          f"{n} messages every {args.period:g} s -> {out}")
    return EXIT_OK


def _summary_text(res) -> str:
    lines = [f"{res.scenario}: {res.status}{(' - ' + res.message) if res.message else ''}",
             f"  {res.steps} steps, {res.sim_time:.4g} s simulated in {res.wall_time:.3f} s wall "
             f"(real-time factor {res.real_time_factor:.3g})"]
    total = sum(res.component_time.values()) or 1.0
    share = ", ".join(f"{n} {100 * t / res.wall_time if res.wall_time else 0:.0f}%"
                      for n, t in sorted(res.component_time.items(), key=lambda kv: -kv[1]))
    lines.append(f"  time share: {share}, master {100 * max(0.0, 1 - total / res.wall_time) if res.wall_time else 0:.0f}%")
    lines += [f"  {note}" for note in res.notes]
    if res.events:
        lines.append("  model-exchange events: " + ", ".join(f"{n} {k}" for n, k in res.events.items()))
    if res.worker_time:
        lines.append("  in the worker process (overlapped with the master): "
                     + ", ".join(f"{n} {t:.3f} s" for n, t in res.worker_time.items()))
    for e in res.errors:
        lines.append(f"  {e.actual} vs {e.reference}: RMSE {e.rmse:.4g}, max error {e.max_error:.4g}")
    for name, c in res.checks.items():
        lines.append(f"  check {name}: {c['value']:.4g} {'<=' if c['ok'] else '>'} {c['limit']:g} "
                     f"{'ok' if c['ok'] else 'FAILED'}")
    if res.mcap:
        lines.append(f"  log: {res.mcap}")
    return "\n".join(lines)


def _open_scenario(args: argparse.Namespace, overrides: dict):
    """The scenario of a YAML file, of an SSP archive or of a run's log (an archive unpacked for the ``with`` block
    only)."""
    from contextlib import nullcontext

    from .engine.scenario import load_scenario
    from .io.ssp import is_ssp, open_ssp

    if args.step is not None:
        overrides.put(("time", "step"), args.step, f"--step {args.step:g}")
    from_log = getattr(args, "from_log", None)
    if (from_log is None) == (args.scenario is None):
        raise CosimError("run takes a scenario file or --from-log LOG, not both" if from_log else
                         "run needs a scenario file (or --from-log LOG: a run's log)")
    if from_log is not None:
        from .io.runlog import open_from_log

        return open_from_log(from_log, overrides)
    if is_ssp(args.scenario):
        return open_ssp(args.scenario, overrides)
    return nullcontext(load_scenario(args.scenario, overrides))


@contextlib.contextmanager
def _stdout_kept_for_json(on: bool):
    """With ``--json``, what the run's FMUs (and worker processes) write to standard output goes to standard error
    until the run is over, so the JSON on stdout stays the only thing there (issue 25: an FMU printing broke it)."""
    if not on:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        with contextlib.redirect_stdout(sys.stderr):
            yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def _cmd_run(args: argparse.Namespace) -> int:
    from .engine.overrides import apply_overrides
    from .run import run_scenario

    overrides = apply_overrides(args.set, args.stop_time)
    if args.parallel:
        overrides.put(("parallel",), args.parallel, f"--parallel {args.parallel}")
    if args.watchdog is not None:
        overrides.put(("watchdog_s",), args.watchdog if args.watchdog > 0 else None, f"--watchdog {args.watchdog:g}")
    live = realtime = None
    if args.live is not None:
        from .observers.live import parse_address

        live = parse_address(args.live)
    if args.realtime is not None:
        from .observers.realtime import parse_factor

        realtime = parse_factor(args.realtime)
    command = " ".join(["python -m cosim", *(shlex.quote(a) for a in sys.argv[1:])])
    if args.from_log is not None and args.out is None:  # beside the log, never over it (its scenario's default)
        args.out = str(Path(args.from_log).with_name(Path(args.from_log).stem + ".rerun.mcap"))
    if args.resume is not None:
        with _stdout_kept_for_json(args.json):
            res = _resume_run(args, live, realtime, command)
    else:
        with _stdout_kept_for_json(args.json), _open_scenario(args, overrides) as scenario:
            res = run_scenario(scenario, out=args.out, log=False if args.no_log else None,
                               progress=not (args.quiet or args.json), live=live, realtime=realtime,
                               stamps="simulation" if args.sim_stamps else "wall", checkpoint_at=args.checkpoint_at,
                               checkpoint_out=args.checkpoint_out, command=command)
    if args.json:
        print(json.dumps(res.as_dict(), indent=2))
    elif not args.quiet:
        print(_summary_text(res))
    return EXIT_OK if res.passed else EXIT_CHECK_FAILED


def _resume_run(args: argparse.Namespace, live, realtime, command: str):
    """``run --resume FILE``: the checkpoint's scenario (``--stop-time`` moves its end; a scenario file given too
    must be the checkpoint's), its state restored, ``--set`` values set at its time."""
    from .engine.overrides import parse_set_value
    from .engine.scenario import load_scenario
    from .io.checkpoint import read_checkpoint
    from .run import resumed_scenario, run_scenario

    if args.from_log is not None:
        raise CosimError("run takes --resume FILE or --from-log LOG, not both")
    for option, value in (("--step", args.step), ("--parallel", args.parallel), ("--watchdog", args.watchdog)):
        if value is not None:
            raise CosimError(f"{option} cannot change a resumed run: it continues the checkpoint's run as it was")
    checkpoint = read_checkpoint(args.resume)
    named = load_scenario(args.scenario) if args.scenario is not None else None
    scenario = resumed_scenario(checkpoint, args.stop_time, named)
    sets = {}
    for item in args.set:
        name, sep, raw = item.partition("=")
        if not sep or not name.strip():
            raise CosimError(f"--set {item}: expected component.variable=VALUE")
        sets[name.strip()] = parse_set_value(raw, f"--set {item}")
    out = args.out if args.out is not None else Path(checkpoint.path).with_suffix(".resumed.mcap")
    return run_scenario(scenario, out=out, log=False if args.no_log else None,
                        progress=not (args.quiet or args.json), live=live, realtime=realtime,
                        stamps="simulation" if args.sim_stamps else "wall", resume=checkpoint, resume_sets=sets,
                        checkpoint_at=args.checkpoint_at, checkpoint_out=args.checkpoint_out, command=command)


def _crashed(args: argparse.Namespace, record, reason: str) -> int:
    """The supervisor's report of a run (or a check) whose process died inside a component (cosim.engine.supervision): one
    line naming the component, the phase, the time and how it died, then where the log written so far is."""
    from .fmi.extract import sweep_orphans
    from .io.recover import recover_crashed

    sweep_orphans()  # the FMUs the dead child extracted
    message = f"{record.where()} {reason}"
    lines = [exit_text(message, "crash")]
    _, where = recover_crashed(record.info())
    if where is not None:
        lines.append(where)
    _error_json(args, message, "crash")
    print("\n".join(lines), file=sys.stderr)
    return EXIT_BAD_INPUT  # an error (2): the run failed


def _cmd_check(args: argparse.Namespace) -> int:
    from .engine.offload import choose
    from .engine.overrides import apply_overrides
    from .run import check_initialization

    with _open_scenario(args, apply_overrides(args.set, args.stop_time)) as scenario:
        plan, report = check_initialization(scenario)  # the checks a run makes before t = 0, FMUs' own included
    order = " -> ".join(plan.names[c] for c in plan.order)
    from .observers.mcap_log import McapRecorder

    n_steps = scenario.time.n_steps  # a logged run of these steps writes through a writer process (cosim.observers.mcap_log)
    _, parallel = choose(plan, scenario.parallel, n_steps,
                         scenario.logging.enabled and McapRecorder.writes_in_a_process(n_steps))
    payload = {"scenario": scenario.name, "ok": True, "preflight": report, "order": [plan.names[c] for c in plan.order],
               "connections": len(plan.links), "parallel": parallel}
    _emit(args, payload, f"{scenario.name}: ok\n  pre-flight: {report}\n  order: {order}\n"
                         f"  {len(plan.links)} connections" + (f"\n  {parallel}" if parallel else ""))
    return EXIT_OK


def _cmd_schema(args: argparse.Namespace) -> int:
    from .engine.schema import scenario_json_schema

    print(json.dumps(scenario_json_schema(), indent=2))
    return EXIT_OK


def _cmd_recover(args: argparse.Namespace) -> int:
    from .io.recover import recover

    rep = recover(args.file, args.out)
    _emit(args, rep.as_dict(), f"recovered {rep.messages} messages on {rep.channels} channels "
                               f"({rep.attachments} attachments, {rep.metadata} metadata) -> {rep.out}")
    return EXIT_OK


# --------------------------------------------------------------------------- entry


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("delta-cosim")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="python -m cosim", description="Delta robot FMI co-simulation platform")
    parser.add_argument("--version", action="version", version=f"%(prog)s (delta-cosim) {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    _robot_parser(sub)
    _cosim_parser(sub)
    _regression_parser(sub)
    from fmus.cli import register as _register_fmus

    from .analysis.report import register as _register_report
    from .analysis.sweep import register as _register_sweep
    from .io.ssp import register as _register_ssp

    _register_report(sub)
    _register_ssp(sub)
    _register_sweep(sub)
    _register_fmus(sub)
    return parser


def _leaf(parser: argparse.ArgumentParser, argv: Sequence[str]) -> argparse.ArgumentParser:
    """The (sub)parser the command line selected: ``run``, ``robot ik``, ..."""
    while True:
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not subs:
            return parser
        chosen = next((a.choices[w] for a in subs for w in argv if w in a.choices), None)
        if chosen is None:
            return parser
        parser, argv = chosen, argv[list(argv).index(chosen.prog.split()[-1]) + 1:]


def _unknown(parser: argparse.ArgumentParser, argv: Sequence[str], extra: list[str]) -> None:
    """argparse's 'unrecognized arguments' with the closest options of the command (exit 2)."""
    import difflib

    leaf = _leaf(parser, argv)
    options = [o for a in leaf._actions for o in a.option_strings]
    hints = []
    for word in extra:
        if word.startswith("-"):
            close = difflib.get_close_matches(word.split("=", 1)[0], options, n=2, cutoff=0.75)
            if close:
                hints.append(f"{word}: did you mean {' or '.join(close)}?")
    leaf.error(f"unrecognized arguments: {' '.join(extra)}" + ("; " + "; ".join(hints) if hints else ""))


class _Parser(argparse.ArgumentParser):
    """argparse with a close-match hint for an invalid command (Python 3.14's suggest_on_error);
    subparsers are of the same class (``add_subparsers`` uses ``type(self)``)."""

    def error(self, message: str):
        import difflib
        import re

        m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if m:
            choices = re.findall(r"'([^']*)'", m.group(2)) or [c.strip() for c in m.group(2).split(",")]
            close = difflib.get_close_matches(m.group(1), choices, n=2, cutoff=0.6)
            if close:
                message += f"; did you mean {' or '.join(close)}?"
        self.print_usage(sys.stderr)
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        exc = SystemExit(EXIT_BAD_INPUT)
        exc.message = f"{self.prog}: {message}"  # for --json's error object (main)
        raise exc


def _terminate_as_interrupt(signum, frame) -> None:
    """SIGTERM or SIGHUP outside the simulation loop: unwind like Ctrl-C (logs finished, worker stopped)."""
    from .errors import Interrupted

    raise Interrupted(signum)


def _error_json(args: argparse.Namespace | None, text: str, kind: str) -> None:
    """With --json the error is a JSON object on stdout too, so a reader always gets one."""
    if args is not None and getattr(args, "json", False):
        print(json.dumps({"ok": False, "error": text, "kind": kind}, indent=2))


def main(argv: Sequence[str] | None = None) -> int:
    import signal

    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        parser = build_parser()
        args, extra = parser.parse_known_args(argv)
        if extra:
            _unknown(parser, argv, extra)
    except KeyboardInterrupt as exc:  # Ctrl-C while starting (imports): interrupted, no traceback
        message, kind, code = exit_status(exc)
        print(exit_text(message, kind), file=sys.stderr)
        return code
    except SystemExit as exc:  # a usage error (a bad option or value): with --json, a JSON object on stdout too
        if exc.code == EXIT_BAD_INPUT and "--json" in argv:
            print(json.dumps({"ok": False, "error": getattr(exc, "message", "invalid arguments"), "kind": "usage"},
                             indent=2))
        raise
    handler: Handler = args.handler
    if threading_main():  # the same shutdown path as Ctrl-C (logs finished, worker stopped, temp files removed)
        for sig in STOP_SIGNALS:
            if sig != signal.SIGINT:  # Ctrl-C raises KeyboardInterrupt by itself
                signal.signal(sig, _terminate_as_interrupt)
    try:
        if handler in _SUPERVISED:  # commands that load and call FMUs: a supervisor names a crash inside one
            from .engine import supervision

            code = supervision.supervise(lambda record, reason: _crashed(args, record, reason))
            if code is not None:  # the supervisor: the command went on in its child process
                return code
        return handler(args)
    except (*_user_errors(), KeyboardInterrupt) as exc:
        message, kind, code = exit_status(exc)
        _error_json(args, message, kind)
        print(exit_text(message, kind), file=sys.stderr)
        return code
    except BrokenPipeError:  # output piped into a reader that stopped early (e.g. `| head`)
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK


def _user_errors() -> tuple[type[BaseException], ...]:
    """The errors a command ends on with one line: the master's and those of the domains plugged in (their
    plugins loaded now if no command did)."""
    from .engine import plugins

    plugins.installed()
    return user_errors()


_SUPERVISED = (_cmd_run, _cmd_check, _cmd_compare)
"""Handlers that instantiate FMUs in this process (run, check, compare --plants): run under the supervisor
(cosim.engine.supervision) when started as ``python -m cosim``."""


def threading_main() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()
