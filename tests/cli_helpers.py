"""Helpers for tests that drive ``python -m cosim`` in a subprocess, as a user runs it.

``cosim`` runs a command to completion, ``start_cosim`` starts one to watch or signal. Both run
from the repository root with text-mode pipes and pass extra keyword arguments to
:mod:`subprocess` (``env``, ``preexec_fn``, ...). Arguments may be paths: they are converted with
``str``. ``cosim`` runs its command in a process forked by the worker's fork server (:mod:`forkserver`) when
nothing it is given is read by an interpreter at start-up; ``COSIM_TEST_FORKSERVER=0`` starts a new interpreter
for every command, as the suite did before.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT = 120  # s, a hung command fails instead of hanging CI


def _command(args) -> list[str]:
    return [sys.executable, "-m", "cosim", *map(str, args)]


def cosim(*args, timeout: float = TIMEOUT, cwd: Path = ROOT, env: dict[str, str] | None = None,
          **kw) -> subprocess.CompletedProcess:
    """Run ``python -m cosim *args`` to the end; stdout and stderr captured as text. The command runs in a process
    of its own forked by the worker's fork server (:mod:`forkserver`: the imports every command makes are made once)
    when nothing it is given is read by an interpreter at start-up; otherwise, and with any other :mod:`subprocess`
    option (``preexec_fn``, ``input``, ...), in a new interpreter."""
    command = [str(a) for a in args]
    kw = {k: v for k, v in kw.items() if v is not None}
    if not kw and _forkable(env) and _SERVER_LOCK.acquire(blocking=False):
        try:
            return _server().run(command, str(cwd), dict(os.environ if env is None else env), timeout)
        finally:
            _SERVER_LOCK.release()
    return subprocess.run(_command(args), cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env, **kw)


_SERVER: list = []
_SERVER_LOCK = threading.Lock()  # one command at a time through the server: a second thread's starts an interpreter


def _forkable(env: dict[str, str] | None) -> bool:
    """Whether ``env`` leaves every variable an interpreter reads at start-up as the fork server's."""
    if os.environ.get("COSIM_TEST_FORKSERVER", "1") == "0":  # the whole suite on new interpreters, as before
        return False
    if env is None:
        return True
    from forkserver import STARTUP_VARIABLES

    names = {n for n in (*env, *os.environ) if n.startswith(STARTUP_VARIABLES)}
    return all(env.get(n) == os.environ.get(n) for n in names)


def _server():
    if not _SERVER:
        import atexit

        from forkserver import Client

        client = Client(str(ROOT))
        atexit.register(client.close)
        _SERVER.append(client)
    return _SERVER[0]


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
