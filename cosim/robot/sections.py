"""The robot's sections of a system: what the front end (a YAML scenario, an SSP archive) validated and left for the
domain in :attr:`cosim.engine.structure.SystemStructure.domain`, as plain values, and what the robot layer makes of
them once per system (kept in its :attr:`~cosim.engine.structure.SystemStructure.made`).

The sections: ``robot`` (a preset name or None), ``fmus`` and ``native_fmi`` (which build of our FMUs),
``trajectory`` (``type``, ``params``, ``check_step``, ``singularity_margin``, or None), ``model`` (an identified
model file, relative to the source, or None), ``initial_state`` (``from_trajectory``, ``component``, ``position``,
``velocity``) and ``scene`` (``position``, ``rate_hz``, or None). A system made in code without them has no robot.
"""

from __future__ import annotations

from typing import Any

from delta.trajectories import TYPES

from ..engine.structure import SystemStructure
from ..errors import ScenarioError

__all__ = ["section", "robot", "trajectory", "trajectory_object", "initial_state"]

_INITIAL_STATE = {"from_trajectory": True, "component": "plant", "position": ["initial.p.x", "initial.p.y",
                                                                                "initial.p.z"],
                  "velocity": ["initial.v.x", "initial.v.y", "initial.v.z"]}


def section(system: SystemStructure, name: str, default: Any = None) -> Any:
    """The domain section ``name`` of ``system`` (``default`` where it has none)."""
    value = system.domain.get(name)
    return default if value is None else value


def robot(system: SystemStructure) -> str | None:
    """The robot preset the system names (None: no robot: nothing to check a trajectory against or draw)."""
    return section(system, "robot")


def trajectory(system: SystemStructure) -> dict[str, Any] | None:
    """The ``trajectory`` section (``type``, ``params`` typed by the type's model, ``check_step``,
    ``singularity_margin``), or None."""
    return section(system, "trajectory")


def initial_state(system: SystemStructure) -> dict[str, Any]:
    """The ``initial_state`` section, its defaults where the system has none."""
    return {**_INITIAL_STATE, **section(system, "initial_state", {})}


def trajectory_object(system: SystemStructure) -> Any:
    """The trajectory of the ``trajectory`` section (an instance of its type's class, :data:`delta.trajectories.TYPES`;
    None without the section), made once per system: the pre-flight, the start values of our trajectory FMUs, the
    initial state and the log's reference path all use this one. Raises :class:`ScenarioError` (placed at the
    section's ``params``) for parameters the trajectory cannot take."""
    spec = trajectory(system)
    if spec is None:
        return None
    if "trajectory" not in system.made:
        cls = TYPES[spec["type"]]
        try:
            system.made["trajectory"] = cls(**spec["params"])
        except (TypeError, ValueError) as exc:
            # Refused (correctness): trajectory parameters the trajectory cannot take
            raise ScenarioError(system.where().issue(("trajectory", "params"), f"{cls.__name__}: {exc}")) from None
    return system.made["trajectory"]
