"""What an FMU needs from the Python that hosts it: recorded when it is built, checked when it is
instantiated.

Our FMUs are Python code run by the host's interpreter (pythonfmu's binary takes the Python
symbols from the process that loads it). The builder records in ``resources/requirements.json``
the Python version and the third-party distributions the FMU's bundled code imports, with the
project's version specifiers (``pyproject.toml``: ``numpy>=1.26``, ``scipy>=1.11``,
``exudyn>=1.9``) and the versions it was built with. pythonfmu / pythonfmu3 copy themselves into
``resources/``, so they are not host requirements.

The generated FMU module gets its adapter class through :func:`load_adapter`, which checks the
record before anything else is imported; with a requirement unmet, instantiation raises
``ImportError`` with one message naming every problem, e.g. ``FMU helix needs exudyn>=1.9, not
installed in /usr/bin/python3.11``, which the exporter hands to the importer's FMI logger as
``fmi2Instantiate`` (``fmi3Instantiate...``) fails. This module runs inside the FMU: standard library only, and
syntax that older Pythons still parse (so that their users read the message, not a SyntaxError).
"""

from __future__ import annotations

import ast
import json
import re
import sys
from pathlib import Path
from typing import Any, Iterable

__all__ = ["FILE", "collect", "problems", "check", "load_adapter", "project_requirements"]

FILE = "requirements.json"
# copied into every FMU's resources/ by the exporter itself
_EXPORTERS = {"pythonfmu", "pythonfmu3"}
_CLAUSE = re.compile(r"^\s*(==|!=|<=|>=|<|>|~=)\s*([0-9][0-9A-Za-z.+!-]*)\s*$")


# --------------------------------------------------------------------------- build time


def project_requirements(root: Path) -> tuple[str, dict[str, str]]:
    """(requires-python, distribution name (normalised) -> version specifier) of the project.

    From ``root/pyproject.toml`` when the sources come from a checkout, else from the installed
    ``delta-cosim`` distribution's metadata; empty when neither is there.
    """
    deps: list[str] = []
    python = ""
    pyproject = root / "pyproject.toml"
    if pyproject.exists():
        import tomllib

        project = tomllib.loads(pyproject.read_text()).get("project", {})
        deps, python = list(project.get("dependencies", [])), project.get("requires-python", "")
    else:
        from importlib import metadata

        try:
            dist = metadata.distribution("delta-cosim")
            deps, python = list(dist.requires or []), dist.metadata.get("Requires-Python", "") or ""
        except metadata.PackageNotFoundError:
            pass
    out: dict[str, str] = {}
    for dep in deps:
        dep = dep.split(";", 1)[0].split("#", 1)[0].strip()  # drop environment markers and comments
        m = re.match(r"^([A-Za-z0-9][A-Za-z0-9._-]*)\s*(?:\[[^\]]*\])?\s*(.*)$", dep)
        if m:
            out[_normalise(m.group(1))] = m.group(2).replace(" ", "")
    return python.replace(" ", ""), out


def _normalise(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _imported_modules(files: Iterable[Path]) -> list[str]:
    """Top-level names of every module the files import (at module level or inside functions)."""
    names = set()
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names.update(alias.name.split(".", 1)[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".", 1)[0])
    return sorted(names)


def collect(files: Iterable[Path], root: Path, own_packages: Iterable[str]) -> dict[str, Any]:
    """The requirements record of an FMU bundling ``files`` (project packages ``own_packages``)."""
    from importlib import metadata

    python, specs = project_requirements(root)
    owners = metadata.packages_distributions()
    own = set(own_packages) | _EXPORTERS
    packages = []
    for module in _imported_modules(files):
        if module in own or module in sys.stdlib_module_names or module == "__future__":
            continue
        dist = (owners.get(module) or [module])[0]
        try:
            built = metadata.version(dist)
        except metadata.PackageNotFoundError:
            built = None
        packages.append({"module": module, "distribution": dist, "specifier": specs.get(_normalise(dist), ""),
                         "built_with": built})
    return {"python": python, "python_built_with": ".".join(map(str, sys.version_info[:3])),
            "packages": packages}


# --------------------------------------------------------------------------- run time (inside the FMU)


def _release(version: str) -> tuple[int, ...]:
    """Numeric release part of a version: ``2.4.6rc1`` -> (2, 4, 6)."""
    parts = []
    for piece in version.split("+", 1)[0].split("."):
        m = re.match(r"\d+", piece)
        if m is None:
            break
        parts.append(int(m.group(0)))
        if m.group(0) != piece:
            break
    return tuple(parts)


def _satisfies(version: str, specifier: str) -> bool:
    """Whether ``version`` meets every clause of ``specifier`` (numeric release parts compared)."""
    have = _release(version)
    for clause in filter(None, (c.strip() for c in specifier.split(","))):
        m = _CLAUSE.match(clause)
        if m is None:
            continue  # a form this small check does not read: not held against the host
        op, want = m.group(1), _release(m.group(2))
        width = max(len(have), len(want))
        a, b = have + (0,) * (width - len(have)), want + (0,) * (width - len(want))
        ok = {"==": a == b, "!=": a != b, "<=": a <= b, ">=": a >= b, "<": a < b, ">": a > b,
              "~=": a >= b and a[: max(1, len(want) - 1)] == b[: max(1, len(want) - 1)]}[op]
        if not ok:
            return False
    return True


def _interpreter() -> str:
    exe = sys.executable or ""
    if Path(exe).name.startswith("python"):
        return exe
    # embedded in a host program: name the installation instead of the host's executable
    return "Python {} at {}".format(".".join(map(str, sys.version_info[:3])), sys.prefix)


def problems(record: dict[str, Any]) -> list[str]:
    """What this interpreter lacks of ``record`` (empty: everything is there)."""
    import importlib.util
    from importlib import metadata

    out = []
    here = ".".join(map(str, sys.version_info[:3]))
    if record.get("python") and not _satisfies(here, record["python"]):
        out.append("Python {}, not {} ({})".format(record["python"], here, _interpreter()))
    for req in record.get("packages", []):
        dist, spec = req["distribution"], req.get("specifier") or ""
        wanted = dist + spec
        try:
            found = importlib.util.find_spec(req["module"]) is not None
        except (ImportError, ValueError):
            found = False
        if not found:
            out.append("{}, not installed in {}".format(wanted, _interpreter()))
            continue
        try:
            version = metadata.version(dist)
        except metadata.PackageNotFoundError:
            continue  # importable without distribution metadata (vendored): cannot tell its version
        if spec and not _satisfies(version, spec):
            out.append("{}, found {} in {}".format(wanted, version, _interpreter()))
    return out


def check(resources: str, fmu: str) -> None:
    """Raise ImportError naming every unmet requirement in ``resources``/requirements.json."""
    path = Path(resources) / FILE
    try:
        record = json.loads(path.read_text())
    except FileNotFoundError:
        return  # built before requirements were recorded
    except (OSError, ValueError) as exc:
        raise ImportError("FMU {}: cannot read {}: {}".format(fmu, path, exc)) from None
    missing = problems(record)
    if missing:
        raise ImportError("FMU {} needs {}".format(fmu, "; needs ".join(missing)))


def load_adapter(resources: str, fmu: str, module: str, cls: str, fmi: int) -> type:
    """The FMU's adapter class, or, when the host cannot run it, a stand-in whose construction
    raises ImportError with the reason.

    The exporters' loaders find the class when the module is imported and report an exception
    raised while constructing the instance through the FMI logger (``fmi2Instantiate`` /
    ``fmi3Instantiate*`` return null); an exception raised while the module is imported is
    reported by pythonfmu but crashes pythonfmu3's loader. So the check runs here and the error
    is deferred to instantiation.
    """
    import importlib

    _release_interpreter_state_at_exit(resources)
    try:
        check(resources, fmu)
        return getattr(importlib.import_module(module), cls)
    except ImportError as exc:
        message = str(exc) if str(exc).startswith("FMU ") else "FMU {}: cannot import its code: {}".format(fmu, exc)
    return _unavailable(message, fmi)


def _release_interpreter_state_at_exit(resources: str) -> None:
    """In a Python host on Linux: reset this FMU's PythonFMU library state before the process exits.

    PythonFMU's wrapper (pythonfmu 0.7.0, pythonfmu3 0.3.4) keeps a global ``shared_ptr`` to its
    interpreter state. When the library is still loaded at exit (the first PythonFMU library of a
    process always is), ``exit`` frees that pointer's control block in a static destructor, then the
    library's unload hook resets the pointer and writes into the freed block, and the next heap
    operation aborts ("corrupted double-linked list"; found with valgrind, see ``cosim/fmi/pythonfmu.py``). An
    ``atexit`` handler runs before those destructors: calling the library's own
    ``finalizePythonInterpreter`` there leaves both an empty pointer. This runs in any Python host
    (FMPy, libcosimpy, our master). It is skipped where PythonFMU started the interpreter itself (a
    C/C++ host: the process is not a Python executable), whose state ends the interpreter in order.
    """
    import atexit
    import glob
    import os

    if not hasattr(os, "RTLD_NOLOAD"):  # Windows: the library resets it from DllMain, in order
        return
    try:
        if os.path.realpath("/proc/self/exe") != os.path.realpath(sys.executable):
            return  # the interpreter is embedded by the FMU's library: leave its shutdown alone
    except (OSError, TypeError):
        return
    root = os.path.dirname(os.path.normpath(resources))
    for library in glob.glob(os.path.join(root, "binaries", "*", "*.so")):
        if library not in _RELEASED_AT_EXIT:
            _RELEASED_AT_EXIT.add(library)
            atexit.register(release_pythonfmu_state, library)


_RELEASED_AT_EXIT = set()  # libraries with a handler


def release_pythonfmu_state(library: str) -> None:
    """Reset the global interpreter state of the PythonFMU library ``library`` if it is loaded (see
    above): found by the name it was loaded under and never loaded here (an unloaded library ran its
    hooks in order). Any other library, or one without the function: nothing. The master calls it
    too, for every PythonFMU library it loads (``cosim.fmi.pythonfmu``)."""
    import ctypes
    import os

    if not hasattr(os, "RTLD_NOLOAD"):  # Windows: pythonfmu resets it from DllMain, in order
        return
    try:
        reset = ctypes.CDLL(library, mode=os.RTLD_NOLOAD | os.RTLD_NOW).finalizePythonInterpreter
    except (OSError, AttributeError):
        return
    reset.argtypes, reset.restype = [], None
    reset()


def _unavailable(message: str, fmi: int) -> type:
    import ctypes

    def __init__(self, **kwargs):
        # give back the reference the exporter's class lookup takes (see fmus._names)
        module = sys.modules.get(type(self).__module__)
        if module is not None:
            ctypes.pythonapi.Py_IncRef(ctypes.py_object(vars(module)))
        raise ImportError(message)

    namespace = {"__init__": __init__, "__doc__": message}
    if fmi == 2:
        from pythonfmu import Fmi2Slave  # shipped in the FMU's resources

        bases: tuple[type, ...] = (Fmi2Slave,)
        namespace["do_step"] = lambda self, current_time, step_size: False  # abstract in Fmi2Slave; never called
    else:
        bases = (object,)  # the generated class adds Fmi3SlaveBase
    return type("Unavailable", bases, namespace)
