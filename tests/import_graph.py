"""Import cycles in a graph of modules (module -> the modules it imports), for the layer tests of each package."""

from __future__ import annotations

import ast
from pathlib import Path


def cycles(graph: dict[str, set[str]]) -> list[str]:
    """Every cycle a depth-first walk meets, as ``a -> b -> ... -> a`` (empty: the graph has none)."""
    state: dict[str, int] = {}
    found: list[str] = []

    def walk(m: str, stack: list[str]) -> None:
        state[m] = 1
        for t in sorted(graph.get(m, ())):
            if state.get(t) == 1:
                found.append(" -> ".join(stack[stack.index(t):] + [t]))
            elif t not in state:
                walk(t, stack + [t])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            walk(m, [m])
    return found


def package_modules(root: Path, package: str) -> dict[str, Path]:
    """The modules of ``package`` (a folder under ``root``) by dotted name, a package by its ``__init__``."""
    out = {}
    for path in (root / package).rglob("*.py"):
        parts = path.relative_to(root).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def imports_anywhere(modules: dict[str, Path], module: str) -> set[str]:
    """The modules of ``modules`` that ``module`` imports anywhere in it (functions and TYPE_CHECKING blocks
    included, relative and absolute), with the packages each import runs first (its own packages only where it
    imports a name from them: a re-export)."""
    path = modules[module]
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    named: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            named.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            parts = package[:len(package) - node.level + 1] if node.level else []
            base = ".".join(parts + ([node.module] if node.module else []))
            named.update(f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names)
    # an import also runs the packages above what it names, first, except the importing module's own packages
    # (already running when it runs); a name imported from one of those is an import of it all the same
    own = {".".join(module.split(".")[:i]) for i in range(1, module.count(".") + 1)}
    out = {name for name in named if name in modules}
    for name in named:
        parts = name.split(".")
        out.update(m for m in (".".join(parts[:i]) for i in range(1, len(parts))) if m in modules and m not in own)
    return out - {module}


def package_cycles(root: Path, package: str) -> list[str]:
    """The import cycles among the modules of ``package``, every import counted (see :func:`imports_anywhere`)."""
    modules = package_modules(root, package)
    return cycles({m: imports_anywhere(modules, m) for m in modules})
