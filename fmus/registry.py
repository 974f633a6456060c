"""FMU names -> adapters, and ``build(name)`` for the master to call on demand.

Robot presets: one FMU per component and robot *kind* (``linear_*``, ``rotary_*``).
The geometry is exposed as fixed ``geometry.*`` parameters whose start values are
the kind's paper preset (thesis linear delta, seed 004 rotary prototype), so the
other preset of the same kind (seed 003's 3-RRR) is a parameter set away, without
one more FMU to build, cache and validate per preset.
"""

from __future__ import annotations

import difflib

import importlib
import importlib.util
from dataclasses import dataclass
from pathlib import Path

from delta.errors import DeltaError

__all__ = ["FmuEntry", "AdapterError", "REGISTRY", "ROLES", "names", "get", "find", "adapter", "build", "available", "native_names"]


class AdapterError(DeltaError, ImportError):
    """An FMU's adapter class, or a module it needs, cannot be imported in this checkout."""


@dataclass(frozen=True)
class FmuEntry:
    """How to build one FMU.

    ``module`` and ``cls`` name the adapter class in :mod:`fmus.adapters` (``fmus.adapters.<module>``
    has an attribute ``cls``); ``kind`` is the robot kind given to the adapter (None for
    robot-independent components); ``packages`` are the project packages bundled (under a unique
    name) with it; ``fmi`` is 2 (co-simulation, pythonfmu) or 3 (model exchange, pythonfmu3);
    ``requires`` are further modules that must be importable for the adapter to run (those its
    module imports lazily, such as ``multibody.plant``).

    What the FMU is, for the tools that look at scenarios and logs (compare, report, table) instead of
    matching names: ``role`` (one of :data:`ROLES`), ``variant`` within the role (the control law, the
    plant's model, the trajectory type) and ``label`` (how a table prints it: ``PD+``, ``CTC``).
    """

    name: str
    module: str
    cls: str
    kind: str | None
    packages: tuple[str, ...] = ("delta",)
    fmi: int = 2
    requires: tuple[str, ...] = ()
    summary: str = ""
    role: str = ""
    variant: str = ""
    label: str = ""


ROLES = ("trajectory", "inverse_kinematics", "forward_kinematics", "controller", "plant")


# control law -> (adapter class, label in tables)
_CONTROLLERS = {"pd": ("PDController", "PD"), "pid": ("PIDController", "PID"), "pdplus": ("PDPlusController", "PD+"),
                "ctc": ("CTCController", "CTC")}


def _robot_entries(kind: str) -> list[FmuEntry]:
    """The FMUs of one robot kind: the declaration of which adapter class serves which FMU, and what it is."""
    return [
        FmuEntry(f"{kind}_ik", "kinematics", "InverseKinematics", kind, summary=f"inverse kinematics, {kind} delta",
                 role="inverse_kinematics", label="IK"),
        FmuEntry(f"{kind}_fk", "kinematics", "ForwardKinematics", kind, summary=f"forward kinematics, {kind} delta",
                 role="forward_kinematics", label="FK"),
        *(FmuEntry(f"{kind}_{ctrl}", "controllers", cls, kind, summary=f"{label} joint controller, {kind} delta",
                   role="controller", variant=ctrl, label=label)
          for ctrl, (cls, label) in _CONTROLLERS.items()),
        FmuEntry(f"{kind}_analytic_plant", "plants", "AnalyticPlant", kind,
                 summary=f"analytic dynamics plant (co-simulation), {kind} delta",
                 role="plant", variant="analytic", label="analytic model"),
        FmuEntry(f"{kind}_analytic_plant_me", "plant_me", "AnalyticPlantME", kind, fmi=3,
                 summary=f"analytic dynamics plant (FMI 3.0 model exchange), {kind} delta",
                 role="plant", variant="analytic_me", label="analytic model (model exchange)"),
        FmuEntry(f"{kind}_exudyn_plant", "plants", "ExudynPlant", kind, packages=("delta", "multibody"),
                 requires=("multibody.plant",), summary=f"Exudyn multibody plant (full or lumped), {kind} delta",
                 role="plant", variant="exudyn", label="Exudyn multibody"),
    ]


def _trajectory_entries() -> list[FmuEntry]:
    """One FMU per trajectory type of :data:`delta.trajectories.TYPES`, as its adapter declares it
    (:data:`fmus.adapters.trajectories.ADAPTERS`: FMU name, class)."""
    from .adapters.trajectories import ADAPTERS

    return [FmuEntry(a.FMU, "trajectories", a.__name__, None,
                     summary=f"{a.TYPE.replace('_', ' ')} trajectory generator", role="trajectory", variant=a.TYPE,
                     label=a.TYPE.replace("_", " ")) for a in ADAPTERS.values()]


def _entries() -> list[FmuEntry]:
    from delta.actuators import KINDS

    return [e for kind in KINDS for e in _robot_entries(kind)] + _trajectory_entries()


REGISTRY: dict[str, FmuEntry] = {e.name: e for e in _entries()}


def names() -> list[str]:
    return list(REGISTRY)


def find(role: str, kind: str | None = None, variant: str | None = None) -> list[FmuEntry]:
    """Our FMUs of ``role`` (:data:`ROLES`), for robot ``kind`` and of ``variant`` where given."""
    if role not in ROLES:
        raise ValueError(f"unknown role {role!r}; roles: {', '.join(ROLES)}")
    return [e for e in REGISTRY.values()
            if e.role == role and (kind is None or e.kind == kind) and (variant is None or e.variant == variant)]


def get(name: str) -> FmuEntry:
    try:
        return REGISTRY[name]
    except KeyError:
        from delta.errors import ParameterError

        close = difflib.get_close_matches(name, list(REGISTRY), n=3)
        hint = f"did you mean {', '.join(close)}? " if close else ""
        raise ParameterError(f"unknown FMU {name!r}; {hint}our FMUs: {', '.join(REGISTRY)}") from None


def adapter(entry: FmuEntry) -> type:
    """The adapter class that builds ``entry`` (``fmus.adapters.<module>.<cls>``), imported.

    Raises :class:`AdapterError` (an ImportError) if its module or the class is missing, or a module it
    needs cannot be imported.
    """
    try:
        module = importlib.import_module(f"{__package__}.adapters.{entry.module}")
    except ImportError as exc:
        raise AdapterError(f"FMU {entry.name}: cannot import its adapter module: {exc}") from exc
    cls = getattr(module, entry.cls, None)
    if not isinstance(cls, type):
        raise AdapterError(f"FMU {entry.name}: {module.__name__} has no adapter class {entry.cls}")
    missing = [m for m in entry.requires if not _importable(m)]
    if missing:
        raise AdapterError(f"FMU {entry.name}: needs {', '.join(missing)}")
    return cls


def _importable(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:  # its parent package is missing
        return False


def _buildable(entry: FmuEntry) -> bool:
    try:
        adapter(entry)
    except ImportError:
        return False
    return True


def available() -> list[str]:
    """FMUs whose adapter class and the modules it needs import in this checkout."""
    return [n for n, e in REGISTRY.items() if _buildable(e)]


def native_names() -> list[str]:
    """Our FMUs that have a native build (all but the Exudyn plants and, for now, the segmented trajectories)."""
    from .native.models import MODELS

    return [n for n in REGISTRY if n in MODELS]


def build(name: str, out_dir: str | Path | None = None, *, force: bool = False, native: bool = False,
          fmi: int = 2) -> Path:
    """Build (or reuse from the cache) the FMU called ``name``; return its path.

    ``native``: the C build (:func:`fmus.native.build.build_native`, FMI ``fmi`` = 2 or 3); raises
    :class:`fmus.native.errors.NativeError` if ``name`` has none or there is no C compiler.
    """
    entry = get(name)
    if native:
        from .native.build import build_native

        return build_native(entry.name, fmi, out_dir, force=force)
    from .builder import build_entry

    return build_entry(entry, out_dir, force=force)
