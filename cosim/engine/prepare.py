"""A system made ready to run, with no FMU instantiated: each component's FMU located (a file, or one the domain
plugged in gives by name, :func:`cosim.engine.plugins.fmu_source`), the domain's pre-flight run, the system plan
built and given the start values the domain adds (:func:`cosim.engine.plugins.prepare`), the events resolved.
"Prepare" is everything before the first FMU call; the domain's checks in it are its pre-flight."""

from __future__ import annotations

from pathlib import Path
from typing import Hashable, Mapping

from ..errors import ComponentSourceError, CosimError, Issue
from ..fmi import FMUInfo, load_fmu
from . import plugins
from .events import resolve_events
from .structure import SystemStructure
from .system import build_plan

__all__ = ["locate_fmus", "input_files", "build_key", "build_ours", "prepare"]


def locate_fmus(structure: SystemStructure,
                fmu_files: Mapping[str, str | Path] | None = None) -> dict[str, FMUInfo]:
    """Each component's FMU: ``path`` relative to the structure's folder, or ``fmu`` given by the domain's FMU source;
    a ``replay`` component's description made by the recordings plugin
    (:func:`cosim.engine.plugins.recording_source`).

    ``fmu_files``: our FMUs already built, by :func:`build_key` (a sweep builds them once for every case);
    the others are built here.
    """
    base = structure.folder()
    infos: dict[str, FMUInfo] = {}
    issues: list[Issue] = []
    built = {k: Path(p) for k, p in (fmu_files or {}).items()}
    for name, comp in structure.components.items():
        loc = ("components", name, "fmu" if comp.fmu else "path" if comp.path else "recording")
        where = dict(file=structure.source, line=structure.where().line(loc))
        replay = comp.replay
        if replay is not None:  # no FMU: the recordings plugin reads the file and checks its time range
            try:
                span = (structure.start_ns * 1e-9, structure.stop_ns * 1e-9)
                infos[name] = plugins.recording_source()(name, replay, base, span)
            except CosimError as exc:  # a recording the reader refuses: its message, placed at the component
                issues.append(Issue(f"components.{name}", str(exc), **where))
            continue
        try:
            if comp.path is not None:
                path = Path(comp.path)
                path = path if path.is_absolute() else base / path
                if not path.exists():
                    issues.append(Issue(f"components.{name}.path", f"FMU file not found: {path}", **where))
                    continue
            else:
                key = build_key(structure, comp.fmu)
                if key not in built:
                    built[key] = build_ours(*key)
                path = built[key]
            infos[name] = load_fmu(path)
        except ComponentSourceError as exc:
            issues += [Issue(f"components.{name}", i.message, **where) for i in exc.issues]
    if issues:
        # Refused (correctness): FMUs that cannot be read: the run would lack them
        raise ComponentSourceError(issues)
    return infos


def input_files(structure: SystemStructure) -> tuple[Path, ...]:
    """The files a run of ``structure`` reads: its source (a scenario file, an archive, a log), the SSP archive it
    came from, the FMUs its components give by ``path`` and the recordings they replay; no output may be written
    over one of them."""
    base = structure.folder()
    given = [c.path or (c.replay.file if c.replay is not None else None) for c in structure.components.values()]
    paths = [Path(p) if Path(p).is_absolute() else base / p for p in given if p]
    archive = structure.ssp["file"] if structure.ssp else None  # e.g. a run from a log of an SSP archive's run
    return tuple(Path(p) for p in (structure.source, archive, *paths) if p is not None and p != "<string>")


def build_key(structure: SystemStructure, name: str) -> Hashable:
    """What decides the file of the component ``fmu: name`` in ``structure``
    (:meth:`~cosim.engine.plugins.FmuSource.key`; the delta robot's: the FMU's name, native or python build, FMI
    version)."""
    return plugins.fmu_source().key(structure, name)


def build_ours(*key: object) -> Path:
    """The FMU file of ``key`` (:func:`build_key`), built or taken from the cache by the domain's FMU source. A build
    that cannot be made is one line naming what is missing."""
    try:
        return Path(plugins.fmu_source().build(key))
    except CosimError:
        raise
    except (KeyError, ValueError, LookupError) as exc:  # the source's message names the FMU and the valid ones
        # Refused (correctness): an FMU we do not have
        raise ComponentSourceError(Issue("", str(exc.args[0]) if exc.args else f"unknown FMU {key!r}")) from None


def prepare(structure: SystemStructure, log_signals: str | None = None, *,
            fmu_files: Mapping[str, str | Path] | None = None):
    """Pre-flight and plan of ``structure`` (no FMU instantiated): returns (plan, the pre-flight's report).

    ``log_signals`` overrides the structure's (:func:`cosim.engine.system.build_plan`);
    ``fmu_files``: our FMUs already built (:func:`locate_fmus`).
    """

    preparations = plugins.prepare(structure)  # the domain's pre-flight (its sections), before any FMU is built
    infos = locate_fmus(structure, fmu_files)
    plan = build_plan(structure, infos, log_signals)
    for prep in preparations:
        prep.apply(plan)
    plan.events = resolve_events(structure, plan)
    return plan, "; ".join(p.report for p in preparations if p.report) or "no pre-flight"
