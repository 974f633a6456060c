"""``python -m cosim calibrate SCENARIO --measured RECORDING --map RUN=REC --fit NAME[=LOW:HIGH]``: a scenario's
values fitted so that its run matches a robot recording (:mod:`cosim.analysis.calibrate`, docs/recordings.md)."""

from __future__ import annotations

import argparse
import shlex

from ..errors import number_option
from .common import EXIT_CHECK_FAILED, EXIT_OK, NUMBER, emit
from .compare import add_recording_reading_options, recording_units

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """The ``calibrate`` command (supervised: it loads FMUs in this process)."""
    p = sub.add_parser("calibrate", help="fit a scenario's values (payload, masses, friction, the time offset) to a "
                                         "robot recording",
                       description="Runs the scenario again and again (no log) and fits the --fit values by least "
                                   "squares (SciPy) so that the --map'ped run signals match the recording: the "
                                   "fitted values with standard errors and correlations, the residual RMS before "
                                   "and after, the runs made. Exit 1 when the fit does not converge.")
    p.add_argument("scenario", help="scenario file (.yaml)")
    p.add_argument("--measured", required=True, metavar="RECORDING",
                   help="the recording: a ROS 2 bag (folder, .mcap, .db3), a ROS 1 .bag, a .csv or a run log")
    p.add_argument("--map", action="append", default=[], required=True, metavar="RUN_SIGNAL=RECORDING_SIGNAL",
                   help="fit the run's signal to the recorded one (plant.q[1]=/joint_states.position[joint1]); "
                        "repeatable")
    p.add_argument("--fit", action="append", default=[], required=True, metavar="NAME[=LOW:HIGH]",
                   help="a value to fit, addressed as --set addresses it (plant.mass.payload=0:1); names joined "
                        "by commas are one value set at each (plant.mass.payload,ctl.mass.payload); 'offset' the "
                        "recording's time minus the run's; repeatable")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override by dotted name, as for run (a fitted name: its start value)")
    p.add_argument("--offset", type=NUMBER, default=0.0, metavar="S",
                   help="the recording's time minus the run's, s, when offset is not fitted (default 0)")
    add_recording_reading_options(p)
    p.add_argument("--max-runs", type=number_option(whole=True, ge=2, le=10_000), default=60, metavar="N",
                   help="most runs of the scenario the fit may make (default 60)")
    p.add_argument("--out", metavar="FILE",
                   help="write the fitted values to this YAML file, which a scenario uses with the key "
                        "'parameters: FILE' (the command, date, RMS and standard errors in its header)")
    p.add_argument("--quiet", action="store_true", help="no progress")
    p.add_argument("--json", action="store_true", help="the calibration as JSON on stdout")
    p.set_defaults(handler=_cmd_calibrate, supervised=True)


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ..analysis.calibrate import CalibrationError, calibrate, offset_component, parse_fits, write_fitted
    from ..analysis.recording_compare import parse_maps
    from ..errors import file_problem

    problem = file_problem(args.scenario)
    if problem is not None:
        raise CalibrationError(f"{args.scenario}: {problem}")
    maps, fits = parse_maps(args.map), parse_fits(args.fit)
    units = recording_units(args, maps)
    if args.out is not None:
        from ..io.output import check_output

        if not Path(args.out).parent.resolve().is_dir():
            raise CalibrationError(f"--out: no folder {Path(args.out).parent} to write {Path(args.out).name} into")
        check_output(Path(args.out))  # a regular file or nothing, before the fit's runs
    bar = task = None
    on_run = None
    if not (args.quiet or args.json):
        from ..run import progress_bar

        bar = progress_bar()
        task = bar.add_task("calibrate: run 0", total=args.max_runs)
        bar.start()
        on_run = lambda n: bar.update(task, completed=n, description=f"calibrate: run {n}")  # noqa: E731
    try:
        cal = calibrate(args.scenario, args.measured, maps, fits, sets=args.set, units=units,
                        time_stamps=args.time, time_origin=args.time_origin, offset=args.offset,
                        max_runs=args.max_runs, on_run=on_run)
    finally:
        if bar is not None:
            bar.stop()
    payload, text = cal.as_dict(), cal.text()
    if args.out is not None:
        try:
            offset_at = offset_component(args.scenario, args.set, args.measured, args.time, args.time_origin)
            write_fitted(cal, args.out, _command(args), offset_at)
        except OSError as exc:
            raise CalibrationError(f"--out: cannot write {args.out}: {exc.strerror or exc}") from None
        text += f"\nwrote {args.out}"
        payload["out"] = args.out
    emit(args, payload, text)
    return EXIT_OK if cal.converged else EXIT_CHECK_FAILED


def _command(args: argparse.Namespace) -> str:
    """The command line that made the calibration, from its options (for the file's header)."""
    words = ["calibrate", args.scenario, "--measured", args.measured]
    words += [w for m in args.map for w in ("--map", m)] + [w for f in args.fit for w in ("--fit", f)]
    words += [w for s in args.set for w in ("--set", s)] + [w for u in args.unit for w in ("--unit", u)]
    words += ["--offset", f"{args.offset:g}"] if args.offset else []
    words += ["--time", args.time] if args.time != "header" else []
    words += ["--time-origin", args.time_origin] if args.time_origin != "first" else []
    words += ["--max-runs", str(args.max_runs)] if args.max_runs != 60 else []
    return "python -m cosim " + shlex.join([*words, "--out", args.out])
