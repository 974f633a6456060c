"""Overrides of a scenario's values: ``--set NAME=VALUE`` parsed and resolved against the scenario's format
(components' parameters, list items, dotted paths), ``--stop-time``, the files of values a scenario's
``parameters:`` key names (:func:`parameter_file_overrides`), and the numbers kept as written."""

from __future__ import annotations

import difflib
import re
import typing
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel

from ..errors import SHOWN_CHARS, Issue, ScenarioError, file_problem, shown
from .bounded_yaml import load_yaml
from .names import quote, split_ref
from .schema import Scenario

__all__ = ["Overrides", "parse_set_value", "WrittenNumber", "as_written", "has_written", "DOTTED", "resolve_name",
           "dotted_overrides", "apply_overrides", "parameter_file_overrides", "MAX_PARAMETER_FILE_BYTES"]

class Overrides(dict):
    """Loader overrides (key path -> value) that remember the option each came from, so an
    issue with an overridden value cites the option (``--set ctl.gain.kp[1]=abc``), not a
    scenario line the user never wrote."""

    def __init__(self) -> None:
        super().__init__()
        self.origins: dict[tuple, str] = {}

    def put(self, path: tuple, value: Any, origin: str) -> None:
        self[path] = value
        self.origins[path] = origin


def parse_set_value(raw: str, origin: str = "--set") -> Any:
    """A ``--set`` value as YAML reads it, with numbers YAML 1.1 leaves as strings (``1e12``) as numbers
    that keep their text (:class:`WrittenNumber`); YAML that does not parse is a :class:`ScenarioError`
    citing ``origin`` (the option as given)."""
    try:
        return _numbers(load_yaml(raw)[0])
    except yaml.YAMLError as exc:  # YAML's text runs over lines ("in <unicode string>, position 1"): one line
        why = " ".join(str(getattr(exc, "problem", None) or exc).split())
        # Refused (correctness): what the value means cannot be read (an alias bomb is bounded: security)
        raise ScenarioError(Issue("", f"invalid value: {why}", origin)) from None


class WrittenNumber(float):
    """A number written as text that YAML 1.1 reads as a string (``1e3``, ``-2.5E-4``), with that text.

    It is the number everywhere (the scenario holds a float, a sweep's case id and table show it);
    a component parameter given so is typed by its FMU variable from the text
    (:func:`cosim.engine.system.typed_value`): a Real or an Integer takes the number, a String the text as
    written (``"1e3"``, not ``"1000.0"``).
    """

    __slots__ = ("text",)

    def __new__(cls, text: str) -> "WrittenNumber":
        number = super().__new__(cls, text)
        number.text = text
        return number

    def __reduce__(self):
        return WrittenNumber, (self.text,)


def _numbers(value: Any) -> Any:
    """YAML 1.1 strings that are numbers (``1e12``) as :class:`WrittenNumber`, also inside lists."""
    if isinstance(value, list):
        return [_numbers(v) for v in value]
    if isinstance(value, str):
        try:
            return WrittenNumber(value)
        except ValueError:
            return value
    return value


def has_written(value: Any) -> bool:
    if isinstance(value, list):
        return any(has_written(v) for v in value)
    return isinstance(value, WrittenNumber)


def as_written(value: Any) -> Any:
    """``value`` with each :class:`WrittenNumber` as its text, also inside lists."""
    if isinstance(value, list):
        return [as_written(v) for v in value]
    return value.text if isinstance(value, WrittenNumber) else value


DOTTED = "<dotted name>"
"""Head of an override key path ``(DOTTED, "ctl.gain.kp[1]")``: a dotted name that
:func:`scenario_from_data` resolves (:func:`resolve_name`) against the scenario it loads."""


def _model_of(annotation: Any) -> type[BaseModel] | None:
    """The pydantic model inside an annotation (``X``, ``X | None``), if any."""

    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in typing.get_args(annotation):
        found = _model_of(arg)
        if found is not None:
            return found
    return None


def _is_mapping(annotation: Any) -> tuple[bool, Any]:
    """(is a dict, its value annotation)."""

    if typing.get_origin(annotation) is dict:
        return True, typing.get_args(annotation)[1]
    for arg in typing.get_args(annotation):
        if typing.get_origin(arg) is dict:
            return True, typing.get_args(arg)[1]
    return False, None


def _unknown_name(name: str, prefix: str, wrong: str, candidates: list[str], origin: str) -> ScenarioError:

    close = difflib.get_close_matches(wrong, candidates, n=3, cutoff=0.5)
    hint = f"did you mean {', '.join(prefix + quote(c) for c in close)}? " if close else ""
    return ScenarioError(Issue("", f"unknown name {prefix + quote(wrong)!r}; {hint}valid here: "
                                   f"{', '.join(prefix + quote(c) for c in candidates)}", origin))


def _split(text: str, origin: str) -> tuple[str, str | None]:
    try:
        head, rest, _ = split_ref(text)
    except ValueError as exc:
        # Refused (correctness): a name we cannot split: which component is meant is a guess
        raise ScenarioError(Issue("", str(exc), origin)) from None
    return head, rest


_LIST_ITEM = re.compile(r"^([A-Za-z_]\w*)\[(\d+)\]$")


def _dotted(path: tuple) -> str:
    """A key path as a dotted name: ``("events", 0, "at")`` -> ``events[0].at``."""
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (("." if out else "") + quote(str(p)))
    return out


def _list_model(annotation: Any) -> type[BaseModel] | None:
    """The model of the items of a ``list[Model]`` field (``events``), else None."""
    if typing.get_origin(annotation) is list:
        args = typing.get_args(annotation)
        return _model_of(args[0]) if args else None
    return None


def resolve_name(name: str, data: dict[str, Any], origin: str = "--set") -> tuple:
    """The key path a dotted override name addresses in scenario ``data``.

    ``COMP.PARAM`` (``ctl.gain.kp[1]``, ``plant.mass.payload``) is a component parameter;
    otherwise the name walks the scenario's sections: ``time.stop``, ``trajectory.params.rx``,
    ``algorithm``, ``logging.enabled``, ``components.ctl.parameters.gain.kp[1]``, ``events[0].at`` (an item of a
    list of sections, numbered from 0; it must exist). A mapping
    (parameters, ``trajectory.params``) takes the rest of the name as one key. A component name
    with a dot is quoted (``'Ship.Engine'.rpm``, ``components.'Ship.Engine'.step_multiple``;
    :mod:`cosim.engine.names`). An unknown name raises :class:`ScenarioError`, one line citing
    ``origin``, with the close matches.
    """
    components = data.get("components") or {}
    head, rest = _split(name, origin)
    if head in components:
        if not rest:
            # Refused (correctness): replacing a component by one value would drop it
            raise ScenarioError(Issue("", f"{name!r} is a component: name one of its parameters, "
                                          f"{quote(head)}.PARAM", origin))
        return ("components", head, "parameters", rest)
    model: type[BaseModel] = Scenario
    remaining: str | None = name
    path: tuple = ()
    while remaining is not None:
        fields = {(f.alias or n): f for n, f in model.model_fields.items() if n != "source"}
        prefix = _dotted(path) + "." if path else ""
        key, remaining = _split(remaining, origin)
        item = _LIST_ITEM.match(key)
        if item is not None and item.group(1) in fields and _list_model(fields[item.group(1)].annotation):
            # one item of a list of sections (events[0].at): 0-based, as the log numbers events
            base, index = item.group(1), int(item.group(2))
            node = data
            for k in path:
                node = node.get(k, {}) if isinstance(node, dict) else {}
            items = node.get(base) if isinstance(node, dict) else None
            if not isinstance(items, list) or index >= len(items):
                count = len(items) if isinstance(items, list) else 0
                # Refused (correctness): an item the list does not have: the value would be dropped or misplaced
                raise ScenarioError(Issue("", f"{name!r}: {prefix}{base} has {count} item(s), numbered from 0",
                                          origin))
            path += (base, index)
            model = _list_model(fields[base].annotation)
            if remaining is None:
                return path
            continue
        if key not in fields:
            top = list(components) + list(fields) if not path else list(fields)
            # Refused (correctness): a name the scenario does not have: the value would be dropped
            raise _unknown_name(name, prefix, key, top, origin)
        path += (key,)
        ann = fields[key].annotation
        is_map, value_ann = _is_mapping(ann)
        sub = _model_of(value_ann) if is_map else _model_of(ann)
        if is_map and sub is not None:  # components: one key, then its model
            if remaining is None:
                return path
            key, remaining = _split(remaining, origin)
            path += (key,)
            model = sub
        elif is_map:  # parameters, trajectory.params, tolerances: the rest is one key
            return path + (remaining,) if remaining is not None else path
        elif sub is not None:
            model = sub
        elif remaining is not None:
            # Refused (correctness): a value has no keys: the value would be dropped
            raise ScenarioError(Issue("", f"{'.'.join(map(str, path))} is a value, it has no "
                                          f"{remaining!r}", origin))
    return path


def _is_dotted_name(name: Any) -> bool:
    """Whether ``name`` can be a dotted name: a non-empty string neither starting nor ending with a dot."""
    return isinstance(name, str) and bool(name) and not name.startswith(".") and not name.endswith(".")


def dotted_overrides(values: dict[str, Any], origin: str = "override") -> Overrides:
    """Loader overrides from ``{dotted name: value}`` (:func:`resolve_name`), e.g.
    ``{"trajectory.params.rx": 0.05, "time.stop": 0.5, "ctl.gain.kp[1]": 4e4}``."""
    out = Overrides()
    for name, value in values.items():
        if not _is_dotted_name(name):
            # Refused (correctness): no name to put the value under
            raise ScenarioError(Issue("", f"expected a dotted name (component.parameter, time.stop, "
                                          f"trajectory.params.NAME), got {shown(repr(name))}", origin))
        out.put((DOTTED, name), value, f"{origin} {name}={shown(repr(value))}")
    return out


def apply_overrides(sets: list[str], stop_time: float | None = None) -> Overrides:
    """Turn ``--set NAME=value`` (dotted names, :func:`resolve_name`) and ``--stop-time`` into loader overrides."""
    out = Overrides()
    for item in sets:
        origin = f"--set {shown(item)}"
        try:  # a quoted component name may hold '=': the key ends at the first '=' after it
            end = split_ref(item)[2] if item.startswith("'") else 0
        except ValueError as exc:
            # Refused (correctness): a name we cannot split: which component is meant is a guess
            raise ScenarioError(Issue("", str(exc), origin)) from None
        at = item.find("=", end)
        key = item[:at] if at >= 0 else item
        if at < 0 or not _is_dotted_name(key):
            # Refused (correctness): no name to put the value under
            raise ScenarioError(Issue("", f"expected NAME=value (component.parameter, time.stop, "
                                          f"trajectory.params.NAME, ...), got {shown(item)!r}", "--set"))
        value = parse_set_value(item[at + 1:], origin)
        out.put((DOTTED, key), value, origin)
    if stop_time is not None:
        out.put(("time", "stop"), stop_time, f"--stop-time {stop_time:g}")
    return out


MAX_PARAMETER_FILE_BYTES = 64 * 2 ** 10
"""Bytes a file of values (``parameters:``) may hold (``calibrate --out`` writes a few hundred)."""


def parameter_file_overrides(files: Any, base: Path, named_at: str) -> Overrides:
    """The values of the files a scenario's ``parameters:`` key names (one path or a list; relative to ``base``, the
    scenario's folder), as overrides by dotted name (``plant.mass.payload: 0.3``, ``components.meas.offset: 0.21``,
    the names ``--set`` takes), in the files' order (a later file's value wins). ``named_at``: where the key was
    given (``scenario.yaml:7``, or the option), cited by every error. Each value's origin is its file and line, so a
    problem found with it later (an FMU without that parameter, a value of the wrong type) is placed there. Raises
    :class:`ScenarioError`, one line: a file missing or unreadable, not YAML, not a mapping of names to values."""
    out = Overrides()
    if files is None:
        return out
    if isinstance(files, str):
        files = [files]
    for i, name in enumerate(files):
        where = f"{named_at}" + (f" (parameters[{i}])" if len(files) > 1 else "")
        path = Path(name)
        path = path if path.is_absolute() else base / path
        problem = file_problem(path)
        raw = b""
        if problem is None:
            try:
                with open(path, "rb") as f:
                    raw = f.read(MAX_PARAMETER_FILE_BYTES + 1)  # bounded: outside input
            except OSError as exc:
                problem = exc.strerror or str(exc)
        if problem is not None:
            # Refused (correctness): values the scenario names but cannot read would leave it run on other values
            raise ScenarioError(Issue("", f"parameters file {path}: {problem}", where))
        _file_values(raw, str(path), where, out)
    return out


def _file_values(raw: bytes, path: str, named_at: str, out: Overrides) -> None:
    """One file of values into ``out``: a mapping of dotted names to scalars or lists, each placed at its line."""
    def at(line: int | None) -> str:  # where a value of the file came from: every message about it starts so
        return f"{path}" + (f":{line}" if line else "") + f" (a parameters file, named at {named_at})"

    def fail(message: str, line: int | None = None) -> ScenarioError:
        return ScenarioError(Issue("", message, at(line)))

    if len(raw) > MAX_PARAMETER_FILE_BYTES:
        # Refused (security): outside input read whole: its size is bounded
        raise fail(f"larger than {MAX_PARAMETER_FILE_BYTES // 2 ** 10} kB, more than a file of values holds: "
                   "refused unread")
    try:
        data, root = load_yaml(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        # Refused (correctness): text that is not UTF-8 would be read as other names and values
        raise fail(f"not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset {exc.start})",
                   raw[:exc.start].count(b"\n") + 1) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        why = " ".join(str(getattr(exc, "problem", None) or exc).split())
        # Refused (correctness): a file that does not parse gives no values to run with
        raise fail(f"invalid YAML: {why}", mark.line + 1 if mark else None) from None
    if data is None:
        return  # only comments: no values
    if not isinstance(data, dict):
        # Refused (correctness): anything but names and values sets nothing that can be placed
        raise fail("expected a mapping of names to values (plant.mass.payload: 0.3)", 1)
    lines = {k.value: k.start_mark.line + 1 for k, _ in root.value if isinstance(k, yaml.ScalarNode)}
    for name, value in data.items():
        line = lines.get(name)
        if not _is_dotted_name(name):
            # Refused (correctness): a value without a name it could be set by would be dropped
            raise fail(f"expected a dotted name (component.parameter, time.stop, components.NAME.offset), got "
                       f"{shown(repr(name))}", line)
        if name == "parameters":
            # Refused (correctness): files naming files: which value wins would depend on a chain of files
            raise fail("a parameters file cannot name other parameters files", line)
        scalar = (bool, int, float, str)
        if not (isinstance(value, scalar) or isinstance(value, list) and all(
                isinstance(v, scalar) or isinstance(v, list) and all(isinstance(w, scalar) for w in v)
                for v in value)):
            # Refused (correctness): a value of another kind cannot be set on an FMU variable
            raise fail(f"{name}: expected a number, a boolean, a string or a list of them, got "
                       f"{shown(repr(value))}", line)
        out.put((DOTTED, name), _numbers(value), at(line))
