"""``python -m cosim fmus build|list|info``: build our FMUs into the cache; describe any FMU.

``list`` and ``info`` accept our FMUs by name and any ``.fmu`` file by path (FMI 2.0 or 3.0,
from any tool): FMI version, generating tool, interfaces, default experiment, and every
variable with causality, variability, type, shape, unit and start value.
"""

from __future__ import annotations

import argparse
import json

__all__ = ["register"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``fmus`` command to the platform CLI."""
    fmus = subparsers.add_parser("fmus", help="build and list the component FMUs")
    sub = fmus.add_subparsers(dest="fmus_command", required=True, metavar="COMMAND")
    p = sub.add_parser("build", help="build every FMU (or the named ones), cached by a hash of its sources")
    p.add_argument("names", nargs="*", help="FMU names (default: every buildable FMU; with --native every FMU that "
                                            "has a native build)")
    p.add_argument("--out", default=None,
                   help="also copy the FMUs into this folder, FMUs only (they are built into the user's cache, "
                        "$DELTA_COSIM_CACHE or ~/.cache/delta-cosim/fmus; native FMUs go to OUT/native/fmi2 and "
                        "OUT/native/fmi3)")
    p.add_argument("--force", action="store_true", help="rebuild even when the cache is current")
    _build_options(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_cmd_build)
    p = sub.add_parser("list", help="list FMUs (ours by name, or any .fmu by path) with inputs, outputs and parameters")
    p.add_argument("names", nargs="*", help="FMU names or .fmu paths (default: all of ours)")
    p.add_argument("--out", default=None, help="also copy our FMUs into this folder (default: read them in the user's cache)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_cmd_list)
    p = sub.add_parser("info", help="everything about one FMU (ours by name, or any .fmu by path): interfaces, "
                                    "default experiment, every variable with type, unit and start value")
    p.add_argument("fmu", help="an .fmu path or one of our FMU names")
    p.add_argument("--out", default=None, help="also copy our FMU into this folder (default: read it in the user's cache)")
    p.add_argument("--json", action="store_true")
    _build_options(p)
    p.set_defaults(handler=_cmd_info)


def _build_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--native", action="store_true",
                   help="our FMUs as native C FMUs (no Python on the host; needs a C compiler to build)")
    p.add_argument("--fmi", type=int, choices=(2, 3), default=None,
                   help="FMI version of the native FMUs (default: both for build, 2 for info)")


def _is_path(name: str) -> bool:
    return name.endswith(".fmu") or "/" in name


def _selection(args: argparse.Namespace) -> list[str]:
    from . import registry

    if not args.names:
        return registry.available()
    return [n if _is_path(n) else registry.get(n).name for n in args.names]


def _resolve(name: str, out: str | None, args: argparse.Namespace):
    """(path, summary) of an .fmu path or one of our FMUs (built if needed)."""
    from pathlib import Path

    from . import registry

    if _is_path(name):
        return Path(name), ""
    entry = registry.get(name)
    native = getattr(args, "native", False)
    return registry.build(name, out, native=native, fmi=getattr(args, "fmi", None) or 2), entry.summary


def _cmd_build(args: argparse.Namespace) -> int:
    import time

    from . import registry

    rows = []
    names = _selection(args) if args.names or not args.native else registry.native_names()
    versions = [args.fmi] if args.fmi else [2, 3]
    for name in names:
        for fmi in versions if args.native else [None]:
            t0 = time.perf_counter()
            path = registry.build(name, args.out, force=args.force, native=args.native, fmi=fmi or 2)
            rows.append({"name": name, "build": "native" if args.native else "python", "fmi": fmi,
                         "path": str(path), "seconds": round(time.perf_counter() - t0, 3)})
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        for r in rows:
            print(f"{r['name']:<28} {r['build']:<6} {r['path']}  ({r['seconds']:.2f} s)")
    return 0


def describe(path) -> dict:
    """Interfaces, default experiment and variables of an FMU file, from its modelDescription.xml."""
    from pathlib import Path

    from fmpy import read_model_description

    from delta.errors import DeltaError

    path = Path(path)
    if not path.is_file():
        raise DeltaError(f"{path}: no such FMU file")
    try:
        md = read_model_description(str(path), validate=False)
    except Exception as exc:  # fmpy raises bare Exception for a bad archive or XML  # noqa: BLE001
        raise DeltaError(f"{path}: not a readable FMU: {exc}") from None
    interfaces = {}
    for key, part in (("cs", md.coSimulation), ("me", md.modelExchange)):
        if part is not None:
            interfaces[key] = {"model_identifier": part.modelIdentifier}
            if key == "cs":
                interfaces[key]["variable_step"] = bool(part.canHandleVariableCommunicationStepSize)
            else:
                interfaces[key]["needs_completed_integrator_step"] = bool(part.needsCompletedIntegratorStep)
    out: dict = {"path": str(path), "fmi": md.fmiVersion, "model_name": md.modelName, "build": _build_of(md),
                 "description": md.description, "generation_tool": md.generationTool, "interfaces": interfaces,
                 "continuous_states": md.numberOfContinuousStates, "event_indicators": md.numberOfEventIndicators,
                 "inputs": [], "outputs": [], "parameters": [], "variables": []}
    de = md.defaultExperiment
    if de is not None:
        out["default_experiment"] = {k: None if v is None else float(v) for k, v in (
            ("start", de.startTime), ("stop", de.stopTime), ("step", de.stepSize), ("tolerance", de.tolerance))}
    key = {"input": "inputs", "output": "outputs", "parameter": "parameters", "structuralParameter": "parameters"}
    for v in md.modelVariables:
        unit = v.unit or (v.declaredType.unit if v.declaredType is not None and hasattr(v.declaredType, "unit")
                          else None)
        item = {"name": v.name, "causality": v.causality, "variability": v.variability, "type": v.type,
                "unit": unit, "start": v.start, "description": v.description}
        if v.dimensions:
            item["shape"] = list(v.shape or ())
        out["variables"].append(item)
        if v.causality in key:
            out[key[v.causality]].append(item)
    return out


def _build_of(md) -> str:  # noqa: ANN001
    """Which build an FMU file is: ours native (C), ours or another pythonfmu FMU (Python on the host), or other."""
    tool = md.generationTool or ""
    if tool.startswith("delta-cosim fmus.native"):
        return "native"
    if "pythonfmu" in tool.lower():
        return "python"
    return "other"


_BUILD_TEXT = {"native": "native C (runs without Python)", "python": "python (pythonfmu: needs Python and the "
               "packages of resources/requirements.json on the host)", "other": "built by another tool"}


def _variable_line(v: dict) -> str:
    shape = f"[{'x'.join(map(str, v['shape']))}]" if v.get("shape") else ""
    unit = f" [{v['unit']}]" if v["unit"] else ""
    start = f" = {v['start']}" if v["start"] is not None else ""
    return f"    {v['name']}{shape}: {v['type']} {v['causality']}/{v['variability']}{unit}{start}"


def _cmd_info(args: argparse.Namespace) -> int:
    from cosim.errors import printable

    path, summary = _resolve(args.fmu, args.out, args)
    info = describe(path)
    if summary:
        info["summary"] = summary
    if args.json:
        print(json.dumps(info, indent=2, default=str))
        return 0
    lines = [f"{info['path']}: {info['model_name']} (FMI {info['fmi']}, generated by {info['generation_tool'] or '?'})"]
    if summary or info["description"]:
        lines.append(f"  {summary or info['description']}")
    lines.append(f"  build: {_BUILD_TEXT[info['build']]}")
    for k, v in info["interfaces"].items():
        extra = ", ".join(f"{a}={b}" for a, b in v.items())
        lines.append(f"  interface {'co-simulation' if k == 'cs' else 'model exchange'}: {extra}")
    if "me" in info["interfaces"]:
        lines.append(f"  continuous states: {info['continuous_states']}, event indicators: {info['event_indicators']}")
    de = info.get("default_experiment")
    if de:
        lines.append("  default experiment: " + ", ".join(f"{k} {v}" for k, v in de.items() if v is not None))
    lines.append(f"  variables ({len(info['variables'])}):")
    lines += [_variable_line(v) for v in info["variables"]]
    print("\n".join(printable(line) for line in lines))  # names and descriptions come from the FMU
    return 0


def _cmd_list(args: argparse.Namespace) -> int:
    from cosim.errors import printable

    payload = {}
    for name in _selection(args):
        path, summary = _resolve(name, args.out, args)
        info = describe(path)
        payload[name] = {"summary": summary or info["description"] or "", **info}
    if args.json:
        print(json.dumps(payload, indent=2, default=str))
        return 0
    for name, info in payload.items():
        print(printable(f"{name} (FMI {info['fmi']}, {'+'.join(info['interfaces']) or 'no interface'}): "
                        f"{info['summary']}"))
        for group in ("inputs", "outputs", "parameters"):
            items = ", ".join(f"{v['name']} [{v['unit'] or '-'}]" for v in info[group])
            print(printable(f"  {group}: {items or '-'}"))
    return 0
