"""FMU names -> adapters, and ``build(name)`` for the master to call on demand.

Robot presets: one FMU per component and robot *kind* (``linear_*``, ``rotary_*``).
The geometry is exposed as fixed ``geometry.*`` parameters whose start values are
the kind's paper preset (thesis linear delta, seed 004 rotary prototype), so the
other preset of the same kind (seed 003's 3-RRR) is a parameter set away, without
one more FMU to build, cache and validate per preset.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from pathlib import Path

__all__ = ["FmuEntry", "REGISTRY", "names", "get", "build", "available"]


@dataclass(frozen=True)
class FmuEntry:
    """How to build one FMU.

    ``module`` and ``cls`` name the adapter in :mod:`fmus.adapters`; ``kind`` is the
    robot kind given to the adapter (None for robot-independent components);
    ``packages`` are the project packages bundled (under a unique name) with it;
    ``fmi`` is 2 (co-simulation, pythonfmu) or 3 (model exchange, pythonfmu3);
    ``requires`` are core modules that must exist for the adapter to be buildable.
    """

    name: str
    module: str
    cls: str
    kind: str | None
    packages: tuple[str, ...] = ("delta",)
    fmi: int = 2
    requires: tuple[str, ...] = ()
    summary: str = ""


def _entries() -> list[FmuEntry]:
    out: list[FmuEntry] = []
    for kind in ("linear", "rotary"):
        out += [
            FmuEntry(f"{kind}_ik", "kinematics", "InverseKinematics", kind,
                     summary=f"inverse kinematics, {kind} delta"),
            FmuEntry(f"{kind}_fk", "kinematics", "ForwardKinematics", kind,
                     summary=f"forward kinematics, {kind} delta"),
        ]
        for ctrl, cls in (("pd", "PDController"), ("pid", "PIDController"), ("pdplus", "PDPlusController"),
                          ("ctc", "CTCController")):
            out.append(FmuEntry(f"{kind}_{ctrl}", "controllers", cls, kind,
                                requires=("delta.control", "delta.dynamics"),
                                summary=f"{ctrl.upper()} joint controller, {kind} delta"))
        out += [
            FmuEntry(f"{kind}_analytic_plant", "plants", "AnalyticPlant", kind, requires=("delta.dynamics",),
                     summary=f"analytic dynamics plant (co-simulation), {kind} delta"),
            FmuEntry(f"{kind}_analytic_plant_me", "plant_me", "AnalyticPlantME", kind, fmi=3,
                     requires=("delta.dynamics",),
                     summary=f"analytic dynamics plant (FMI 3.0 model exchange), {kind} delta"),
            FmuEntry(f"{kind}_exudyn_plant", "plants", "ExudynPlant", kind, packages=("delta", "multibody"),
                     requires=("multibody",), summary=f"Exudyn multibody plant (full or lumped), {kind} delta"),
        ]
    from .adapters.trajectories import ADAPTERS  # one FMU per type of delta.trajectories.TYPES

    out += [FmuEntry(a.FMU, "trajectories", a.__name__, None, requires=("delta.trajectories",),
                     summary=f"{a.TYPE.replace('_', ' ')} trajectory generator") for a in ADAPTERS.values()]
    return out


REGISTRY: dict[str, FmuEntry] = {e.name: e for e in _entries()}


def names() -> list[str]:
    return list(REGISTRY)


def get(name: str) -> FmuEntry:
    try:
        return REGISTRY[name]
    except KeyError:
        from delta.errors import ParameterError

        raise ParameterError(f"unknown FMU {name!r}; valid FMUs: {', '.join(REGISTRY)}") from None


def _has_adapter(entry: FmuEntry) -> bool:
    adapter = Path(__file__).parent / "adapters" / f"{entry.module}.py"
    return adapter.exists() and f"class {entry.cls}(" in adapter.read_text() and all(_module_has_api(m) for m in entry.requires)


def _module_has_api(module: str) -> bool:
    """Whether a required core module exists (the analytic model lives in delta.dynamics)."""
    try:
        spec = importlib.util.find_spec(module)
    except ModuleNotFoundError:
        return False
    if spec is None:
        return False
    if module == "delta.dynamics":
        mod = importlib.import_module(module)
        return hasattr(mod, "analytic_model")
    if module == "multibody":
        return importlib.util.find_spec("multibody.plant") is not None or hasattr(
            importlib.import_module(module), "make_plant")
    return True


def available() -> list[str]:
    """FMUs whose adapter and core modules exist in this checkout."""
    return [n for n, e in REGISTRY.items() if _has_adapter(e)]


def build(name: str, out_dir: str | Path | None = None, *, force: bool = False) -> Path:
    """Build (or reuse from the cache) the FMU called ``name``; return its path."""
    from .builder import build_entry

    return build_entry(get(name), out_dir, force=force)
