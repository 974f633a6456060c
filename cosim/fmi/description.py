"""What an FMU declares: its variables and interfaces, read from modelDescription.xml once per file."""

from __future__ import annotations

import math
import re
import sys
import zipfile
from xml.etree import ElementTree
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Any

from ..errors import ComponentSourceError, Issue, file_problem, printable
from .extract import check_archive, extraction, file_stamp, forget_extractions

REAL, INTEGER, BOOLEAN, STRING, BINARY, CLOCK = "Real", "Integer", "Boolean", "String", "Binary", "Clock"
# declared FMI 2.0 / 3.0 types mapped onto the kinds the master exchanges (connections need equal kinds)
_KIND = {"Real": REAL, "Float64": REAL, "Float32": REAL,
         "Integer": INTEGER, "Enumeration": INTEGER, "Int8": INTEGER, "Int16": INTEGER, "Int32": INTEGER,
         "Int64": INTEGER, "UInt8": INTEGER, "UInt16": INTEGER, "UInt32": INTEGER, "UInt64": INTEGER,
         "Boolean": BOOLEAN, "String": STRING, "Binary": BINARY, "Clock": CLOCK}
# kinds whose values live in Python lists (copied through Python), not in ctypes arrays
PY_KINDS = (STRING, BINARY)


@dataclass(frozen=True)
class Variable:
    """A model variable as the master sees it."""

    name: str
    vr: int
    kind: str  # REAL, INTEGER, BOOLEAN, STRING or BINARY
    fmi_type: str  # the type as declared (Real, Float64, Int32, Enumeration, ...)
    causality: str
    variability: str
    unit: str | None
    description: str | None
    start: Any
    index: int  # 1-based position in ModelVariables (FMI 2.0 ModelStructure indices)
    shape: tuple[int, ...] = ()  # FMI 3.0 array dimensions; () for a scalar
    dims: tuple[tuple[int | None, int | None], ...] = ()  # per dimension: (fixed size, structural parameter vr)
    initial: str | None = None
    min: str | None = None
    max: str | None = None

    @property
    def count(self) -> int:
        """Number of elements (1 for a scalar)."""
        return math.prod(self.shape) if self.shape else 1

    @property
    def is_array(self) -> bool:
        return bool(self.dims)


def initial_of(var: Variable) -> str | None:
    """``var``'s ``initial``, or where the description leaves it out the default the standard gives for its
    causality and variability (FMI 2.0 table of section 2.2.7, FMI 3.0 section 2.4.7.5: the same defaults)."""
    if var.initial:
        return var.initial
    if var.causality in ("parameter", "structuralParameter") or var.variability == "constant":
        return "exact"
    if var.causality in ("calculatedParameter", "output", "local"):
        return "calculated"
    return None  # input, independent: no initial


def settable_at_start(var: Variable) -> bool:
    """Whether an importer may set ``var`` before initialization (FMI 2.0 section 4.2.4 / 3.2.3 and FMI 3.0
    section 2.3: in the instantiated state, any non-constant variable with initial ``exact`` or ``approx``, and
    an input): parameters, inputs, and outputs or locals declared ``initial="exact"`` or ``"approx"``."""
    if var.variability == "constant" or var.causality == "independent":
        return False
    return var.causality == "input" or initial_of(var) in ("exact", "approx")


@dataclass
class FMUInfo:
    """A parsed FMU: model description, variables, interfaces, feedthrough.

    The archive is extracted (into a temporary directory) only when an instance needs its
    binaries (:attr:`unzipdir`), and removed at the end of the run (:class:`Extractions`).
    """

    path: Path
    md: Any  # fmpy.model_description.ModelDescription
    variables: dict[str, Variable]
    stamp: tuple[int, ...] = ()  # the file as read (:func:`file_stamp`): a rebuilt file is another extraction
    ambiguous: dict[str, tuple[int, ...]] = field(default_factory=dict)  # names declared twice (:func:`_ambiguous`)
    notes: tuple[str, ...] = ()  # what the description says that is read as other tools read it, said once
    shared: dict[str, str] = field(default_factory=dict)  # parameters and inputs on one value reference: left out

    @property
    def unzipdir(self) -> Path:
        """The extracted archive (extracted at first use, shared by every copy of this info)."""
        return extraction((self.path, self.stamp))

    @property
    def fmi_major(self) -> int:
        return int(self.md.fmiVersion.split(".")[0])

    @property
    def interfaces(self) -> list[str]:
        return [k for k, v in (("cs", self.md.coSimulation), ("me", self.md.modelExchange)) if v is not None]

    @cached_property
    def feedthrough(self) -> dict[str, list[str] | None]:
        """Output name -> the inputs it depends on directly; None when the FMU does not declare it (every input).
        FMI 1.0 declares it per output as ``<DirectDependency><Name>input</Name>...</DirectDependency>`` (no
        element: every input, FMI 1.0 section 2.10), which fmpy does not read: read here from the XML."""
        inputs = {v.name for v in self.variables.values() if v.causality == "input"}
        if self.fmi_major == 1:
            return _fmi1_direct_dependencies(self.model_description_xml(), inputs,
                                             [v.name for v in self.variables.values() if v.causality == "output"])
        out: dict[str, list[str] | None] = {}
        for u in self.md.outputs:
            if u.dependencies is None:
                out[u.variable.name] = None
            else:
                # every listed input counts, whatever its dependenciesKind (conservative)
                out[u.variable.name] = [d.name for d in u.dependencies if d.name in inputs]
        return out

    def model_description_xml(self) -> bytes:

        with zipfile.ZipFile(self.path) as z:
            return z.read("modelDescription.xml")

    def structural_parameters(self) -> dict[str, Variable]:
        return {n: v for n, v in self.variables.items() if v.causality == "structuralParameter"}

    def with_structure(self, values: dict[str, Any]) -> "FMUInfo":
        """A copy whose array shapes follow the structural parameter values ``values`` (name -> value)."""
        by_vr = {v.vr: int(values[n]) if n in values else _scalar_start(v)
                 for n, v in self.structural_parameters().items()}
        variables = {n: replace(v, shape=_shape(v.dims, by_vr, n)) if v.dims else v
                     for n, v in self.variables.items()}
        return FMUInfo(self.path, self.md, variables, self.stamp, self.ambiguous, self.notes, self.shared)


def _scalar_start(v: Variable) -> int:
    try:
        return int(str(v.start).split()[0])
    except (ValueError, IndexError):
        # Refused (correctness): no array size follows from it
        raise ComponentSourceError(Issue("", f"structural parameter {v.name} has no usable start value "
                                             f"({v.start!r})")) from None


def _shape(dims, by_vr: dict[int, int], name: str) -> tuple[int, ...]:
    shape = []
    for size, vr in dims:
        if size is None:
            if vr not in by_vr:
                # Refused (correctness): no array size follows from it
                raise ComponentSourceError(Issue("", f"{name}: dimension refers to value reference {vr}, "
                                                     "which is not a structural parameter"))
            size = by_vr[vr]
        shape.append(int(size))
    return tuple(shape)


def _fmi1_direct_dependencies(xml: bytes, inputs: set[str], outputs: list[str]) -> dict[str, list[str] | None]:
    """FMI 1.0 outputs' ``DirectDependency`` lists (None where an output has none: it depends on every input)."""
    declared: dict[str, list[str]] = {}
    for sv in ElementTree.fromstring(xml).iter("ScalarVariable"):
        dep = sv.find("DirectDependency")
        if dep is not None and sv.get("causality") == "output":
            names = (n.text.strip() for n in dep.iter("Name") if n.text)
            declared[sv.get("name", "")] = [n for n in names if n in inputs]
    return {name: declared.get(name) for name in outputs}


_CACHE: dict[Path, FMUInfo] = {}  # resolved path -> its description, read from the file of info.stamp


def _unit(v: Any) -> str | None:
    if getattr(v, "unit", None):
        return v.unit
    dt = getattr(v, "declaredType", None)
    return getattr(dt, "unit", None) if dt is not None else None


def _attr(v: Any, name: str) -> str | None:
    value = getattr(v, name, None)
    if value is None and getattr(v, "declaredType", None) is not None:
        value = getattr(v.declaredType, name, None)
    return None if value is None else str(value)


_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_SET_BY_MASTER = ("input", "parameter", "structuralParameter")


def _numbers(text: str, kind: str) -> list[float]:
    """A start, min or max attribute as numbers (an FMI 3.0 array start holds several); ValueError if one is not."""
    if kind == BOOLEAN:
        return [float(("false", "true").index(w) if w in ("false", "true") else int(w)) for w in text.split()]
    return [float(w) if kind == REAL else float(int(w)) for w in text.split()]


def _check_description(path: Path, md: Any) -> tuple[tuple[str, ...], dict[str, str]]:
    """What fmpy reads without validation but the master relies on, one error naming the variable: a model
    identifier that is a C identifier (it names the library loaded: '../../x' or '/x' loaded a library outside the
    FMU), a GUID, value references that are unsigned 32-bit, and start, min and max values of the variable's type (a
    Real start 'abc', or a start NaN or INF of a parameter or an input, was taken). An infinite min or max is no
    bound, as FMPy reads it. Returned, as FMPy and libcosim run such FMUs: notes to say once (a min above the max: a
    value set there is refused where it is set, as outside the range) and the parameters and inputs that share a
    value reference with another of them, name -> what they share (an alias set holds at most one: setting one
    would silently change the other; left out, they are refused where named, as names declared twice are, see
    :func:`_ambiguous`; an output or a local may alias an input or a parameter)."""
    def fail(message: str) -> ComponentSourceError:
        return ComponentSourceError(Issue("", f"{path}: modelDescription.xml: {message}"))

    for kind in ("coSimulation", "modelExchange", "scheduledExecution"):
        interface = getattr(md, kind, None)
        if interface is not None and not _IDENTIFIER.match(str(interface.modelIdentifier or "")):
            # Refused (security): it names the library loaded: '../../x' or '/x' loaded one outside the FMU
            raise fail(f"{kind} modelIdentifier {interface.modelIdentifier!r} is not a C identifier (it names the "
                       "FMU's library: letters, digits and _)")
    if not str(md.fmiVersion or "").startswith("3") and not md.guid:
        # Refused (correctness): FMI 1.0 and 2.0 require it, instantiation passes it (the FMU checks it)
        raise fail("no guid (fmi2Instantiate checks it)")
    aliases: dict[tuple, list[Any]] = {}
    empty: list[str] = []
    for v in md.modelVariables:
        vr = v.valueReference
        if not isinstance(vr, int) or not 0 <= vr < 2 ** 32:
            # Refused (correctness): the FMI calls take a uint32: another variable would be read or set
            raise fail(f"variable {v.name}: valueReference {vr!r} is not an unsigned 32-bit integer")
        kind = _KIND.get(v.type, v.type)
        aliases.setdefault((kind, vr), []).append(v)
        for attr in ("start", "min", "max"):
            text = v.start if attr == "start" else getattr(v, attr, None)
            if text is None or kind not in (REAL, INTEGER, BOOLEAN):
                continue
            try:
                values = _numbers(str(text), kind)
            except ValueError:
                # Refused (correctness): no value of the declared type: FMPy's schema validation refuses it too
                raise fail(f"variable {v.name}: {attr} {str(text)[:40]!r} is not a {v.type} value") from None
            # an infinite min or max is no bound (FMPy reads INF as xs:double allows; the range check takes it so)
            unusable = [x for x in values if math.isnan(x) or (attr == "start" and math.isinf(x))]
            if v.causality in _SET_BY_MASTER and unusable:
                # Refused (correctness): a NaN bound passes every value; a NaN or inf start reaches the equations
                raise fail(f"variable {v.name} ({v.causality}): {attr} {str(text)[:40]!r} is not a finite number")
        lo, hi = getattr(v, "min", None), getattr(v, "max", None)
        if lo is not None and hi is not None and kind in (REAL, INTEGER) and float(lo) > float(hi):
            empty.append(f"{v.name} (min {lo} > max {hi})")
    notes, shared = [], {}
    for (kind, vr), group in aliases.items():
        settable = [v for v in group if v.causality in _SET_BY_MASTER]
        if len(settable) > 1:  # aliases are legal, but a set of them holds at most one parameter or input
            names = ", ".join(f"{v.name} ({v.causality})" for v in settable[:4])
            what = f"{names} share the {kind} value reference {vr}"
            shared.update((v.name, what) for v in settable)
            notes.append(f"{what}: left out (not logged, not settable); the run goes on while nothing names them")
    if empty:
        more = " and more" if len(empty) > 5 else ""
        notes.append(f"variable{'s' if len(empty) > 1 else ''} {', '.join(empty[:5])}{more}: no value is in the "
                     "declared range; the run goes on, and a value set there is refused as outside it")
    return tuple(notes), shared


def _ambiguous(md: Any) -> dict[str, tuple[int, ...]]:
    """The names more than one variable of ``md`` declares, with their value references. FMI requires unique names,
    but tools that do not check run such FMUs (libcosim and Vico run dp-ship's DPController.fmu, which declares
    ``iepsi`` twice): the name is left out of the FMU's variables (not logged, not set), which is safe where
    nothing names it; where the system or the user names it, :mod:`cosim.engine.system` refuses it as ambiguous
    (a correctness need: either variable could be meant)."""
    by_name: dict[str, list[int]] = {}
    for v in md.modelVariables:
        by_name.setdefault(v.name, []).append(v.valueReference)
    return {name: tuple(vrs) for name, vrs in by_name.items() if len(vrs) > 1}


_WARNED: set[Path] = set()


def warn_ambiguous(info: FMUInfo) -> None:
    """Say once per FMU file and process, on stderr, which names ``info`` left out as declared more than once, and
    its other :attr:`~FMUInfo.notes` (what it declares that is read as other tools read it)."""
    if info.path in _WARNED or not (info.ambiguous or info.notes):
        return
    _WARNED.add(info.path)
    for note in info.notes:
        print(printable(f"warning: {info.path.name}: modelDescription.xml: {note}"), file=sys.stderr)
    if not info.ambiguous:
        return
    named = ", ".join(f"{n!r} (value references {', '.join(map(str, vrs))})"
                      for n, vrs in list(info.ambiguous.items())[:5])
    more = " and more" if len(info.ambiguous) > 5 else ""
    print(printable(f"warning: {info.path.name}: modelDescription.xml declares more than one variable named "
                    f"{named}{more}: left out (not logged, not settable); the run goes on while nothing names "
                    "them"), file=sys.stderr)


def load_fmu(path: str | Path) -> FMUInfo:
    """Read the model description (once per path and process); nothing is extracted yet."""
    import fmpy  # lazy: --help loads this module without it

    path = Path(path).resolve()
    try:
        st = path.stat()
    except OSError:
        # Refused (correctness): no FMU, nothing to run
        raise ComponentSourceError(Issue("", f"FMU not found: {path}")) from None
    problem = file_problem(path, directory_ok=True)  # an .fmu file, or the folder of an unpacked one
    if problem is not None:
        # Refused (security): a FIFO or a device named .fmu would be read for ever
        raise ComponentSourceError(Issue("", f"{path}: {problem}")) from None
    stamp = file_stamp(st)
    cached = _CACHE.get(path)
    if cached is not None:
        if cached.stamp == stamp:
            return cached
        forget_extractions(path)  # the file was rebuilt in place: its old extractions are stale
    if path.is_file():
        check_archive(path)
    try:
        md = fmpy.read_model_description(str(path), validate=False)
    except Exception as exc:  # fmpy raises bare Exception for malformed files
        # Refused (correctness): what the FMU declares cannot be read
        raise ComponentSourceError(Issue("", f"{path}: cannot read modelDescription.xml: {exc}")) from None
    clocks = [v for v in md.modelVariables if v.type == "Clock"]
    if clocks:
        names = ", ".join(f"{v.name} (vr {v.valueReference})" for v in clocks[:5])
        # Refused (correctness): clocked partitions would never tick: the run would be silently wrong
        raise ComponentSourceError(Issue("", f"{path.name} declares Clock variables ({names}): clocks (FMI 3.0 "
                                             "scheduled execution and synchronous clocks) are not supported"))
    notes, shared = _check_description(path, md)
    ambiguous = _ambiguous(md)
    variables = {}
    for i, v in enumerate(md.modelVariables, start=1):
        if v.name in ambiguous or v.name in shared:
            continue
        dims = tuple((int(d.start) if d.start is not None else None, d.valueReference) for d in v.dimensions)
        variables[v.name] = Variable(
            name=v.name, vr=v.valueReference, kind=_KIND.get(v.type, v.type), fmi_type=v.type,
            causality=v.causality, variability=v.variability, unit=_unit(v), description=v.description,
            start=v.start, index=i, shape=tuple(v.shape or ()) if dims else (), dims=dims, initial=v.initial,
            min=_attr(v, "min"), max=_attr(v, "max"))
    info = FMUInfo(path, md, variables, stamp, ambiguous, notes, shared)
    _CACHE[path] = info
    return info
