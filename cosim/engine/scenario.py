"""Scenario files read: YAML loading with line numbers, the checks pydantic cannot make, one error list.

Every problem is reported at once as ``file:line: dotted.path: message``. The format itself is
:mod:`cosim.engine.schema`; overrides (``--set``, ``--stop-time``) are :mod:`cosim.engine.overrides`.
"""

from __future__ import annotations

import copy
import difflib
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from ..errors import Issue, ScenarioError, file_problem
from .bounded_yaml import YamlTooLarge, load_yaml
from .names import expand_signal, split_ref
from . import plugins
from .overrides import DOTTED, Overrides, as_written, has_written, parameter_file_overrides, resolve_name
from .conditions import condition_issue, parse_condition
from .schema import Scenario, TrajectorySpec, trajectory_params_model
from .sources import SourceMap, collect_lines, issue_at

__all__ = ["Scenario", "ScenarioFile", "load_scenario", "read_scenario", "parse_scenario", "scenario_from_data",
           "effective_scenario", "MAX_SCENARIO_BYTES", "trajectory_params_issues"]

_ALIASES = {"src": "from", "dst": "to"}
_UNION_TAG = re.compile(r"^(bool|int|float|str|list\[.*\]|union\[.*\])$")
_PARAM_MSG = "expected a number, a boolean, a string, a list of them, or a list of lists (rows of a matrix)"


@dataclass(frozen=True)
class ScenarioFile:
    """A scenario file read and parsed once (not validated): its data and the line of every key path.

    :meth:`load` validates it with overrides as :func:`load_scenario` does, so variants of one
    file (a sweep's cases) do not read and parse it again.
    """

    file: str
    data: dict[str, Any]
    lines: dict[tuple, int]

    def load(self, overrides: dict[tuple, Any] | None = None) -> Scenario:
        """The scenario with ``overrides`` applied (:func:`scenario_from_data`); raises :class:`ScenarioError`."""
        return scenario_from_data(self.data, self.file, overrides, self.lines)


def _parse_yaml(text: str, file: str) -> ScenarioFile:
    try:
        data, root = load_yaml(text)
    except YamlTooLarge as exc:
        # Refused (security): an alias bomb: bounded before it expands
        raise ScenarioError(Issue("", str(exc), file, 1)) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = " ".join(str(getattr(exc, "problem", None) or exc).split())  # one line, whatever YAML says
        line = mark.line + 1 if mark else None
        if isinstance(exc, yaml.reader.ReaderError):  # a character YAML refuses (NUL, a control character)
            line = text[:exc.position].count("\n") + 1
            code = exc.character if isinstance(exc.character, int) else ord(exc.character)
            problem = f"the character U+{code:04X} at offset {exc.position} is not allowed in YAML"
        # Refused (correctness): what the file means cannot be read
        raise ScenarioError(Issue("", f"invalid YAML: {problem}", file, line)) from None
    lines: dict[tuple, int] = {}
    if root is not None:
        collect_lines(root, (), lines)
    if data is None:  # an empty file, or only comments: one line, not every key it lacks
        # Refused (correctness): nothing to run
        raise ScenarioError(Issue("", "the file holds no scenario (it is empty, or only comments)", file, 1))
    if not isinstance(data, dict):
        # Refused (correctness): what the file means cannot be read as a scenario
        raise ScenarioError(Issue("", "a scenario is a mapping (components, connections, time, ...)", file, 1))
    return ScenarioFile(file, data, lines)


def parse_scenario(text: str, file: str = "<string>", overrides: dict[tuple, Any] | None = None) -> Scenario:
    """Parse and validate scenario YAML; raise :class:`ScenarioError` with every issue."""
    return _parse_yaml(text, file).load(overrides)


def scenario_from_data(data: dict[str, Any], file: str = "<string>", overrides: dict[tuple, Any] | None = None,
                       lines: dict[tuple, int] | None = None) -> Scenario:
    """Validate scenario data (the mapping a YAML file holds, or one built from an SSP file).

    ``overrides`` are applied first; ``lines`` (key path -> line) place the issues in ``file``.
    Raises :class:`ScenarioError` with every issue.
    """

    lines = lines if lines is not None else {}
    origins = dict(getattr(overrides, "origins", {}))
    written: dict[tuple, Any] = {}
    data = copy.deepcopy(data)  # the overrides must not change the caller's mapping
    for path, value, origin in _in_order(data, file, overrides, origins, lines):
        if path[0] == DOTTED:  # a dotted name (--set NAME=VALUE, the Python API, a file of values): resolved here
            path = resolve_name(path[1], data, origin)
            origins[path] = origin
        components = data.get("components") or {}
        if path[0] == "components" and len(path) == 1:  # the whole mapping replaced by an option's value
            # Refused (correctness): replacing every component by one value would drop them
            raise ScenarioError(Issue("", "name a component's parameter (NAME.PARAM=VALUE), not all of components",
                                      origins.get(path, "--set components")))
        if path[0] == "components" and path[1] not in components:
            close = difflib.get_close_matches(path[1], list(components), n=3)
            hint = f"did you mean {', '.join(close)}? " if close else ""
            # Refused (correctness): a value for a component the file does not have would be dropped
            raise ScenarioError(Issue("", f"unknown component {path[1]!r} in {file}; {hint}components: "
                                      f"{', '.join(components)}", origins.get(path, "--set")))
        if path[0] == "components" and len(path) == 4 and path[2] == "parameters":
            if has_written(value):
                written[path] = as_written(value)
            else:  # a later override of the same parameter, written otherwise, replaces the text
                written.pop(path, None)
        node = data
        for key in path[:-1]:
            node = node[key] if isinstance(node, list) else node.setdefault(key, {})
        node[path[-1]] = value
    data["source"] = file
    try:
        scenario = Scenario.model_validate(data)
    except ValidationError as exc:
        by_loc: dict[tuple, list[str]] = {}
        for err in exc.errors():
            # drop pydantic's union-member tags (".int", ".list[...]") from the location
            loc = tuple(_ALIASES.get(p, p) if isinstance(p, str) else p for p in err["loc"]
                        if not (isinstance(p, str) and _UNION_TAG.match(p)))
            msg = err["msg"].removeprefix("Value error, ")
            if err["type"] == "extra_forbidden":
                msg = "unknown key"
            by_loc.setdefault(loc, []).append(msg)
        issues = [issue_at(loc, msgs[0] if len(msgs) == 1 else _PARAM_MSG, file, lines, origins)
                  for loc, msgs in by_loc.items()]
        # Refused (correctness): values of the wrong type or range: the run would not be the one written
        raise ScenarioError(issues) from None
    scenario._sources = SourceMap(file, lines, origins, written)  # before the checks: a domain's reads its structure
    issues = [issue_at(loc, msg, file, lines, origins) for loc, msg in _semantic_issues(scenario)]
    if issues:
        # Refused (correctness): a scenario that contradicts itself: the run would not be the one written
        raise ScenarioError(issues)
    return scenario


def _in_order(data: dict[str, Any], file: str, overrides: dict[tuple, Any] | None, origins: dict[tuple, str],
              lines: dict[tuple, int]) -> list[tuple[tuple, Any, str]]:
    """(key path, value, origin) of every value set over the file's: first those of the files its ``parameters:``
    key names (or ``--set parameters=...``; relative to the scenario's folder), then ``overrides``, which win."""
    files, named_at = data.get("parameters"), f"{file}:{lines.get(('parameters',), 1)}"
    for path, value in (overrides or {}).items():
        if path in (("parameters",), (DOTTED, "parameters")):
            files, named_at = value, origins.get(path, "--set parameters")
    base = Path(file).parent if file and file != "<string>" else Path.cwd()
    readable = isinstance(files, str) or isinstance(files, list) and all(isinstance(f, str) for f in files)
    from_files = parameter_file_overrides(files, base, named_at) if readable else Overrides()  # else: pydantic says
    return [(p, v, from_files.origins[p]) for p, v in from_files.items()] + [
        (p, v, origins.get(p, f"--set {p[1]}" if p[0] == DOTTED else "--set")) for p, v in (overrides or {}).items()]


def _semantic_issues(s: Scenario) -> list[tuple[tuple, str]]:
    """Cross-field checks pydantic cannot see: names that must exist, sections that need a robot."""

    out: list[tuple[tuple, str]] = []
    names = list(s.components)

    def comp_of(ref: str, loc: tuple) -> None:
        try:
            comp = split_ref(ref)[0]
        except ValueError as exc:
            out.append((loc, str(exc)))
            return
        if comp not in s.components:
            close = difflib.get_close_matches(comp, names, n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else f"; components: {', '.join(names)}"
            out.append((loc, f"unknown component {comp!r}{hint}"))

    for i, c in enumerate(s.connections):
        comp_of(c.src, ("connections", i, "from"))
        comp_of(c.dst, ("connections", i, "to"))
    seen: dict[str, int] = {}
    for i, c in enumerate(s.connections):
        if c.dst in seen:
            out.append((("connections", i, "to"), f"input {c.dst} is already driven by connections[{seen[c.dst]}]"))
        seen.setdefault(c.dst, i)
    if s.trajectory is not None:
        out += [(("trajectory", "params") + loc, msg) for loc, msg in trajectory_params_issues(s.trajectory)]
    if s.robot is not None:
        robots = plugins.robots()
        if s.robot not in robots:
            close = difflib.get_close_matches(s.robot, robots, n=3) or robots
            out.append((("robot",), f"unknown robot preset {s.robot!r}; valid: {', '.join(close) or 'none (no plugin)'}"))
    if s.model is not None and s.robot is None:
        out.append((("model",), "an identified model needs 'robot' (the preset it was identified for)"))
    if s.trajectory is not None and s.initial_state.from_trajectory and s.initial_state.position:
        if s.initial_state.component not in s.components:
            out.append((("initial_state", "component"), f"unknown component {s.initial_state.component!r}"))
    if s.logging.scene is not None:
        comp_of(s.logging.scene.position, ("logging", "scene", "position"))
    if s.compare is not None:
        act, ref = expand_signal(s.compare.actual), expand_signal(s.compare.reference)
        if len(act) != len(ref):
            out.append((("compare",), f"actual has {len(act)} signals, reference {len(ref)}"))
        for key, sigs in (("actual", act), ("reference", ref)):
            for sig in sigs:
                comp_of(sig, ("compare", key))
    if s.checks is not None and s.compare is None:
        out.append((("checks",), "acceptance checks need a 'compare' section"))
    for i, e in enumerate(s.events):
        if e.at is not None and e.at < s.time.start:  # after the stop time it is simply not reached (--stop-time)
            out.append((("events", i, "at"), f"{e.at:g} s is before the run's start, {s.time.start:g} s"))
        if e.when is not None:
            problem = condition_issue(e.when)
            if problem:
                out.append((("events", i, "when"), problem))
            else:
                comp_of(parse_condition(e.when)[0], ("events", i, "when"))
        for name in e.set:
            comp_of(name, ("events", i, "set", name))
    return out + plugins.scenario_issues(s)



def trajectory_params_issues(spec: TrajectorySpec) -> list[tuple[tuple, str]]:
    """``trajectory.params`` checked against the type's parameters: (location under params, message)."""

    model = trajectory_params_model(spec.type)
    valid = list(model.model_fields)
    try:
        model.model_validate(spec.params)
    except ValidationError as exc:
        out = []
        for err in exc.errors():
            loc = tuple(err["loc"])
            if err["type"] == "extra_forbidden":
                close = difflib.get_close_matches(str(loc[0]), valid, n=3, cutoff=0.5)
                hint = f"did you mean {', '.join(close)}? " if close else ""
                out.append((loc[:1], f"{spec.type} has no parameter {loc[0]!r}; {hint}valid: {', '.join(valid)}"))
            else:
                out.append((loc, err["msg"].removeprefix("Value error, ")))
        return out
    return []


MAX_SCENARIO_BYTES = 16 * 2 ** 20
"""Bytes a scenario file may hold (the shipped ones hold a few kB; :data:`~cosim.engine.bounded_yaml.MAX_YAML_NODES`
bounds what it expands to)."""


def load_scenario(path: str | Path, overrides: dict[tuple, Any] | None = None) -> Scenario:
    """Load a scenario file. ``overrides`` maps key paths to values (``--set``, ``--stop-time``)."""
    return read_scenario(path).load(overrides)


def read_scenario(path: str | Path) -> ScenarioFile:
    """Read and parse a scenario file, not yet validated (:meth:`ScenarioFile.load`); raises
    :class:`ScenarioError` for a file that cannot be read, is not UTF-8 or not YAML."""
    path = Path(path)
    problem = file_problem(path)
    if problem is None:
        try:
            with open(path, "rb") as f:
                raw = f.read(MAX_SCENARIO_BYTES + 1)
        except OSError as exc:
            problem = exc.strerror or str(exc)
    if problem is not None:
        # Refused (security): a FIFO or a device named as a scenario would be read for ever
        raise ScenarioError(Issue("", f"cannot read scenario: {problem}", str(path))) from None
    if len(raw) > MAX_SCENARIO_BYTES:
        # Refused (security): a scenario is read whole: its size is bounded
        raise ScenarioError(Issue("", f"the file is larger than {MAX_SCENARIO_BYTES // 2 ** 20} MiB, more than any "
                                      "scenario holds (cosim.engine.scenario.MAX_SCENARIO_BYTES): refused", str(path)))
    if raw.startswith(b"PK\x03\x04"):
        # Refused (correctness): a zip archive read as YAML: its bytes say nothing a scenario means
        raise ScenarioError(Issue("", "a zip archive, not a YAML scenario: run, check, layout, sweep and "
                                      "cosim.api.run read an SSP archive whose name ends in .ssp; the other commands "
                                      "take a YAML scenario", str(path)))
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        # Refused (correctness): what the file means cannot be read
        raise ScenarioError(Issue("", f"not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset {exc.start}); "
                                      f"save the scenario as UTF-8", str(path), line)) from None
    return _parse_yaml(text, str(path))




def effective_scenario(scenario: Scenario) -> dict[str, Any]:
    """``scenario`` as it runs, every override applied (:meth:`Scenario.as_run`)."""
    return scenario.as_run()

