"""What a domain adds to the generic master, and how the master finds it.

The engine runs any FMUs and knows no robot. A domain (this project's delta robot: :mod:`cosim.robot`) plugs in
as one :class:`Plugin`, found through the ``cosim.plugins`` entry point group of the installed distributions
(``pyproject.toml``: ``[project.entry-points."cosim.plugins"]``) the first time the engine asks, or given by
:func:`register` (an application, a test). Each of its parts is optional:

* ``errors``: the domain's error roots; a command shows them as one line, as it shows the master's
  (:func:`cosim.errors.user_errors`).
* ``robots``: the names a scenario's ``robot:`` may take; ``trajectories``: the trajectory types of its
  ``trajectory:`` section (``type`` -> a dataclass whose fields are the ``params``).
* ``scenario_issues(scenario)``: the domain's checks of a scenario, as ``(location, message)``, reported with the
  master's, each at its file and line.
* ``fmu_source``: how a component given as ``fmu: NAME`` gets its FMU (:class:`FmuSource`: a build key, a build).
* ``recording_source``: how a component given as ``recording: FILE`` (:class:`~cosim.engine.structure.Replay`) is
  made: ``(name, replay, base folder, (start_s, stop_s)) -> info``, an object the plan reads as an FMU's
  description (``variables``, ``feedthrough``, ``path``) whose ``slave(name)`` the execution steps. Without a
  plugin that gives one, the ``cosim.recordings`` entry point group's (this project publishes
  :func:`cosim.io.recordings.component.recording_info`: the engine cannot import the file formats), loaded only
  when a scenario has such a component (the reader's imports cost a run's start 0.1-0.2 s).
* ``prepare(system)``: before the plan is made: the domain's pre-flight of a
  :class:`~cosim.engine.structure.SystemStructure` (its components and time grid, and the sections the engine leaves
  to the domain: :attr:`~cosim.engine.structure.SystemStructure.domain`); returns a :class:`Preparation`, whose
  ``report`` is the pre-flight's line and whose ``apply(plan)`` gives the plan the domain's start values.
* ``scene(system)``: what the ``/scene`` channels draw (:class:`Scene`), or None.

Every part that acts on a run takes the system structure, never a front end's schema: a system read from an SSP
archive, made in code or from a YAML scenario is the same to a domain. ``scenario_issues`` alone checks the YAML
scenario as written (it places its findings at the file's lines).

Like libcosim's model URI sub-resolvers, this is the one door: the engine, the FMI layer, the observers and the
file formats import nothing of a domain (``tests/unit/test_layers.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Callable, Hashable, Mapping, Protocol, Sequence

from ..errors import CosimError, domain_errors

__all__ = ["Plugin", "FmuSource", "Preparation", "Scene", "GROUP", "RECORDINGS_GROUP", "installed", "register",
           "fmu_source", "recording_source", "robots", "trajectories", "scenario_issues", "prepare", "scene"]

RECORDINGS_GROUP = "cosim.recordings"
"""The entry point group of the maker of ``recording:`` components (see ``recording_source`` above)."""
GROUP = "cosim.plugins"
"""The entry point group a domain's plugin is published in: each entry names a :class:`Plugin` or a function
without arguments that returns one."""


class FmuSource(Protocol):
    """How components given as ``fmu: NAME`` get their FMU file."""

    def key(self, system: Any, name: str) -> Hashable:
        """What decides the file for ``name`` in ``system`` (a :class:`~cosim.engine.structure.SystemStructure`;
        the same key: the same file; a sweep builds each key once)."""

    def build(self, key: Any) -> Path:
        """The FMU file of ``key``, built or taken from a cache. Raises a :class:`~cosim.errors.CosimError`."""


@dataclass
class Preparation:
    """What a domain's pre-flight found: its one-line report, and the start values it gives the plan."""

    report: str = ""
    apply: Callable[[Any], None] = lambda plan: None


class Scene(Protocol):
    """A drawing of the system for the ``/scene`` channels (``foxglove.SceneUpdate`` in JSON form)."""

    position: Sequence[str]  # the three signals the drawing follows (x, y, z)
    rate_hz: float
    reference: Any  # the whole reference path (n, 3), or None

    def update(self, p: Any, t_ns: int, trail: list | None = None) -> dict | None:
        """The scene with the drawn point at ``p`` (3,), at ``t_ns``; None when it cannot be drawn there."""


@dataclass
class Plugin:
    """One domain's parts (see the module's docstring); every one is optional."""

    name: str
    errors: tuple[type[BaseException], ...] = ()
    robots: Callable[[], Sequence[str]] | None = None
    trajectories: Callable[[], Mapping[str, type]] | None = None
    scenario_issues: Callable[[Any], list[tuple[tuple, str]]] | None = None
    fmu_source: FmuSource | None = None
    recording_source: Callable[[str, Any, Path, tuple[float, float]], Any] | None = None
    prepare: Callable[[Any], Preparation] | None = None
    scene: Callable[[Any], Scene | None] | None = None


_PLUGINS: list[Plugin] | None = None


def installed() -> tuple[Plugin, ...]:
    """The plugins of this process: those registered, else those the installed distributions publish (loaded
    once, on the first call)."""
    global _PLUGINS
    if _PLUGINS is None:
        found: list[Plugin] = []
        for ep in sorted(entry_points(group=GROUP), key=lambda e: e.name):
            try:
                obj = ep.load()
            except Exception as exc:  # noqa: BLE001 - a broken plugin is named, not a traceback
                raise CosimError(f"plugin {ep.name} ({ep.value}) cannot be loaded: "
                                 f"{type(exc).__name__}: {exc}") from exc
            plugin = obj if isinstance(obj, Plugin) else obj()
            if not isinstance(plugin, Plugin):
                raise CosimError(f"plugin {ep.name} ({ep.value}) is not a cosim.engine.plugins.Plugin")
            found.append(plugin)
        _use(found)
    return tuple(_PLUGINS)


def register(*plugins: Plugin) -> list[Plugin] | None:
    """Use exactly ``plugins`` from now on (none: a master without domain); returns the ones used before
    (None: not loaded yet), for a caller that puts them back."""
    global _PLUGINS
    before = _PLUGINS
    _use(list(plugins))
    return before


def _use(plugins: list[Plugin]) -> None:
    global _PLUGINS
    _PLUGINS = plugins
    domain_errors[:] = [cls for p in plugins for cls in p.errors]


def _first(part: str) -> tuple[Plugin | None, Any]:
    for p in installed():
        value = getattr(p, part)
        if value is not None:
            return p, value
    return None, None


def fmu_source() -> FmuSource:
    """The source of ``fmu: NAME`` components; a :class:`~cosim.errors.CosimError` without one."""
    _, source = _first("fmu_source")
    if source is None:
        raise CosimError("no plugin gives FMUs by name (fmu:); give each component's FMU file with path:")
    return source


def recording_source() -> Callable[[str, Any, Path, tuple[float, float]], Any]:
    """The maker of ``recording: FILE`` components; a :class:`~cosim.errors.CosimError` without one."""
    _, source = _first("recording_source")
    if source is not None:
        return source
    for ep in sorted(entry_points(group=RECORDINGS_GROUP), key=lambda e: e.name):
        try:
            return ep.load()
        except Exception as exc:  # noqa: BLE001 - a broken plugin is named, not a traceback
            raise CosimError(f"recordings plugin {ep.name} ({ep.value}) cannot be loaded: "
                             f"{type(exc).__name__}: {exc}") from exc
    raise CosimError(f"nothing replays recordings (recording:): no plugin gives one, and the {RECORDINGS_GROUP} "
                     "entry point group is empty (install cosim)")


def robots() -> list[str]:
    """Every robot name a scenario may give (empty: no domain knows robots)."""
    return [name for p in installed() if p.robots is not None for name in p.robots()]


def trajectories() -> dict[str, type]:
    """Every trajectory type a scenario's ``trajectory:`` section may name, to its class."""
    out: dict[str, type] = {}
    for p in installed():
        if p.trajectories is not None:
            out.update(p.trajectories())
    return out


def scenario_issues(scenario: Any) -> list[tuple[tuple, str]]:
    """The domains' checks of ``scenario``: (location, message) each."""
    return [issue for p in installed() if p.scenario_issues is not None for issue in p.scenario_issues(scenario)]


def prepare(system: Any) -> list[Preparation]:
    """Each domain's pre-flight of ``system`` (its report and start values), in plugin order."""
    return [p.prepare(system) for p in installed() if p.prepare is not None]


def scene(system: Any) -> Scene | None:
    """The drawing of ``system``'s ``/scene`` channels, by the first domain that draws it; None: no scene."""
    for p in installed():
        if p.scene is not None:
            drawing = p.scene(system)
            if drawing is not None:
                return drawing
    return None
