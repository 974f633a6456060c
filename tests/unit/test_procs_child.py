"""cosim.procs.Child, for a fork: its exit code and its raw wait status once reaped, whether by poll or by wait (the
supervisor reads the status to tell a crash from an exit: it no longer calls waitpid itself)."""

from __future__ import annotations

import os
import signal
import time

import pytest

from cosim import procs

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="POSIX only")


def _crash() -> None:
    signal.signal(signal.SIGSEGV, signal.SIG_DFL)
    os.kill(os.getpid(), signal.SIGSEGV)


def test_an_exit_is_reaped_with_its_code_and_status():
    child = procs.start(lambda: 3, name="exits")
    assert child.wait() == 3
    assert os.WIFEXITED(child.status) and os.WEXITSTATUS(child.status) == 3, child.status


def test_a_crash_seen_by_poll_keeps_its_signal():
    child = procs.start(_crash, name="crashes")
    deadline = time.monotonic() + 30
    while child.poll() is None:
        assert time.monotonic() < deadline, "the child never ended"
        time.sleep(0.01)
    assert child.returncode == -signal.SIGSEGV, child.returncode
    assert os.WIFSIGNALED(child.status) and os.WTERMSIG(child.status) == signal.SIGSEGV, child.status
