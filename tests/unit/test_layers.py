"""The master's rooms: imports point one way, with no cycle and no hidden import.

Layers, lowest first: ``errors``, ``cbuild`` (the C helpers' compiler), ``fmi`` (FMU access), ``engine`` (scenario, plan, algorithms, execution),
``observers``, ``io``, ``run`` (a scenario's run, composed), ``analysis``, ``api``, the CLI. A module imports
only from its own layer or below. Inside a layer, module-level imports form no cycle. Our own modules are
imported at module level, except in the CLI (``cosim/cli.py`` imports each command's modules inside the
command, so that ``--help`` starts in a fraction of a second; its docstring says so).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "cosim"
LAYERS = ["errors", "cbuild", "procs", "fmi", "engine", "observers", "io", "run", "analysis", "api", "cli", "__main__"]
LAZY_OK = {"cosim.cli"}  # imports inside functions, for start-up time (see its docstring)


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


def _imports(module: str) -> list[tuple[str, int, bool]]:
    """(imported cosim module, line, at module level) of ``module``, TYPE_CHECKING blocks left out."""
    path = MODULES[module]
    tree = ast.parse(path.read_text())
    out = []

    def visit(node: ast.AST, top: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
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
    graph = {m: {t for t, _, top in _imports(m) if top and t in MODULES and t != m} for m in MODULES}
    # a package's __init__ importing its own modules is how a package offers its names: not a cycle edge back
    state: dict[str, int] = {}
    cycles = []

    def walk(m: str, stack: list[str]) -> None:
        state[m] = 1
        for t in sorted(graph[m]):
            if state.get(t) == 1:
                cycles.append(" -> ".join(stack[stack.index(t):] + [t]))
            elif t not in state:
                walk(t, stack + [t])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            walk(m, [m])
    assert not cycles, "\n".join(cycles)


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
