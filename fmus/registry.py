"""Our FMUs: one definition each (:class:`~fmus.definition.FmuDefinition`), and ``build(name)`` for the master
to call on demand.

Each definition holds the FMU's adapter class (its interface, declared once) and its native model class (what it
computes, traced from the :mod:`delta` formulas: the step of both builds, :mod:`fmus.traced`), as objects: this
module imports both layers, and neither imports it. It imports them when a definition's classes are first asked
for (the functions below): what an FMU is (name, role, kind, whether it has a native build) is known without
them, and a run of cached FMUs does not load pythonfmu3 and CasADi.

Robot presets: one FMU per component and robot *kind* (``linear_*``, ``rotary_*``).
The geometry is exposed as fixed ``geometry.*`` parameters whose start values are
the kind's paper preset (thesis linear delta, seed 004 rotary prototype), so the
other preset of the same kind (seed 003's 3-RRR) is a parameter set away, without
one more FMU to build, cache and validate per preset.
"""

from __future__ import annotations

import difflib
import importlib.util
from pathlib import Path

from delta.actuators import KINDS
from delta.errors import DeltaError, ParameterError

from .adapters.trajectories import ADAPTERS
from .builder import build_python
from .definition import FmuDefinition
from .native.build import build_native
from .native.errors import NativeError

__all__ = ["FmuDefinition", "AdapterError", "REGISTRY", "ROLES", "names", "get", "find", "adapter", "build",
           "available", "native_names"]


class AdapterError(DeltaError, ImportError):
    """A module an FMU's adapter needs (:attr:`FmuDefinition.requires`) cannot be imported in this checkout."""


ROLES = ("trajectory", "inverse_kinematics", "forward_kinematics", "controller", "plant")


# The modules of the definitions' classes, imported when a definition's classes are first asked for.
def _controllers():
    from .adapters import controllers
    return controllers


def _kinematics():
    from .adapters import kinematics
    return kinematics


def _plants():
    from .adapters import plants
    return plants


def _analytic_plant():
    from .adapters import analytic_plant
    return analytic_plant


def _plant_me():
    from .adapters import plant_me  # pythonfmu3
    return plant_me


def _models():
    from .native import models  # CasADi
    return models


# control law -> (its adapter class, its native model class: each imported when first asked for; label in tables)
_CONTROLLERS = {"pd": (lambda: _controllers().PDController, lambda: _models().Controller, "PD"),
                "pid": (lambda: _controllers().PIDController, lambda: _models().PIDController, "PID"),
                "pdplus": (lambda: _controllers().PDPlusController, lambda: _models().Controller, "PD+"),
                "ctc": (lambda: _controllers().CTCController, lambda: _models().CTCController, "CTC")}


def _robot_definitions(kind: str) -> list[FmuDefinition]:
    """The FMUs of one robot kind: for each, its adapter and native model, and what it is."""
    return [
        FmuDefinition(f"{kind}_ik", lambda: _kinematics().InverseKinematics, lambda: _models().InverseKinematics,
                      kind, summary=f"inverse kinematics, {kind} delta", role="inverse_kinematics", label="IK"),
        FmuDefinition(f"{kind}_fk", lambda: _kinematics().ForwardKinematics, lambda: _models().ForwardKinematics,
                      kind, summary=f"forward kinematics, {kind} delta", role="forward_kinematics", label="FK"),
        *(FmuDefinition(f"{kind}_{law}", adapter, native, kind, summary=f"{label} joint controller, {kind} delta",
                        role="controller", variant=law, label=label)
          for law, (adapter, native, label) in _CONTROLLERS.items()),
        FmuDefinition(f"{kind}_analytic_plant", lambda: _analytic_plant().AnalyticPlant, lambda: _models().AnalyticPlant,
                      kind, summary=f"analytic dynamics plant (co-simulation), {kind} delta",
                      role="plant", variant="analytic", label="analytic model"),
        FmuDefinition(f"{kind}_analytic_plant_me", lambda: _plant_me().AnalyticPlantME,
                      lambda: _models().AnalyticPlant, kind, fmi=3,
                      summary=f"analytic dynamics plant (FMI 3.0 model exchange), {kind} delta",
                      role="plant", variant="analytic_me", label="analytic model (model exchange)"),
        FmuDefinition(f"{kind}_exudyn_plant", lambda: _plants().ExudynPlant, None, kind,
                      packages=("delta", "multibody"), requires=("multibody.plant",),
                      summary=f"Exudyn multibody plant (full or lumped), {kind} delta",
                      role="plant", variant="exudyn", label="Exudyn multibody"),
    ]


def _trajectory_definitions() -> list[FmuDefinition]:
    """One FMU per trajectory type of :data:`delta.trajectories.TYPES`, as its adapter declares it
    (:data:`fmus.adapters.trajectories.ADAPTERS`: FMU name, class); every one has a native build."""
    return [FmuDefinition(a.FMU, lambda a=a: a, lambda: _models().Trajectory, None,
                          summary=f"{a.TYPE.replace('_', ' ')} trajectory generator",
                          role="trajectory", variant=a.TYPE, label=a.TYPE.replace("_", " ")) for a in ADAPTERS.values()]


REGISTRY: dict[str, FmuDefinition] = {d.name: d for d in [*(d for kind in KINDS for d in _robot_definitions(kind)),
                                                          *_trajectory_definitions()]}
"""FMU name -> its definition, for every FMU of ours."""


def names() -> list[str]:
    return list(REGISTRY)


def find(role: str, kind: str | None = None, variant: str | None = None) -> list[FmuDefinition]:
    """Our FMUs of ``role`` (:data:`ROLES`), for robot ``kind`` and of ``variant`` where given."""
    if role not in ROLES:
        raise ValueError(f"unknown role {role!r}; roles: {', '.join(ROLES)}")
    return [e for e in REGISTRY.values()
            if e.role == role and (kind is None or e.kind == kind) and (variant is None or e.variant == variant)]


def get(name: str) -> FmuDefinition:
    try:
        return REGISTRY[name]
    except KeyError:
        close = difflib.get_close_matches(name, list(REGISTRY), n=3)
        hint = f"did you mean {', '.join(close)}? " if close else ""
        raise ParameterError(f"unknown FMU {name!r}; {hint}our FMUs: {', '.join(REGISTRY)}") from None


def adapter(fmu: FmuDefinition) -> type:
    """The adapter class of ``fmu``, once the modules it needs (:attr:`FmuDefinition.requires`, which it imports
    lazily) are importable here; raises :class:`AdapterError` (an ImportError) naming those that are not."""
    missing = [m for m in fmu.requires if not _importable(m)]
    if missing:
        raise AdapterError(f"FMU {fmu.name}: needs {', '.join(missing)}")
    return fmu.adapter


def _importable(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:  # its parent package is missing
        return False


def available() -> list[str]:
    """FMUs whose adapter can run in this checkout (every module it needs imports)."""
    return [n for n, e in REGISTRY.items() if all(_importable(m) for m in e.requires)]


def native_names() -> list[str]:
    """Our FMUs that have a native build (all but the Exudyn plants)."""
    return [n for n, e in REGISTRY.items() if e.has_native]


def build(name: str, out_dir: str | Path | None = None, *, force: bool = False, native: bool = False,
          fmi: int = 2) -> Path:
    """Build (or reuse from the cache) the FMU called ``name``; return its path.

    ``native``: the C build (:func:`fmus.native.build.build_native`, FMI ``fmi`` = 2 or 3); raises
    :class:`fmus.native.errors.NativeError` if ``name`` has none or there is no C compiler.
    """
    fmu = get(name)
    if not native:
        return build_python(fmu, out_dir, force=force)
    if not fmu.has_native:
        raise NativeError(f"FMU {name!r} has no native build; native FMUs: {', '.join(native_names())}")
    return build_native(fmu, fmi, out_dir, force=force)
