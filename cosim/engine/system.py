"""System structure: names resolved once into typed ids, wiring checked, Gauss-Seidel order.

Pure with respect to FMI calls: it reads model descriptions (:class:`cosim.fmi.FMUInfo`)
and the scenario, and produces a :class:`SystemPlan` the algorithm executes.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

from ..errors import AlgebraicLoopError, Issue, UnknownSignalError, WiringError, shown
from ..fmi import FMUInfo, Variable
from ..fmi.description import warn_ambiguous
from ..fmi.description import initial_of, settable_at_start
from .algorithm import ALGORITHMS
from .names import quote, split_ref
from .structure import SystemStructure
from .wiring import expand_connection, find_variable, index_text

__all__ = ["Port", "Link", "SystemPlan", "build_plan", "gauss_seidel_order", "find_variable_loop"]


@dataclass(frozen=True)
class Port:
    """A resolved variable: component index and variable (value reference, type, unit).

    ``element`` selects one element of an FMI 3.0 array (0-based, row-major); None is the
    whole variable (every element).
    """

    comp: int
    var: Variable
    element: int | None = None

    @property
    def offset(self) -> int:
        return self.element or 0

    @property
    def count(self) -> int:
        return self.var.count if self.element is None else 1

    def label(self, names: list[str]) -> str:
        return f"{quote(names[self.comp])}.{self.var.name}{index_text(self.var, self.element)}"


@dataclass(frozen=True)
class Link:
    src: Port
    dst: Port

    @property
    def count(self) -> int:
        return self.src.count


# value ranges of FMI 3.0's fixed-width integers (FMI 2.0 Integer and Enumeration: 32 bits)
_INT_RANGE = {"Int8": 8, "Int16": 16, "Int32": 32, "Int64": 64, "Integer": 32, "Enumeration": 64}
_UINT_BITS = {"UInt8": 8, "UInt16": 16, "UInt32": 32, "UInt64": 64}


def typed_value(var: Variable, value: Any) -> tuple[Any, str]:
    """``value`` as ``var``'s declared type, or (None, what is wrong).

    A number written in a way YAML 1.1 reads as a string (``1e12``) counts as a number for a
    Real or an Integer, and stays the text as written for a String; a boolean is not a number,
    a number is not a boolean, an integer type needs a whole number within its range.
    """
    want = var.fmi_type
    if isinstance(value, (list, tuple)):
        out = []
        for v in value:
            x, problem = typed_value(var, v)
            if problem:
                return None, problem
            out.append(x)
        return out, ""
    bad = f"{var.name} is {want}: expected {{}}, got {shown(repr(value))}"
    if var.kind in ("Real", "Integer"):
        x = value
        if isinstance(value, str):
            try:
                x = float(value)
            except ValueError:
                return None, bad.format("a number")
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            return None, bad.format("a number")
        if var.kind == "Real":
            try:
                x = float(x)
            except OverflowError:  # a whole number past the largest double (1e309 written out)
                return None, bad.format("a finite number")
            if not math.isfinite(x):  # nan, or an infinity the FMU would compute with as if it were a value
                return None, bad.format("a finite number")
            return x, _out_of_range(var, x)
        if isinstance(x, float) and not x.is_integer():
            return None, bad.format("a whole number")
        x = int(x)
        if want in _UINT_BITS:
            lo, hi = 0, 2 ** _UINT_BITS[want] - 1
        else:
            bits = _INT_RANGE.get(want, 64)
            lo, hi = -2 ** (bits - 1), 2 ** (bits - 1) - 1
        if not lo <= x <= hi:
            return None, bad.format(f"a whole number in {lo}..{hi}")
        return x, _out_of_range(var, x)
    if var.kind == "Boolean":
        if isinstance(value, bool):
            return value, ""
        if isinstance(value, int) and value in (0, 1):
            return bool(value), ""
        return None, bad.format("true or false")
    if var.kind == "String":
        if isinstance(value, (str, int, float)):
            return value if isinstance(value, str) else str(value), ""
        return None, bad.format("a string")
    return value, ""  # Binary: hexadecimal text, checked when set


def _out_of_range(var: Variable, x: float) -> str:
    """What is wrong with ``x`` against ``var``'s declared ``min`` / ``max`` (inclusive), or ""."""
    lo = _bound(var.min, -math.inf)
    hi = _bound(var.max, math.inf)
    if lo <= x <= hi:
        return ""
    unit = f" {var.unit}" if var.unit else ""
    return f"{var.name} = {x!r}{unit} is outside its declared range [{var.min or '-inf'}, {var.max or 'inf'}]{unit}"


def _bound(text: str | None, default: float) -> float:
    try:
        return default if text is None else float(text)
    except ValueError:  # an enumeration's symbolic bound, or malformed: not checked
        return default


def _flatten(value: Any) -> list:
    if isinstance(value, (list, tuple)):
        return [x for item in value for x in _flatten(item)]
    return [value]


@dataclass
class SystemPlan:
    """Everything the algorithm needs, resolved: components, links, order, what to read and log."""

    names: list[str]
    infos: list[FMUInfo]
    links: list[Link]
    order: list[int]  # Gauss-Seidel order, component indices
    start_values: list[dict[str, Any]]  # per component, variable name -> value
    inputs: list[list[Variable]]  # connected inputs, per component
    outputs: list[list[Variable]]  # outputs read every step, per component
    logged: list[list[Variable]] = field(default_factory=list)  # inputs + outputs recorded, per component
    events: list = field(default_factory=list)  # the scenario's events resolved (cosim.engine.events.EventSpec)

    def port(self, ref: str) -> Port:
        comp, name, _ = split_ref(ref)
        if comp not in self.names or name is None:
            # Refused (correctness): a signal named that the system does not have: what is meant is a guess
            raise UnknownSignalError(f"{ref}: no such component.variable (components: "
                                     f"{', '.join(map(quote, self.names))})")
        i = self.names.index(comp)
        var, element, problem = find_variable(self.infos[i], name)
        if var is None:
            # Refused (correctness): no such variable, or a name declared twice (ambiguous): either could be meant
            raise UnknownSignalError(problem or f"{ref}: no such variable")
        return Port(i, var, element)


def _missing(info: FMUInfo, vname: str, candidates: list[str], comp: str = "") -> str:
    """Why ``vname`` names no variable of ``info``: declared more than once (ambiguous: refused where named, see
    :func:`cosim.fmi.description._ambiguous`), sharing its value reference with another parameter or input (setting
    one would change the other: refused where named), or not at all (with the closest names)."""
    where = f"{info.path.name}{f' ({comp})' if comp else ''}"
    base = vname.split("[", 1)[0]
    for name in (vname, base):
        if name in info.shared:
            return f"{where}: {info.shared[name]}: setting one would change the other, so {name!r} cannot be set or " \
                   "connected"
        if name in info.ambiguous:
            vrs = ", ".join(map(str, info.ambiguous[name]))
            return (f"{where} declares {len(info.ambiguous[name])} variables named {name!r} (value references "
                    f"{vrs}): the name is ambiguous, so it cannot be set or connected")
    return f"{where} has no variable {vname!r}{_close(vname, candidates)}"


def _close(name: str, candidates: list[str]) -> str:
    close = difflib.get_close_matches(name, candidates, n=3, cutoff=0.5)
    if close:
        return "; did you mean " + ", ".join(close) + "?"
    shown = candidates[:8]
    more = "" if len(candidates) <= 8 else f", ... ({len(candidates)} in all)"
    return "; available: " + (", ".join(shown) + more if shown else "none")


def _describe(ref: str, v: Variable) -> str:
    return f"{ref} ({v.fmi_type}{', ' + v.unit if v.unit else ''})"


def build_plan(structure: SystemStructure, infos: Mapping[str, FMUInfo], log_signals: str | None = None) -> SystemPlan:
    """Resolve every name in ``structure`` against the FMUs; raise one error listing every problem, each at the
    file and line (or option) its value came from.

    In turn: the parameters typed as start values (:func:`_start_values`), the connections resolved into
    links (:func:`_links`), the signals the run reads besides (:func:`_reads`), what each component exchanges
    and logs (:func:`_exchanged`), and the order the algorithm needs (:func:`_order`).
    """
    names = list(structure.components)
    idx = {n: i for i, n in enumerate(names)}
    issues: list[Issue] = []
    sources = structure.where()

    def issue(loc: tuple, msg: str) -> None:
        issues.append(sources.issue(loc, msg))

    infos, start_values = _start_values(structure, dict(infos), idx, issue)
    links = _links(structure, infos, idx, issue)
    reads = _reads(structure, infos, idx, issue)
    if issues:
        # Refused (correctness): connections that cannot carry their values (kinds, sizes, causality)
        raise WiringError(issues)
    for info in infos.values():
        warn_ambiguous(info)  # names declared twice that nothing named: left out, said once
    inputs, outputs, logged = _exchanged(structure, infos, names, links, reads, log_signals)
    order = _order(structure, infos, names, links)
    return SystemPlan(names, [infos[n] for n in names], links, order, start_values, inputs, outputs, logged)


Report = Callable[[tuple, str], None]


def _start_values(structure: SystemStructure, infos: dict[str, FMUInfo], idx: dict[str, int],
                  issue: Report) -> tuple[dict[str, FMUInfo], list[dict[str, Any]]]:
    """Each component's parameters typed by the FMU variables they set (arrays sized by the structural
    parameters first); returns the infos with their structure and the start values per component."""
    names = list(idx)
    written = structure.where().written
    start_values: list[dict[str, Any]] = [dict() for _ in names]
    infos = dict(infos)
    for n, comp in structure.components.items():
        structural = {p: v for p, v in comp.parameters.items()
                      if p in infos[n].variables and infos[n].variables[p].causality == "structuralParameter"}
        if structural:  # array sizes follow the scenario's structural parameters
            infos[n] = infos[n].with_structure(structural)
        info = infos[n]
        for pname, value in comp.parameters.items():
            loc = ("components", n, "parameters", pname)
            value = written.get(loc, value)  # a number given as text (--set s=1e3): typed from it below
            whole = info.variables.get(pname)
            if whole is not None and whole.is_array:
                flat = _flatten(value)
                if len(flat) != whole.count:
                    issue(loc, f"{pname} has shape {'x'.join(map(str, whole.shape))} ({whole.count} elements), "
                               f"{len(flat)} value(s) given (give a list, nested lists row by row)")
                    continue
                targets = [(pname, flat)]
            elif isinstance(value, list):
                if whole is not None:  # one value: a list named k[1], k[2] ... and an issue for each
                    issue(loc, f"{pname} is one {whole.fmi_type} value, not a list: got a list of {len(value)}")
                    continue
                if not value:  # set nothing, silently
                    issue(loc, f"an empty list sets none of {pname}[1], {pname}[2], ...: give their values")
                    continue
                targets = [(f"{pname}[{k + 1}]", v) for k, v in enumerate(value)]
            else:
                targets = [(pname, value)]
            for vname, val in targets:
                var = info.variables.get(vname)
                if var is None:
                    settable = [v.name for v in info.variables.values() if settable_at_start(v)]
                    count = 0
                    while f"{vname}[{count + 1}]" in info.variables:
                        count += 1
                    if count and not isinstance(value, list):  # a vector named by its scalar elements k[1] .. k[n]
                        issue(loc, f"{info.path.name} has no variable {vname!r}: {vname}[1] .. {vname}[{count}] are "
                                   f"its {count} elements; set one ({quote(n)}.{vname}[1]={val}) or all at once "
                                   f"with a list ({quote(n)}.{vname}=[{','.join([str(val)] * count)}])")
                        continue
                    issue(loc, _missing(info, vname, settable))
                elif not settable_at_start(var):
                    issue(loc, f"{vname} is {var.causality}/{var.variability} (initial {initial_of(var)}): its value "
                               "cannot be set before initialization (FMI: inputs and non-constant variables with "
                               "initial exact or approx)")
                else:
                    typed, problem = typed_value(var, val)
                    if problem:
                        issue(loc, problem)
                    else:
                        start_values[idx[n]][vname] = typed

    return infos, start_values


def _links(structure: SystemStructure, infos: dict[str, FMUInfo], idx: dict[str, int], issue: Report) -> list[Link]:
    """The connections as links between resolved ports, each checked (causality, kind, size, unit, one driver)."""
    links: list[Link] = []

    def resolve(ref: str, loc: tuple, role: str) -> Port | None:
        comp, vname, _ = split_ref(ref)
        if comp not in idx or vname is None:
            return None  # already reported by the scenario validation
        info = infos[comp]
        want = ("output",) if role == "output" else ("input",)
        var, element, problem = find_variable(info, vname)
        candidates = [v.name for v in info.variables.values() if v.causality in want]
        if var is None:  # a connection's end may also be a prefix (p_ref for p_ref.x .y .z): offered first
            prefixes = dict.fromkeys(n.split("[", 1)[0].rsplit(".", 1)[0] for n in candidates if "." in n or "[" in n)
            candidates = [p for p in prefixes if p not in info.variables] + candidates
            named = vname in info.ambiguous or vname in info.shared
            issue(loc, problem if problem and not named else _missing(info, vname, candidates, comp))
            return None
        if var.causality not in want:
            issue(loc, f"{ref} is a{'n' if var.causality[0] in 'aeiou' else ''} {var.causality}, expected an "
                       f"{role}{_close(vname, candidates)}")
            return None
        return Port(idx[comp], var, element)

    driven: dict[str, int] = {}
    for i, c in enumerate(structure.connections):
        pairs, problem = expand_connection(c.src, c.dst, infos)  # a prefix wires every matching suffix
        if problem:
            issue(("connections", i), problem)
        for c_src, c_dst in pairs:
            src = resolve(c_src, ("connections", i, "from"), "output") if c_src is not None else None
            dst = resolve(c_dst, ("connections", i, "to"), "input") if c_dst is not None else None
            if src is None or dst is None:
                continue
            if src.var.kind != dst.var.kind:
                issue(("connections", i), f"type mismatch: {_describe(c_src, src.var)} -> {_describe(c_dst, dst.var)}")
                continue
            if src.count != dst.count:
                issue(("connections", i), f"size mismatch: {c_src} has {src.count} element(s), {c_dst} has "
                                          f"{dst.count}")
                continue
            if c.units == "check" and src.var.unit and dst.var.unit and src.var.unit != dst.var.unit:
                remedy = ('suppressUnitConversion="true" on the ssd:Connection' if structure.archive
                          else "`units: as_is` on the connection")
                issue(("connections", i), f"unit mismatch: {_describe(c_src, src.var)} -> {_describe(c_dst, dst.var)} "
                                          f"(the master converts no units; {remedy} passes the numbers as they are)")
                continue
            if c_dst in driven:  # after a prefix, or a prefix after an element line, or two prefixes
                issue(("connections", i), f"input {c_dst} is already driven by connections[{driven[c_dst]}]")
                continue
            driven.setdefault(c_dst, i)
            links.append(Link(src, dst))

    return links


def _reads(structure: SystemStructure, infos: dict[str, FMUInfo], idx: dict[str, int], issue: Report) -> list[Port]:
    """The signals the run reads besides the connections (:attr:`SystemStructure.observed`: the compared pair,
    the scene's position)."""
    reads: list[Port] = []
    for ref, loc in ((ref, o.loc) for o in structure.observed for ref in o.signals):
        comp, vname, _ = split_ref(ref)
        if comp in idx and vname is not None:
            var, element, _ = find_variable(infos[comp], vname)
            if var is None or var.causality not in ("output", "input"):
                outs = [v.name for v in infos[comp].variables.values() if v.causality == "output"]
                issue(loc, f"{ref}: no such output{_close(vname, outs)}")
            else:
                reads.append(Port(idx[comp], var, element))
    return reads


def _exchanged(structure: SystemStructure, infos: dict[str, FMUInfo], names: list[str], links: list[Link],
               reads: list[Port], log_signals: str | None) -> tuple[list, list, list]:
    """Per component: the inputs set, the outputs read each step and the variables logged."""
    inputs = [[] for _ in names]
    outputs = [[] for _ in names]
    for link in links:
        if link.dst.var not in inputs[link.dst.comp]:
            inputs[link.dst.comp].append(link.dst.var)
        if link.src.var not in outputs[link.src.comp]:
            outputs[link.src.comp].append(link.src.var)
    for p in reads:
        if p.var.causality == "output" and p.var not in outputs[p.comp]:
            outputs[p.comp].append(p.var)
    signals = log_signals if log_signals is not None else structure.log_signals
    logged = [[] for _ in names]
    if signals != "none":
        for k, n in enumerate(names):
            all_out = [v for v in infos[n].variables.values() if v.causality == "output"]
            for v in all_out:
                if v not in outputs[k]:
                    outputs[k].append(v)
            logged[k] = (list(inputs[k]) if signals == "all" else []) + list(outputs[k])

    return inputs, outputs, logged


def _order(structure: SystemStructure, infos: dict[str, FMUInfo], names: list[str], links: list[Link]) -> list[int]:
    """The components' order: by direct feedthrough when the algorithm reads outputs of the same step (an
    algebraic loop refused, naming the variables in it), any order otherwise."""
    sources = structure.where()
    feedthrough = [_feedthrough(infos[n], structure.components[n].feedthrough) for n in names]
    ordered = ALGORITHMS[structure.algorithm].reads_this_step  # reads outputs of the same macro step: an order needed
    if ordered:
        loop = find_variable_loop(names, links, feedthrough)
        if loop is not None:
            labels, undeclared = loop
            free = [a.name for a in ALGORITHMS.values() if not a.reads_this_step]
            # an SSP archive has no YAML to edit: the advice is the command-line option that does the same
            setting = "--set {}={}" if structure.archive else "{}: {}"
            remedy = "use " + " or ".join(setting.format("algorithm", a) for a in free) if free else ""
            err = AlgebraicLoopError(labels, remedy)
            if undeclared:
                hint = (f"; {', '.join(sorted(map(quote, undeclared)))} do not declare output dependencies in "
                        f"ModelStructure (so every output is assumed to depend on every input): if they have no "
                        f"direct feedthrough, set {setting.format('components.<name>.feedthrough', 'none')}")
                err = AlgebraicLoopError(labels, remedy)
                err.issues[0] = sources.issue(("connections",), err.issues[0].message + hint)
            else:
                err.issues[0] = sources.issue(("connections",), err.issues[0].message)
            err.args = ("\n".join(str(i) for i in err.issues),)
            # Refused (correctness): an algebraic loop: Gauss-Seidel would read a value not yet computed
            raise err
    # an algorithm that reads the previous step only (Jacobi) can take any order
    return gauss_seidel_order(len(names), [(lk.src.comp, lk.dst.comp,
                                            ordered and lk.dst.var.name in feedthrough[lk.dst.comp])
                                           for lk in links])


def _feedthrough(info: FMUInfo, declared: str) -> dict[str, list[str] | None] | set[str]:
    """The set of inputs that reach some output directly (``None`` marks an assumed dependency)."""
    if declared == "none":
        return {}
    inputs = [v.name for v in info.variables.values() if v.causality == "input"]
    out: dict[str, bool] = {}
    for outname, deps in info.feedthrough.items():
        for u in (inputs if deps is None else deps):
            out[u] = out.get(u, False) or deps is not None  # True: declared, False: assumed
    return out


def find_variable_loop(names: list[str], links: list[Link], feedthrough: list[dict]) -> tuple[list[str], set[str]] | None:
    """A cycle in the variable graph (output -> input by connection, input -> outputs by feedthrough).

    Returns the variables along the loop and the components whose dependency was
    assumed (undeclared in ModelStructure), or None when there is no loop.
    """
    # collapse to the component level: an edge src_comp -> dst_comp exists when the connected
    # input feeds through in dst; a cycle of such edges is an algebraic loop
    edges: dict[int, list[tuple[int, Link]]] = {}
    for lk in links:
        if lk.dst.var.name in feedthrough[lk.dst.comp]:
            edges.setdefault(lk.src.comp, []).append((lk.dst.comp, lk))
    colour = [0] * len(names)
    stack: list[tuple[int, Link | None]] = []

    def dfs(u: int) -> list[Link] | None:
        colour[u] = 1
        for v, lk in edges.get(u, []):
            stack.append((v, lk))
            if colour[v] == 1:
                cycle = []
                for node, link in reversed(stack):
                    cycle.append(link)
                    if link.src.comp == v:
                        break
                return list(reversed(cycle))
            if colour[v] == 0:
                found = dfs(v)
                if found:
                    return found
            stack.pop()
        colour[u] = 2
        return None

    for start in range(len(names)):
        if colour[start] == 0:
            cycle = dfs(start)
            if cycle:
                labels = []
                undeclared = set()
                for lk in cycle:
                    labels += [lk.src.label(names), lk.dst.label(names)]
                    if not feedthrough[lk.dst.comp][lk.dst.var.name]:
                        undeclared.add(names[lk.dst.comp])
                labels.append(cycle[0].src.label(names))
                return labels, undeclared
    return None


def gauss_seidel_order(n: int, edges: list[tuple[int, int, bool]]) -> list[int]:
    """Order components so that each runs after the components it reads from.

    ``edges`` are (source, destination, hard): hard when the destination's input feeds
    through to an output. Cycles (only possible through soft edges once loops are
    excluded) are broken at a component whose incoming edges are all soft: it runs
    first and uses its inputs from the previous communication step. Ties keep the
    scenario order.
    """
    incoming: list[set[tuple[int, bool]]] = [set() for _ in range(n)]
    for s, d, hard in edges:
        if s != d:
            incoming[d].add((s, hard))
    done: list[int] = []
    remaining = list(range(n))
    while remaining:
        ready = [c for c in remaining if all(s in done for s, _ in incoming[c])]
        if not ready:
            ready = [c for c in remaining if all(s in done or not hard for s, hard in incoming[c])]
            if not ready:
                # Refused (correctness): an algebraic loop: Gauss-Seidel would read a value not yet computed
                raise AlgebraicLoopError([str(c) for c in remaining])
        c = ready[0]
        done.append(c)
        remaining.remove(c)
    return done
