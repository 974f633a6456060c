"""The master's rooms: imports point one way, with no cycle and no hidden import.

Layers, lowest first: ``errors``, ``cbuild`` (the C helpers' compiler), ``fmi`` (FMU access), ``engine`` (scenario, plan, algorithms, execution),
``observers``, ``io``, ``robot`` (the delta robot plugged in), ``run`` (a scenario's run, composed), ``analysis``, ``api``, the CLI. A module imports
only from its own layer or below. Inside a layer, module-level imports form no cycle. Our own modules are
imported at module level, except in the CLI (``cosim/cli/`` imports each command's modules inside the
command, so that ``--help`` starts in a fraction of a second; its docstring says so).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from import_graph import cycles

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "cosim"
LAYERS = ["errors", "cbuild", "procs", "fmi", "engine", "observers", "io", "robot", "run", "analysis", "api", "cli", "__main__"]
LAZY_OK = {"cosim.cli", *(f"cosim.cli.{p.stem}" for p in (PACKAGE / "cli").glob("*.py") if p.stem != "__init__")}
"""The CLI (``cosim/cli/``: the entry and one module per command) imports each command's modules inside the command,
for start-up time (see its docstring)."""


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


MODULES = _modules()


def _layer(module: str) -> int:
    parts = module.split(".")
    if len(parts) == 1:  # the package itself
        return 0
    return LAYERS.index(parts[1])


def _resolve(module: str, path: Path, node: ast.ImportFrom | ast.Import) -> list[str]:
    """The cosim modules an import statement names."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name.split(".")[0] == "cosim"]
    if node.level == 0:
        base = node.module or ""
    else:
        package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
        package = package[: len(package) - (node.level - 1)]
        base = ".".join(package + ([node.module] if node.module else []))
    if not base.startswith("cosim"):
        return []
    targets = []
    for alias in node.names:
        sub = f"{base}.{alias.name}"
        targets.append(sub if sub in MODULES else base)
    return targets


def _imports(module: str, typing_too: bool = False) -> list[tuple[str, int, bool]]:
    """(imported cosim module, line, at module level) of ``module``; TYPE_CHECKING blocks left out unless
    ``typing_too``."""
    path = MODULES[module]
    tree = ast.parse(path.read_text())
    out = []

    def visit(node: ast.AST, top: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test) and not typing_too:
                continue
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                out.extend((t, child.lineno, top) for t in _resolve(module, path, child))
            inner = top and not isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            visit(child, inner)

    visit(tree, True)
    return out


def test_the_rooms_exist():
    for room in ("engine", "fmi", "observers", "io", "analysis"):
        assert (PACKAGE / room / "__init__.py").is_file(), room
    assert len(MODULES) > 20


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_point_down(module):
    wrong = [f"{module}:{line} imports {target}" for target, line, _ in _imports(module)
             if target in MODULES and _layer(target) > _layer(module)]
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize("module", sorted(set(MODULES) - LAZY_OK))
def test_our_modules_are_imported_at_module_level(module):
    hidden = [f"{module}:{line} imports {target} inside a function" for target, line, top in _imports(module)
              if not top]
    assert not hidden, "\n".join(hidden)


def test_no_import_cycle():
    """No cycle among our modules' imports, wherever they stand: at module level, inside functions, under
    TYPE_CHECKING, and through a package's ``__init__`` (its re-exports)."""
    graph = {m: {t for t, _, _ in _imports(m, typing_too=True) if t in MODULES and t != m} for m in MODULES}
    found = cycles(graph)
    assert not found, "\n".join(found)


def test_the_cycle_check_can_fail():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == ["a -> b -> c -> a"]


@pytest.mark.parametrize("module", sorted(set(MODULES) - LAZY_OK))
def test_an_import_inside_a_function_says_why(module):
    """Third-party packages some commands never need (fmpy, matplotlib, Dask, mcap, foxglove, an optional pandas)
    may be imported where they are used, so that `python -m cosim --help`, which loads most modules to build its
    parser, starts without them; the line says so (``# lazy: ...`` or ``# optional: ...``)."""
    path = MODULES[module]
    lines = path.read_text().splitlines()
    silent = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for sub in ast.walk(node):
                if isinstance(sub, (ast.Import, ast.ImportFrom)) and not re.search(
                        r"#\s*(lazy|optional)\b", lines[sub.lineno - 1]):
                    silent.append(f"{module}:{sub.lineno}: {lines[sub.lineno - 1].strip()}")
    assert not silent, "\n".join(silent)


GENERIC = ("engine", "fmi", "observers", "io")
"""The rooms of the master for any FMU: they import nothing of the robot's packages, anywhere in a module (at
module level, inside a function, under TYPE_CHECKING, or by name through importlib); the robot plugs in through
cosim.engine.plugins."""
DOMAIN = ("delta", "fmus", "multibody")


def _domain_imports(path: Path) -> list[str]:
    """Every place in ``path`` that imports a robot package, with its line."""
    tree = ast.parse(path.read_text())
    found = []
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            names = [node.module or ""]
        elif isinstance(node, ast.Call) and ast.unparse(node.func).split(".")[-1] in ("import_module", "__import__"):
            names = [a.value for a in node.args[:1] if isinstance(a, ast.Constant) and isinstance(a.value, str)]
        found += [f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path.name}:{node.lineno} imports {n}"
                  for n in names if n.split(".")[0] in DOMAIN]
    return found


@pytest.mark.parametrize("module", sorted(m for m in MODULES if m.split(".")[1:2] and m.split(".")[1] in GENERIC))
def test_the_generic_rooms_import_no_robot(module):
    wrong = _domain_imports(MODULES[module])
    assert not wrong, "\n".join(wrong)


def test_the_robot_check_finds_every_way_of_importing(tmp_path):
    """The check above can fail: each way a module may reach the robot is found."""
    bad = tmp_path / "bad.py"
    bad.write_text("from __future__ import annotations\nimport importlib\nfrom typing import TYPE_CHECKING\n"
                   "import delta.robots as r\nif TYPE_CHECKING:\n    from fmus.registry import FmuEntry\n"
                   "def f():\n    from multibody import plant\n    return importlib.import_module('fmus.registry')\n"
                   "from ..errors import CosimError\n")
    found = _domain_imports(bad)
    assert [line.split(" imports ")[1] for line in found] == ["delta.robots", "fmus.registry", "multibody",
                                                               "fmus.registry"], found


def test_the_robot_plugs_in_through_its_entry_point():
    from importlib.metadata import entry_points

    from cosim.engine import plugins

    (ep,) = [e for e in entry_points(group=plugins.GROUP) if e.name == "delta"]
    assert ep.value == "cosim.robot:plugin", ep
    assert [p.name for p in plugins.installed()] == ["delta"]


FRONT_END = ("cosim.engine.schema", "cosim.engine.scenario", "cosim.engine.overrides")
"""The YAML scenario's modules: its pydantic schema, its reading (file lines, ``parameters:`` files) and ``--set``.
They make a :class:`cosim.engine.structure.SystemStructure`; what runs one never needs them."""


def _reached(graph: dict[str, set[str]], start: str) -> set[str]:
    """Every module ``start`` imports, directly or through others."""
    seen: set[str] = set()
    todo = [start]
    while todo:
        for target in graph.get(todo.pop(), ()):
            if target not in seen:
                seen.add(target)
                todo.append(target)
    return seen


def _front_end_reached(graph: dict[str, set[str]], modules) -> list[str]:
    return [f"{m} reaches {', '.join(sorted(_reached(graph, m) & set(FRONT_END)))}" for m in modules
            if _reached(graph, m) & set(FRONT_END)]


def test_what_runs_a_system_never_reaches_the_yaml_front_end():
    """The engine's modules (but the front end's own), the FMI layer, the observers (the log included) and the run's
    files (output claims, checkpoints) run a system structure, whoever made it (a YAML scenario, an SSP archive,
    code): none imports the scenario's schema, directly or through another module, at module level, inside a
    function or for typing (the domain plugged in reads its sections from the structure, the log records the
    structure's document)."""
    graph = {m: {t for t, _, _ in _imports(m, typing_too=True) if t in MODULES and t != m} for m in MODULES}
    running = [m for m in MODULES if (m.split(".")[1:2] in (["engine"], ["fmi"], ["observers"])
                                      or m in ("cosim.io.checkpoint", "cosim.io.output")) and m not in FRONT_END]
    assert len(running) > 30, running
    wrong = _front_end_reached(graph, running)
    assert not wrong, "\n".join(wrong)


def test_the_front_end_check_can_fail():
    graph = {"cosim.engine.system": {"cosim.engine.names"}, "cosim.engine.names": {"cosim.engine.overrides"},
             "cosim.engine.overrides": {"cosim.engine.schema"}}
    assert _front_end_reached(graph, ["cosim.engine.system"]) == [
        "cosim.engine.system reaches cosim.engine.overrides, cosim.engine.schema"]
