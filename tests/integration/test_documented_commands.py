"""Every ``python -m cosim`` command of the README and docs/ works as written: each page's shell blocks are run in
order (a page's later commands read what its earlier ones wrote), from a folder holding a copy of the scenarios
and the golden logs, and each must end with exit 0.

A command is left out only when it cannot run unattended, with the reason below: it names a file of the reader's
own (``A.mcap``, ``ANY.fmu``, another tool's ``system.ssp``), or it serves the live view until stopped
(tests/integration/test_live.py runs that).
"""

from __future__ import annotations

import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from cli_helpers import cosim

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
PLACEHOLDERS = ("A.mcap", "B.mcap", "ANY.fmu", "system.ssp")
TIMEOUT_S = 600


def documented(page: Path) -> list[tuple[str, str | None]]:
    """The ``python -m cosim`` commands of ``page``'s shell blocks, in order, continuation lines joined, comments
    dropped, each with the error line the page shows right below it in a console block (``error: ...``: the
    command must end with exit 2 and print that line), or None (it must succeed)."""
    out: list[tuple[str, str | None]] = []
    for block in shell_blocks(page.read_text(encoding="utf-8")):
        lines = re.sub(r"\\\n\s*", " ", block).splitlines()
        for i, line in enumerate(lines):
            command = line.strip().removeprefix("$ ").strip()
            if command.startswith("python -m cosim "):
                shown = lines[i + 1].strip() if i + 1 < len(lines) else ""
                out.append((re.sub(r"\s+#.*$", "", command), shown if shown.startswith("error: ") else None))
    return out


def shell_blocks(text: str) -> list[str]:
    """The bodies of the fenced blocks that are shell (no language, bash, sh, shell, console), fences paired line
    by line: a closing fence is never taken for the opening of the next block."""
    blocks, lang, body = [], "", None
    for line in text.splitlines():
        if line.lstrip().startswith("```"):
            if body is None:
                lang, body = line.lstrip()[3:].strip(), []
            else:
                if lang in ("", "bash", "sh", "shell", "console"):
                    blocks.append("\n".join(body) + "\n")
                body = None
        elif body is not None:
            body.append(line)
    return blocks


def commands(page: Path) -> list[str]:
    return [c for c, _ in documented(page)]


def _why_not(command: str) -> str | None:
    if any(p in command for p in PLACEHOLDERS):
        return "names a file of the reader's own"
    if " --live" in command:
        return "serves the live view until stopped (tests/integration/test_live.py)"
    return None


RUNNABLE = [(page, cmd, error) for page in PAGES for cmd, error in documented(page) if _why_not(cmd) is None]


def test_the_pages_hold_the_commands_this_test_runs():
    """The extraction can fail: the README's main command is found, and every left-out command has its reason."""
    readme = commands(ROOT / "README.md")
    assert "python -m cosim run scenarios/helix_ctc.yaml" in readme, readme
    assert any(e is not None for _, _, e in RUNNABLE), "the pages' documented errors are found (docs/core.md)"
    assert len(RUNNABLE) >= 25, len(RUNNABLE)
    assert commands(ROOT / "docs" / "sweeps.md"), "the sweep page's commands span several lines: joined"
    assert shell_blocks("```text\nA\n```\nprose\n```bash\nB\n```\n") == ["B\n"], "fences paired wrongly"


@pytest.fixture
def workdir(tmp_path_factory) -> Path:
    """A folder of a page's own, as a reader starts one page (the pages run on the suite's workers at once)."""
    d = tmp_path_factory.mktemp("documented")
    shutil.copytree(ROOT / "scenarios", d / "scenarios")
    (d / "tests").mkdir()
    shutil.copytree(ROOT / "tests" / "golden", d / "tests" / "golden")
    return d


@pytest.mark.parametrize("page", [p for p in PAGES if any(q == p for q, _, _ in RUNNABLE)], ids=lambda p: p.name)
def test_every_documented_command_works_as_written(page, workdir):
    """Among the suite's longest (the README's page: 17 commands, each a process of its own, about a minute): nothing
    cheaper proves that a page works as a reader types it; the pages run side by side on the suite's workers."""
    for command, error in ((c, e) for q, c, e in RUNNABLE if q == page):
        args = shlex.split(command)
        args[0] = sys.executable
        target = None
        if ">" in args:  # the shell's redirection of stdout into a file
            at = args.index(">")
            args, target = args[:at], args[at + 1]
        if args[1:3] == ["-m", "cosim"]:  # as tests/cli_helpers.py runs every command (stdin /dev/null)
            r = cosim(*args[3:], cwd=workdir, timeout=TIMEOUT_S)
        else:
            r = subprocess.run(args, cwd=workdir, capture_output=True, text=True, timeout=TIMEOUT_S,
                               stdin=subprocess.DEVNULL)
        if error is not None:  # the page shows the command failing: with that line
            assert r.returncode == 2 and r.stderr.strip() == error, f"{page.name}: `{command}` shows `{error}`, " \
                f"gave exit {r.returncode}: {r.stderr[-500:]}"
            continue
        assert r.returncode == 0, f"{page.name}: `{command}` exited {r.returncode}\n{r.stderr[-2000:]}\n{r.stdout[-1500:]}"
        if target is not None:
            (workdir / target).write_text(r.stdout)
