"""Python shown in the docs with what it prints: each ```python block of README.md and docs/*.md that a "prints"
paragraph and a plain block follow is run from the repository root, and must print that block line for line, so its
figures cannot go stale."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
SHOWN = re.compile(r"```python\n(?P<code>.*?)```\s*\nprints[^\n]*\n\s*```\n(?P<out>.*?)```", re.S)


def _examples() -> list[tuple[str, str, str]]:
    found = []
    for page in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        text = page.read_text(encoding="utf-8")
        for m in SHOWN.finditer(text):
            found.append((f"{page.relative_to(ROOT)}:{text[:m.start()].count(chr(10)) + 1}", m["code"], m["out"]))
    return found


EXAMPLES = _examples()


def test_the_docs_show_python_with_its_output():
    assert any(where.startswith("docs/api.md") for where, _, _ in EXAMPLES), [w for w, _, _ in EXAMPLES]


@pytest.mark.parametrize("where, code, shown", EXAMPLES, ids=[w for w, _, _ in EXAMPLES])
def test_a_documented_python_example_prints_what_the_page_shows(where, code, shown):
    got = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert got.returncode == 0, f"{where}: exit {got.returncode}: {got.stderr[-2000:]}"
    assert got.stdout.splitlines() == shown.splitlines(), f"{where}: printed\n{got.stdout}\nthe page shows\n{shown}"
