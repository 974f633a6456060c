"""``python -m cosim robot presets|ik|fk|workspace|singularity``: kinematics, workspace and singularities of a robot
preset."""

from __future__ import annotations

import argparse

from delta.errors import UnreachableError

from ..errors import CosimError, number_option
from .common import EXIT_OK, MARGIN, NUMBER, POSITIVE, emit

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """The ``robot`` command."""
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
    emit(args, payload, "\n".join(lines))
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
    emit(args, payload, text)
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
    emit(args, payload, text)
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
        emit(args, payload, text)
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
        emit(args, payload, f"largest {free} = {value:.4f} m ({value * 1e3:.1f} mm) around {np.round(centre, 4).tolist()}")
        return EXIT_OK
    res = check_cylinder(robot, centre, *dims, args.margin, **options)
    payload = {"robot": robot.name, "centre": centre.tolist(), "cylinder": dims, "ok": res.ok,
               "reason": res.reason, "p": res.p.tolist()}
    if not res.ok:
        x, y, z = res.p
        raise UnreachableError(f"{args.robot}: cylinder not reachable at p = ({x:.4f}, {y:.4f}, {z:.4f}) m: {res.reason}")
    emit(args, payload, "cylinder reachable")
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
    emit(args, payload, text)
    return EXIT_OK
