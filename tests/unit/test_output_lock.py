"""The lock of an output file names its owner in one JSON line: a command line holding a newline (a file name may)
cannot forge the owner's pid, and any locale writes it."""

from __future__ import annotations

import json
import os
import sys

from cosim.io.output import _describe_owner, claim


def test_a_newline_in_the_command_line_cannot_forge_the_owner(tmp_path, monkeypatch):
    forged = "x\npid=1\nstarted=0\ncommand=forged"
    monkeypatch.setattr(sys, "argv", ["python -m cosim", "run", f"{tmp_path}/{forged}.yaml"])
    target = tmp_path / "out.mcap"
    out = claim(target, ())
    try:
        lock = target.with_name("out.mcap.lock")
        assert len(lock.read_text().splitlines()) == 1, lock.read_text()
        assert json.loads(lock.read_text())["command"][2].endswith(f"{forged}.yaml")
        described = _describe_owner(lock)
        assert f"pid {os.getpid()}," in described and "pid 1," not in described, described
        assert "\n" not in described and "\\n" in described, described  # shown, escaped
    finally:
        out.discard()


def test_an_unreadable_or_foreign_lock_is_another_run(tmp_path):
    lock = tmp_path / "x.lock"
    for text in ("pid=1\nstarted=0\n", "[1]", '{"pid": "1; rm"}', ""):
        lock.write_text(text)
        assert _describe_owner(lock).startswith("another run"), text
    assert _describe_owner(lock) == "another run (pid ?, started ?: ?)"
