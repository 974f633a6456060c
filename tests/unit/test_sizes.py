"""Files of one role and functions that fit on a screen: no package file over 700 lines (Python and the native
FMUs' C), no function over 100 lines, in cosim, delta, fmus and multibody."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("cosim", "delta", "fmus", "multibody")
MAX_FILE_LINES = 700
MAX_FUNCTION_LINES = 100
FILES = sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*")
               if p.suffix in (".py", ".c", ".h") and "__pycache__" not in p.parts)


def long_functions(source: str) -> list[tuple[str, int]]:
    """(name, lines) of every function or method over the limit in ``source``."""
    return [(node.name, node.end_lineno - node.lineno + 1) for node in ast.walk(ast.parse(source))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES]


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_files_and_functions_stay_small(path):
    text = path.read_text(encoding="utf-8")
    lines = len(text.splitlines())
    assert lines <= MAX_FILE_LINES, f"{path.relative_to(ROOT)}: {lines} lines (at most {MAX_FILE_LINES}: split by role)"
    if path.suffix == ".py":
        assert not long_functions(text), f"{path.relative_to(ROOT)}: {long_functions(text)}"


def test_the_size_checks_can_fail():
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    assert long_functions(f"def f():\n{body}\n") == [("f", MAX_FUNCTION_LINES + 1)]
    assert len(FILES) > 100
