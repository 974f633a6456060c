"""fmus: one definition per FMU, from which both builds come, and modules without import cycles.

* No import cycle among the modules of ``fmus``, counting every import: at module level, inside functions and
  under ``TYPE_CHECKING`` (an import hidden in a function is a cycle all the same, run later).
* The python build bundles exactly the modules of ``fmus`` its adapter imports, directly or not.
* No FMU's code is found by name: no ``importlib.import_module`` in ``fmus`` but in :mod:`fmus.requirements`, the
  loader inside a python FMU, which imports the bundled adapter once the host check passed.
* Every FMU with a native build declares the same variables in both builds (name, type, causality, variability,
  unit, start, description) and the same default experiment: both come from its definition's adapter.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest
from import_graph import imports_anywhere, package_cycles, package_modules

pytest.importorskip("casadi")

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "fmus"


MODULES = package_modules(ROOT, "fmus")


def _imports(module: str) -> set[str]:
    return imports_anywhere(MODULES, module)


def test_fmus_native_is_a_package():
    assert (PACKAGE / "native" / "__init__.py").is_file()
    assert "fmus.native" in MODULES and "fmus.native.build" in MODULES


def test_the_import_graph_is_read():
    """The graph below sees imports in functions and under TYPE_CHECKING, relative and absolute."""
    seen = _imports("fmus.registry")
    assert {"fmus.definition", "fmus.builder", "fmus.native.build", "fmus.adapters.kinematics"} <= seen, seen
    assert "fmus.export2" in _imports("fmus.adapters.kinematics")


def test_fmus_has_no_import_cycle():
    found = package_cycles(ROOT, "fmus")
    assert not found, "\n".join(found)


def test_the_python_build_bundles_every_fmus_module_its_adapter_imports():
    """The builder reads the imports with a regular expression (fast enough for every run's cache check); the
    modules it bundles are those this AST-based graph reaches from the adapter's module and the FMU's loader."""
    from fmus import builder, registry

    for fmu in registry.REGISTRY.values():
        needed: set[str] = set()
        todo = [fmu.adapter.__module__, "fmus.requirements"]
        while todo:
            module = todo.pop()
            if module not in needed:
                needed.add(module)
                parts = module.split(".")
                todo += [*sorted(_imports(module)), *(".".join(parts[:i]) for i in range(1, len(parts)))]
        bundled = {rel for rel in builder.source_files(fmu) if rel.startswith("fmus/")}
        assert bundled == {MODULES[m].relative_to(ROOT).as_posix() for m in needed}, fmu.name


def test_no_fmu_code_is_looked_up_by_name():
    found = []
    for module, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Attribute) and node.attr in ("import_module", "__import__"):
                found.append(f"{module}:{node.lineno}")
            elif isinstance(node, ast.Name) and node.id == "__import__":
                found.append(f"{module}:{node.lineno}")
    assert {f.split(":")[0] for f in found} <= {"fmus.requirements"}, found


# ----------------------------------------------------------------------------- one interface, both builds

def _variables(root: ET.Element) -> dict[str, tuple]:
    """name -> (type, causality, variability, unit, start, description), FMI 2 or 3."""
    out = {}
    if root.get("fmiVersion") == "2.0":
        for sv in root.iter("ScalarVariable"):
            (typed,) = list(sv)
            out[sv.get("name")] = (typed.tag, sv.get("causality"), sv.get("variability"), typed.get("unit"),
                                   _start(typed.tag, typed.get("start")), sv.get("description"))
    else:
        for v in root.find("ModelVariables"):
            start = v.find("Start").get("value") if v.tag == "String" else v.get("start")
            out[v.get("name")] = (v.tag, v.get("causality"), v.get("variability"), v.get("unit"),
                                  _start(v.tag, start), v.get("description"))
    return out


def _start(tag: str, text: str | None):  # noqa: ANN202
    if text is None or tag in ("String", "Boolean"):
        return text
    return float(text)


def _same(a: tuple, b: tuple) -> bool:
    """Equal, the start values to 1e-15: pythonfmu writes them with 16 significant digits, the native build exactly."""
    if a[:4] + a[5:] != b[:4] + b[5:]:
        return False
    if isinstance(a[4], float) and isinstance(b[4], float):
        return math.isclose(a[4], b[4], rel_tol=1e-15, abs_tol=0.0)
    return a[4] == b[4]


def _experiment(root: ET.Element) -> dict[str, float]:
    return {k: float(v) for k, v in root.find("DefaultExperiment").attrib.items() if k != "tolerance"}


def _native_names() -> list[str]:
    from fmus import registry

    return registry.native_names()


@pytest.mark.parametrize("name", _native_names())
def test_python_and_native_builds_declare_the_same_variables(name):
    """Both builds' modelDescription.xml, made in this process from the FMU's definition (no FMU is built): the
    python FMU's variables are the native FMU's. The native FMU has both interfaces in one binary, so the
    model-exchange states' derivatives (locals) and, for the model-exchange plant, the co-simulation plant's
    parameters are the native FMU's only; the python FMI 3 FMU declares the time as its independent variable, as
    does the native FMI 3 build."""
    from fmus import registry
    from fmus.native.interface import interface, model_description

    fmu = registry.get(name)
    python_root = fmu.declared().to_xml()
    native_root = ET.fromstring(model_description(interface(name, fmu.native_model()), fmu.fmi, "token", []))
    python, native = _variables(python_root), _variables(native_root)
    assert python, name
    differ = {n: (v, native.get(n)) for n, v in python.items() if n not in native or not _same(v, native[n])}
    assert not differ, f"{name}: python vs native: {differ}"
    extra = {n: v for n, v in native.items() if n not in python}
    if fmu.fmi == 2:
        assert all(v[1] == "local" for v in extra.values()), f"{name}: native only: {extra}"
    else:
        assert all(v[1] == "parameter" for v in extra.values()), f"{name}: native only: {extra}"
    assert _experiment(python_root) == _experiment(native_root), name
