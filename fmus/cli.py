"""``python -m cosim fmus build|list``: build the FMUs into the cache and show their interfaces."""

from __future__ import annotations

import argparse
import json

__all__ = ["register"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``fmus`` command to the platform CLI."""
    fmus = subparsers.add_parser("fmus", help="build and list the component FMUs")
    sub = fmus.add_subparsers(dest="fmus_command", required=True, metavar="{build,list}")
    p = sub.add_parser("build", help="build every FMU (or the named ones), cached by a hash of its sources")
    p.add_argument("names", nargs="*", help="FMU names (default: every buildable FMU)")
    p.add_argument("--out", default=None, help="cache directory (default .fmu_cache)")
    p.add_argument("--force", action="store_true", help="rebuild even when the cache is current")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_cmd_build)
    p = sub.add_parser("list", help="list the FMUs with their inputs, outputs and parameters")
    p.add_argument("names", nargs="*", help="FMU names (default: all)")
    p.add_argument("--out", default=None, help="cache directory used to build and read them (default .fmu_cache)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_cmd_list)


def _selection(args: argparse.Namespace) -> list[str]:
    from . import registry

    return [registry.get(n).name for n in args.names] if args.names else registry.available()


def _cmd_build(args: argparse.Namespace) -> int:
    import time

    from . import registry

    rows = []
    for name in _selection(args):
        t0 = time.perf_counter()
        path = registry.build(name, args.out, force=args.force)
        rows.append({"name": name, "path": str(path), "seconds": round(time.perf_counter() - t0, 3)})
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        for r in rows:
            print(f"{r['name']:<28} {r['path']}  ({r['seconds']:.2f} s)")
    return 0


def describe(path) -> dict:
    """Inputs, outputs and parameters of a built FMU, from its modelDescription.xml."""
    from fmpy import read_model_description

    md = read_model_description(str(path))
    out: dict = {"fmi": md.fmiVersion, "description": md.description, "inputs": [], "outputs": [], "parameters": []}
    de = md.defaultExperiment
    if de is not None:
        out["default_experiment"] = {"start": de.startTime, "stop": de.stopTime, "step": de.stepSize}
    key = {"input": "inputs", "output": "outputs", "parameter": "parameters"}
    for v in md.modelVariables:
        if v.causality in key:
            item = {"name": v.name, "type": v.type, "unit": v.unit, "start": v.start, "description": v.description}
            if v.causality == "parameter":
                item["variability"] = v.variability
            out[key[v.causality]].append(item)
    return out


def _cmd_list(args: argparse.Namespace) -> int:
    from . import registry

    payload = {}
    for name in _selection(args):
        entry = registry.get(name)
        info = describe(registry.build(name, args.out))
        payload[name] = {"summary": entry.summary, **info}
    if args.json:
        print(json.dumps(payload, indent=2))
        return 0
    for name, info in payload.items():
        print(f"{name} (FMI {info['fmi']}): {info['summary']}")
        for group in ("inputs", "outputs", "parameters"):
            items = ", ".join(f"{v['name']} [{v['unit'] or '-'}]" for v in info[group])
            print(f"  {group}: {items or '-'}")
    return 0
