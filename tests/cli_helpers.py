"""Helpers for tests that drive ``python -m cosim`` in a subprocess, as a user runs it.

``cosim`` runs a command to completion, ``start_cosim`` starts one to watch or signal. Both run
from the repository root with text-mode pipes and pass extra keyword arguments to
:mod:`subprocess` (``env``, ``preexec_fn``, ...). Arguments may be paths: they are converted with
``str``.
"""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT = 120  # s, a hung command fails instead of hanging CI


def _command(args) -> list[str]:
    return [sys.executable, "-m", "cosim", *map(str, args)]


def cosim(*args, timeout: float = TIMEOUT, cwd: Path = ROOT, **kw) -> subprocess.CompletedProcess:
    """Run ``python -m cosim *args`` to the end; stdout and stderr captured as text."""
    return subprocess.run(_command(args), cwd=cwd, capture_output=True, text=True, timeout=timeout, **kw)


def start_cosim(*args, cwd: Path = ROOT, **kw) -> subprocess.Popen:
    """Start ``python -m cosim *args``; stdout and stderr are text pipes (read them with ``communicate``)."""
    return subprocess.Popen(_command(args), cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            **kw)


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(predicate: Callable[[], object], timeout: float = 30.0, what: str = "") -> None:
    """Poll ``predicate`` until it is true; fail the test after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out after {timeout} s waiting for {what}"
        time.sleep(0.05)
