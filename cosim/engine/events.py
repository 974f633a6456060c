"""Scenario events (``events:``), resolved against a system plan: what each one sets, and when it fires.

A *time event* (``at``) sets its values when the run reaches that time: before the macro step that starts
there, or, between two grid points, by cutting that macro step (every active component steps to the event's
time, the values are set, and they step on to the end of their step). A *state event* (``when: "SIGNAL <
VALUE"``) fires when the signal crosses the value in that direction; the execution locates the crossing inside
the macro step by restoring every component's state and stepping again (the Illinois variant of regula falsi,
to the event's ``tolerance``), when every component can save its state; otherwise it fires at the end of the
macro step in which it is seen, with one warning naming the components without state.

What may be set (as libcosim's scenario manager and Maestro allow): an input no connection drives, and a
parameter the FMU declares ``tunable``. Everything else is refused before the run starts, naming the file and
line of the name.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

from ..errors import Issue, ScenarioError, UnknownSignalError, shown
from ..fmi.description import REAL, STRING, Variable
from ..fmi.slave import as_number
from .conditions import parse_condition
from .structure import SystemStructure
from .system import Port, SystemPlan

__all__ = ["Change", "EventSpec", "resolve_events", "resolve_sets", "event_at", "EventState", "FiredEvent"]


@dataclass(frozen=True)
class Change:
    """One value an event sets: component index, variable, its values (flat, ``var.count`` of them)."""

    comp: int
    var: Variable
    values: tuple


@dataclass(frozen=True)
class EventSpec:
    """A scenario event resolved: ``index`` in the list; a time event's ``at_ns`` (and ``at``, s, as written), or a
    state event's ``signal`` (the port read), ``op`` (``<`` or ``>``), ``value``, ``repeat``, ``tolerance``;
    ``changes`` and ``shown`` (name -> value as written, for the log)."""

    index: int
    changes: tuple[Change, ...]
    shown: dict = field(hash=False, compare=False)
    at: float | None = None
    at_ns: int | None = None
    signal: Port | None = None
    op: str = ""
    value: float = 0.0
    repeat: bool = False
    tolerance: float = 1e-6

    def g(self, x: float) -> float:
        """The crossing function: negative once the condition holds (``x < value`` or ``x > value``)."""
        return x - self.value if self.op == "<" else self.value - x


def resolve_events(structure: SystemStructure, plan: SystemPlan) -> list[EventSpec]:
    """The structure's events resolved against ``plan``; raises :class:`ScenarioError` listing every name that
    cannot be set (unknown, an output, a connected input, a fixed parameter) or read, each at its file and line."""
    src = structure.where()
    issues: list[Issue] = []
    driven = {(lk.dst.comp, lk.dst.var.name) for lk in plan.links}
    out: list[EventSpec] = []
    for i, e in enumerate(structure.events):
        changes: list[Change] = []
        for name, value in e.set.items():
            loc = ("events", i, "set", name)
            try:
                port = plan.port(name)
            except UnknownSignalError as exc:
                issues.append(src.issue(loc, str(exc.args[0] if exc.args else exc)))
                continue
            problem = _settable(port, driven, plan.names[port.comp])
            if problem is None:
                values, problem = _values(port.var, value)
            if problem is not None:
                issues.append(src.issue(loc, f"{name}: {problem}"))
                continue
            changes.append(Change(port.comp, port.var, values))
        spec: dict[str, Any] = dict(index=i, changes=tuple(changes), shown=_plain(e.set), tolerance=e.tolerance)
        if e.at is not None:
            spec.update(at=float(e.at), at_ns=round(e.at * 1e9))
        else:
            signal, op, value = parse_condition(e.when)
            try:
                port = plan.port(signal)
            except UnknownSignalError as exc:
                issues.append(src.issue(("events", i, "when"), str(exc.args[0] if exc.args else exc)))
                continue
            if port.var.kind != REAL or port.var.causality != "output":
                issues.append(src.issue(("events", i, "when"), f"{signal} is a {port.var.causality} "
                                        f"{port.var.fmi_type}; a condition reads a Real output"))
                continue
            spec.update(signal=port, op=op, value=value, repeat=e.repeat)
        out.append(EventSpec(**spec))
    if issues:
        # Refused (correctness): events that cannot be applied as written: the run would not be the one written
        raise ScenarioError(issues)
    return out


def _plain(values: dict) -> dict:
    """The values as plain JSON data (numbers written as text, :class:`~cosim.engine.overrides.WrittenNumber`, as
    floats), for the log."""
    return json.loads(json.dumps(values))


def resolve_sets(values: dict[str, Any], plan: SystemPlan, origin: str = "--set") -> tuple[Change, ...]:
    """``component.variable: value`` changes set during a run (a resumed run's ``--set``), resolved against
    ``plan``; raises :class:`ScenarioError` naming ``origin`` for each that cannot be set."""
    driven = {(lk.dst.comp, lk.dst.var.name) for lk in plan.links}
    issues, changes = [], []
    for name, value in values.items():
        try:
            port = plan.port(name)
        except UnknownSignalError as exc:
            issues.append(Issue("", str(exc.args[0] if exc.args else exc), f"{origin} {name}"))
            continue
        problem = _settable(port, driven, plan.names[port.comp])
        if problem is None:
            flat, problem = _values(port.var, value)
        if problem is not None:
            issues.append(Issue("", f"{name}: {problem}", f"{origin} {name}"))
            continue
        changes.append(Change(port.comp, port.var, flat))
    if issues:
        # Refused (correctness): events that cannot be applied as written: the run would not be the one written
        raise ScenarioError(issues)
    return tuple(changes)


def event_at(changes: tuple[Change, ...], values: dict, t_ns: int) -> EventSpec:
    """An event outside the scenario's list (index -1): ``changes`` at ``t_ns`` (a resumed run's ``--set``)."""
    return EventSpec(index=-1, changes=changes, shown=_plain(values), at=t_ns * 1e-9, at_ns=t_ns)


def _settable(port: Port, driven: set, comp: str) -> str | None:
    """Why ``port``'s variable cannot be set during a run, or None."""
    var = port.var
    if port.element is not None:
        return f"an element of the array {var.name}; an event sets a whole variable"
    if var.causality == "input":
        if (port.comp, var.name) in driven:
            return "this input is driven by a connection; an event sets inputs no connection drives"
        return None
    if var.causality == "parameter":
        if var.variability == "tunable":
            return None
        return (f"a {var.variability} parameter of {comp}, which the FMU lets change only before the run; an event "
                "sets tunable parameters and inputs no connection drives")
    return f"a {var.causality} of {comp}; an event sets tunable parameters and inputs no connection drives"


def _values(var: Variable, value: Any) -> tuple[tuple, str | None]:
    flat = list(value) if isinstance(value, (list, tuple)) else [value]
    if len(flat) != var.count:
        return (), f"{len(flat)} value(s) given, the variable has {var.count} element(s)"
    try:
        return tuple(str(v) if var.kind == STRING else as_number(var.kind, v) for v in flat), None
    except (TypeError, ValueError):
        return (), f"{shown(repr(value))} is not a {var.fmi_type} value"


@dataclass
class FiredEvent:
    """An event that fired: its located time ``t`` (s), index in the scenario's list, the values set."""

    t: float
    event: int
    set: dict


class EventState:
    """The run-time state of the resolved events: which time events are still to come, which state events are
    armed, the crossing function of each at the last accepted point, the events fired so far (:attr:`fired`,
    taken by the log) and the warnings (:attr:`warnings`)."""

    def __init__(self, specs: list[EventSpec]):
        self.specs = specs
        self.timed = sorted((s for s in specs if s.at_ns is not None), key=lambda s: (s.at_ns, s.index))
        self.state = [s for s in specs if s.signal is not None]
        self.next_timed = 0  # index into timed of the first not fired
        self.armed = {s.index: True for s in self.state}
        self.g_prev: dict[int, float] = {}
        self.fired: list[FiredEvent] = []
        self.warnings: list[str] = []
        self.located = 0  # state events located by re-stepping
        self.restarts = 0  # steps taken again while locating

    def progress(self) -> dict:
        """What a checkpoint keeps: the time events fired, the state events still armed."""
        return {"next_timed": self.next_timed, "armed": {str(k): v for k, v in self.armed.items()}}

    def resume(self, progress: dict | None, t_ns: int) -> None:
        """A run resumed at ``t_ns`` from a checkpoint's :meth:`progress` (None: the checkpoint's run had no events,
        so every time event before ``t_ns`` is taken as past)."""
        if progress is not None and progress.get("next_timed", 0) <= len(self.timed):
            self.next_timed = int(progress["next_timed"])
            for k, v in (progress.get("armed") or {}).items():
                if int(k) in self.armed:
                    self.armed[int(k)] = bool(v)
            return
        while self.next_timed < len(self.timed) and self.timed[self.next_timed].at_ns < t_ns:
            self.next_timed += 1

    def due(self, t_ns: int) -> list[EventSpec]:
        """Time events at ``t_ns`` not fired yet (taken)."""
        out = []
        while self.next_timed < len(self.timed) and self.timed[self.next_timed].at_ns <= t_ns:
            out.append(self.timed[self.next_timed])
            self.next_timed += 1
        return out

    def inside(self, t0_ns: int, t1_ns: int) -> list[EventSpec]:
        """Time events strictly between ``t0_ns`` and ``t1_ns`` not fired yet (not taken)."""
        out = []
        j = self.next_timed
        while j < len(self.timed) and self.timed[j].at_ns < t1_ns:
            if self.timed[j].at_ns > t0_ns:
                out.append(self.timed[j])
            j += 1
        return out
