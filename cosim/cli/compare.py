"""``python -m cosim compare|baseline|validate-model``: two logs (or one scenario on two plants) compared, a log
decimated into a baseline, and the analytic model validated against the Exudyn plant."""

from __future__ import annotations

import argparse
import sys

from ..errors import CosimError
from .common import EXIT_CHECK_FAILED, EXIT_OK, MARGIN, NUMBER, POSITIVE, emit

__all__ = ["register", "add_recording_options", "add_recording_reading_options", "recording_options",
           "recording_units"]


def register(sub: argparse._SubParsersAction) -> None:
    """The ``compare`` (supervised: with a scenario it loads FMUs), ``baseline`` and ``validate-model`` commands."""
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
    add_recording_options(p.add_argument_group("against a recording (`compare RUN.mcap RECORDING --map ...`, "
                                                "docs/recordings.md)"))
    p.set_defaults(handler=_cmd_compare, supervised=True)

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


def add_recording_options(g) -> None:
    """The options of a run against a recording (``--map``, ``--align``, ``--offset``, ``--max-offset``, ``--time``,
    ``--time-origin``, ``--unit``), added to the parser or group ``g``: ``compare`` and ``report`` share them;
    :func:`recording_options` reads them."""
    g.add_argument("--map", action="append", default=[], metavar="RUN_SIGNAL=RECORDING_SIGNAL",
                   help="compare the run's signal with the recorded one (plant.q[1]=/joint_states.position[joint1], "
                        "ctl.q[1]=q1 for a CSV column); repeatable")
    g.add_argument("--align", action="store_true",
                   help="estimate the time offset (recording - run): cross-correlation, refined below the step")
    g.add_argument("--offset", type=NUMBER, default=0.0, metavar="S",
                   help="the recording's time minus the run's, s (default 0; --align estimates it)")
    g.add_argument("--max-offset", type=POSITIVE, metavar="S",
                   help="with --align: largest |offset| tried, s (default half the shorter span)")
    add_recording_reading_options(g)


def add_recording_reading_options(g) -> None:
    """How a recording is read (``--time``, ``--time-origin``, ``--unit``): :func:`add_recording_options`' and
    ``calibrate``'s; :func:`recording_units` reads ``--unit``."""
    g.add_argument("--time", choices=("header", "log"), default="header",
                   help="a bag's header stamps or log (receive) times (default header)")
    g.add_argument("--time-origin", choices=("first", "absolute"), default="first",
                   help="recording times from its first message, or absolute (default first)")
    g.add_argument("--unit", action="append", default=[], metavar="RUN_SIGNAL=UNIT",
                   help="the unit of the recorded signal mapped to RUN_SIGNAL (bags carry none; default: the run "
                        "signal's); repeatable")


def recording_units(args: argparse.Namespace, maps: dict) -> dict[str, str]:
    """``--unit`` by run signal; CosimError (one line) for a malformed one or one of a signal no ``--map`` maps."""
    units = {}
    for item in args.unit:
        name, sep, unit = item.partition("=")
        if not sep or not name.strip():
            raise CosimError(f"--unit {item!r}: expected RUN_SIGNAL=UNIT, e.g. plant.q[1]=deg")
        units[name.strip()] = unit.strip()
    unmapped = sorted(set(units) - set(maps))
    if unmapped:
        raise CosimError(f"--unit {', '.join(unmapped)}: not mapped by any --map")
    return units


def recording_options(args: argparse.Namespace) -> dict:
    """The keyword arguments of :func:`cosim.analysis.recording_compare.compare_recording` (``maps``, ``units``,
    ``time``, ``time_origin``, ``align``, ``offset``, ``max_offset``) from :func:`add_recording_options`' options;
    CosimError (one line) for a malformed ``--map`` or ``--unit``, or a ``--unit`` of a signal not mapped."""
    from ..analysis.recording_compare import parse_maps

    maps = parse_maps(args.map)
    units = recording_units(args, maps)
    return {"maps": maps, "units": units, "time": args.time, "time_origin": args.time_origin, "align": args.align,
            "offset": args.offset, "max_offset": args.max_offset}


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
        from ..io.output import check_output  # lazy: the CLI imports each command's modules in the command

        check_output(Path(args.out))  # a regular file or nothing: never renamed over a FIFO or a device
    bar = None
    progress = None
    if not (args.quiet or args.json):
        from ..run import progress_bar

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
        emit(args, rep.as_dict(), rep.text())
        return EXIT_OK
    text = "\n\n".join([*(r.text() for r in ident.reports), ident.text()])
    payload = {"identified": {"w_inertia": ident.w_inertia, "w_gravity": ident.w_gravity,
                              "w_rotation": ident.w_rotation},
               "fits": [asdict(f) for f in ident.fits], "reports": [r.as_dict() for r in ident.reports]}
    if args.out is not None:
        from ..robot.model_file import write_model_file

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
    emit(args, payload, text)
    return EXIT_OK


def _cmd_compare(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ..analysis.compare import compare_logs, compare_plants, logged_tolerances, parse_tolerances
    from ..engine.overrides import apply_overrides

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
    elif len(ins) == 2 and (args.map or _is_recording(ins[1])):
        cmp = _against_recording(args, tol)
    elif len(ins) == 2 and all(Path(x).suffix == ".mcap" for x in ins):
        if args.set or args.stop_time is not None:
            raise CosimError("--set and --stop-time apply to a scenario, not to two logs")
        from ..io.runlog import read_run

        a, b = read_run(ins[0]), read_run(ins[1])
        if not tol and a.name == b.name:  # a run against its baseline: the scenario's own tolerances
            tol = logged_tolerances(a)
            if tol and not args.json:
                print(f"tolerances: regression.tolerances of the scenario attached to {ins[0]}", file=sys.stderr)
        cmp = compare_logs(a, b, tol, args.signals or None)
    else:
        raise CosimError(f"compare takes two .mcap logs, a log and a recording (bag folder, .mcap, .db3, .bag, "
                         f".csv) with --map, or one scenario .yaml, got: {' '.join(ins)}")
    if args.checked_only and not cmp.checked:
        raise CosimError("--checked-only: no signal has a tolerance, so nothing was checked; give --tol NAME=VALUE "
                         "(or compare a run with its scenario's baseline, whose regression.tolerances apply)")
    emit(args, cmp.as_dict(), cmp.text(args.checked_only))
    return EXIT_OK if cmp.ok else EXIT_CHECK_FAILED


def _is_recording(path: str) -> bool:
    from ..io.recordings import recording_kind

    return recording_kind(path) in ("ros1", "ros2", "csv")


def _against_recording(args: argparse.Namespace, tol: dict):
    """``compare RUN.mcap RECORDING --map ...``: the run's signals against the recorded ones."""
    from pathlib import Path

    from ..analysis.recording_compare import compare_recording

    run, recording = args.inputs
    if Path(run).suffix != ".mcap":
        raise CosimError(f"compare with a recording: the first input is the run's .mcap log, got {run}")
    if args.set or args.stop_time is not None or args.signals:
        raise CosimError("--set, --stop-time and --signals do not apply to a recording; --map names the signals")
    return compare_recording(run, recording, tolerances=tol, **recording_options(args))


def _cmd_baseline(args: argparse.Namespace) -> int:
    from ..io.runlog import write_baseline

    out, n = write_baseline(args.log, args.out, args.period, args.components)
    emit(args, {"out": str(out), "messages": n, "period_s": args.period},
          f"{n} messages every {args.period:g} s -> {out}")
    return EXIT_OK
