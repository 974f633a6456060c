"""The README and docs/ describe the platform as it is, not how it came to be: no issue numbers and no commit
hashes (a figure's provenance is the command that gives it)."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
ISSUE = re.compile(r"\b(issue|issues) #?\d+|(?<![\w/])#\d{1,4}\b", re.I)
HEX = re.compile(r"(?<![\w./-])[0-9a-f]{7,40}(?![\w-])")


def _commits(words: set[str]) -> set[str]:
    """The words that name a commit of this repository (none when git or the history is missing)."""
    if shutil.which("git") is None or not (ROOT / ".git").exists() or not words:
        return set()
    out = subprocess.run(["git", "-C", str(ROOT), "cat-file", "--batch-check"], input="\n".join(
        f"{w}^{{commit}}" for w in sorted(words)) + "\n", capture_output=True, text=True, check=False).stdout
    return {w for w, line in zip(sorted(words), out.splitlines()) if not line.endswith("missing")
            and " commit " in line}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_no_issue_numbers_or_commit_hashes(page):
    text = page.read_text(encoding="utf-8")
    issues = [m.group(0) for m in ISSUE.finditer(text)]
    words = {w for w in HEX.findall(text) if re.search(r"[a-f]", w) and re.search(r"\d", w)}
    commits = _commits(words)
    assert not issues and not commits, f"{page.name}: issue numbers {issues}, commit hashes {sorted(commits)}"


def test_the_history_check_can_fail():
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                          check=False).stdout.strip()
    if not head:
        pytest.skip("no git history here")
    assert _commits({head, "3ec24279217c"}) == {head}
    assert ISSUE.search("fixed in issue 27") and ISSUE.search("see #12") and not ISSUE.search("a/#12/b")
