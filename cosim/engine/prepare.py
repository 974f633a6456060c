"""A scenario made ready to run, with no FMU instantiated: each component's FMU located (a file, or ours built by
the registry, python or native), the pre-flight run, the system plan built with the trajectory's and the initial
state's start values."""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

from fmus import registry
from fmus.native.build import compiler
from fmus.native.errors import CompilerMissingError

from ..errors import ComponentSourceError, Issue, ScenarioError
from ..fmi import FMUInfo, load_fmu
from .events import resolve_events
from .model_file import model_based, model_start_values
from .preflight import initial_state_values, preflight, trajectory_start_values
from .scenario import Scenario
from .system import build_plan

__all__ = ["locate_fmus", "input_files", "build_key", "build_ours", "prepare"]


def locate_fmus(scenario: Scenario, fmu_files: Mapping[str, str | Path] | None = None) -> dict[str, FMUInfo]:
    """Each component's FMU: ``path`` relative to the scenario file, or ``fmu`` built by fmus.registry.

    ``fmu_files``: our FMUs already built, by :func:`build_key` (a sweep builds them once for every case);
    the others are built here.
    """
    base = _scenario_dir(scenario)
    infos: dict[str, FMUInfo] = {}
    issues: list[Issue] = []
    built = {k: Path(p) for k, p in (fmu_files or {}).items()}
    for name, comp in scenario.components.items():
        loc = ("components", name, "fmu" if comp.fmu else "path")
        where = dict(file=scenario.source, line=scenario.sources.line(loc))
        try:
            if comp.path is not None:
                path = Path(comp.path)
                path = path if path.is_absolute() else base / path
                if not path.exists():
                    issues.append(Issue(f"components.{name}.path", f"FMU file not found: {path}", **where))
                    continue
            else:
                key = build_key(scenario, comp.fmu)
                if key not in built:
                    built[key] = build_ours(*key)
                path = built[key]
            infos[name] = load_fmu(path)
        except ComponentSourceError as exc:
            issues += [Issue(f"components.{name}", i.message, **where) for i in exc.issues]
    if issues:
        raise ComponentSourceError(issues)
    return infos


def input_files(scenario: Scenario) -> tuple[Path, ...]:
    """The files a run of ``scenario`` reads: its file (or archive, or log and archive) and the FMUs its components give by ``path``;
    no output may be written over one of them."""
    base = _scenario_dir(scenario)
    paths = [Path(c.path) if Path(c.path).is_absolute() else base / c.path
             for c in scenario.components.values() if c.path is not None]
    archive = scenario.archive["file"] if scenario.archive else None  # a run from a log of an SSP archive's run
    return tuple(Path(p) for p in (scenario.source, archive, *paths) if p is not None and p != "<string>")


def _scenario_dir(scenario: Scenario) -> Path:
    return Path(scenario.source).parent if scenario.source and scenario.source != "<string>" else Path.cwd()


def build_key(scenario: Scenario, name: str) -> tuple[str, bool, int]:
    """(FMU name, native, FMI version) of our FMU ``name`` in ``scenario``: the native build where the scenario asks
    for it (``fmus: native``, or ``auto`` with a C compiler on this machine) and the FMU has one, else the python
    build (FMI 2 co-simulation, or 3 for ``*_me``)."""
    if scenario.fmus == "python":
        return name, False, 2

    if name not in registry.native_names():
        return name, False, 2
    if scenario.fmus == "auto":

        try:
            compiler()
        except CompilerMissingError:
            return name, False, 2
    return name, True, scenario.native_fmi


def build_ours(name: str, native: bool = False, fmi: int = 2) -> Path:
    """Our FMU ``name``, built (or taken from the cache): the python build, or with ``native`` the C build for FMI
    ``fmi``. A native build that cannot be made (no C compiler) is one line naming what is missing."""

    try:
        return Path(registry.build(name, native=native, fmi=fmi))
    except (KeyError, ValueError, LookupError) as exc:  # the registry's message names the FMU and the valid ones
        raise ComponentSourceError(Issue("", str(exc.args[0]) if exc.args else f"unknown FMU {name!r}")) from None


def prepare(scenario: Scenario, log_signals: str | None = None, *,
            fmu_files: Mapping[str, str | Path] | None = None):
    """Pre-flight and plan (no FMU instantiated): returns (plan, preflight report).

    With a ``trajectory:`` section, our trajectory FMUs get their parameters from it.
    ``log_signals`` overrides ``logging.signals`` (:func:`cosim.engine.system.build_plan`);
    ``fmu_files``: our FMUs already built (:func:`locate_fmus`).
    """

    trajectory_values = trajectory_start_values(scenario)  # our trajectory FMUs follow the scenario's section
    report = preflight(scenario)
    infos = locate_fmus(scenario, fmu_files)
    plan = build_plan(scenario, infos, log_signals)
    for name, values in trajectory_values.items():
        c = plan.names.index(name)
        plan.start_values[c] = {**values, **plan.start_values[c]}  # explicit ones are equal (checked)
    model = scenario.model_file()
    if model is not None:  # the identified model: start values of our model-based components, explicit ones win
        for c, name in enumerate(plan.names):
            comp = scenario.components[name]
            if comp.fmu is not None and model_based(registry.get(comp.fmu)):
                values = model_start_values(model, plan.infos[c].variables)
                plan.start_values[c] = {**values, **plan.start_values[c]}
    init = initial_state_values(scenario)
    if init:
        c = plan.names.index(scenario.initial_state.component)
        variables = plan.infos[c].variables
        missing = [n for n in init if n not in variables]
        if missing:

            raise ScenarioError(Issue("initial_state", f"{scenario.initial_state.component} has no "
                                      f"{', '.join(missing)} (set initial_state.position/velocity to its start "
                                      f"parameters, or from_trajectory: false)", scenario.source))
        plan.start_values[c] = {**init, **plan.start_values[c]}  # explicit parameters win
    plan.events = resolve_events(scenario, plan)
    return plan, report
