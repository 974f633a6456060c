"""Where each value of a scenario came from: its file and line, or the command-line option that set it, and
how a problem found there is placed (``file:line: dotted.path: message``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import yaml

from ..errors import Issue

__all__ = ["SourceMap", "collect_lines", "line_for", "issue_at"]

# --------------------------------------------------------------------------- YAML with lines


@dataclass
class SourceMap:
    """Where a scenario's values came from, by key path (``("components", "ctl", "parameters", "gain.kp")``).

    ``file``: the scenario file (or archive); ``lines``: the 1-based line of every key and item in it;
    ``origins``: the command-line option (``--set ctl.gain.kp[1]=2e4``) of every overridden value;
    ``written``: overridden component parameters as written where the text matters (a number given as text,
    ``--set s=1e3``, typed by the FMU variable it sets: :func:`cosim.engine.system.build_plan`).
    """

    file: str | None
    lines: dict[tuple, int] = field(default_factory=dict)
    origins: dict[tuple, str] = field(default_factory=dict)
    written: dict[tuple, Any] = field(default_factory=dict)

    def line(self, loc: tuple) -> int | None:
        """The line of ``loc`` in the file, or of its nearest enclosing key."""
        return line_for(loc, self.lines)

    def issue(self, loc: tuple, message: str) -> Issue:
        """An issue placed where the value at ``loc`` came from (:func:`issue_at`)."""
        return issue_at(loc, message, self.file, self.lines, self.origins)


def collect_lines(node: yaml.Node, path: tuple, lines: dict[tuple, int]) -> None:
    """Record the 1-based line of every key and item, by key path."""
    lines.setdefault(path, node.start_mark.line + 1)
    if isinstance(node, yaml.MappingNode):
        for k, v in node.value:
            key = k.value if isinstance(k, yaml.ScalarNode) else str(k)
            lines[path + (key,)] = k.start_mark.line + 1
            collect_lines(v, path + (key,), lines)
    elif isinstance(node, yaml.SequenceNode):
        for i, v in enumerate(node.value):
            collect_lines(v, path + (i,), lines)


def _format_loc(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


def line_for(loc: tuple, lines: dict[tuple, int]) -> int | None:
    for n in range(len(loc), -1, -1):
        if loc[:n] in lines:
            return lines[loc[:n]]
    return None


def issue_at(loc: tuple, message: str, file: str | None, lines: dict[tuple, int],
             origins: dict[tuple, str] | None = None) -> Issue:
    """An issue placed where the value came from: the command-line option that set it
    (``--set ctl.gain.kp[1]=abc: ...``), else ``file:line`` of the scenario.

    A location that contains an overridden value (``time`` holding ``--stop-time``) is placed
    in the file and names the option too.
    """
    origins = origins or {}
    for path, origin in origins.items():
        if loc[:len(path)] == path:
            return Issue("", message, origin)
    inside = [o for p, o in origins.items() if p[:len(loc)] == loc]
    tail = f" (with {', '.join(inside)})" if inside else ""
    return Issue(_format_loc(loc), message + tail, file, line_for(loc, lines))
