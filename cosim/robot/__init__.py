"""The delta robot plugged into the generic master: what the robot adds to a run, as one
:class:`cosim.engine.plugins.Plugin` (published in ``pyproject.toml``'s ``cosim.plugins`` entry point group).

* :mod:`.sources`: our FMUs by name (``fmu: linear_ctc``), python or native builds of :mod:`fmus.registry`;
* :mod:`.preflight`: the trajectory against the workspace, the start values of our trajectory FMUs, the plant's
  initial state and the identified model's parameters;
* :mod:`.model_file`: identified model files (``model:``, written by ``validate-model --out``);
* :mod:`.scene`: the robot drawn on the log's ``/scene`` channels.

The master's rooms below this one (``cosim.engine``, ``cosim.fmi``, ``cosim.observers``, ``cosim.io``) import
nothing of ``delta``, ``fmus`` or ``multibody``; this room is where they meet.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from delta.errors import DeltaError
from delta.robots import PRESETS
from delta.trajectories import TYPES

from ..engine.plugins import Plugin
from ..errors import ScenarioError
from . import preflight, scene, sources
from .model_file import system_model

if TYPE_CHECKING:  # the YAML schema only names the type: the plugin's run-time parts take a system structure
    from ..engine.schema import Scenario

__all__ = ["plugin"]


def _scenario_issues(s: Scenario) -> list[tuple[tuple, str]]:
    """The robot's checks of a scenario: its identified model readable and made for its robot."""
    out: list[tuple[tuple, str]] = []
    if s.model is not None and s.robot is not None:
        try:
            model = system_model(s.structure())
        except ScenarioError as exc:
            out += [(("model",), i.message) for i in exc.issues]
        else:
            if model.robot != s.robot:
                out.append((("model",), f"{s.model} was identified for {model.robot}, the scenario's robot is "
                                        f"{s.robot}"))
    if s.trajectory is not None and s.robot is None:
        out.append((("trajectory",), "a trajectory needs 'robot' (the preset to check it against)"))
    if s.logging.scene is not None and s.robot is None:
        out.append((("logging", "scene"), "the 3D scene needs 'robot'"))
    return out


def plugin() -> Plugin:
    """The delta robot's plugin (the ``cosim.plugins`` entry point ``delta``)."""
    return Plugin(name="delta", errors=(DeltaError,), robots=lambda: list(PRESETS), trajectories=lambda: dict(TYPES),
                  scenario_issues=_scenario_issues, fmu_source=sources.RegistrySource(), prepare=preflight.prepare,
                  scene=scene.scene)
