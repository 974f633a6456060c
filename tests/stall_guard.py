"""A pytest plugin of the suite: stop an xdist run that has stalled, naming the last test reported, instead of waiting.

Seen once (2026-11-29, on the 2-core machine): a worker died of a segfault inside an FMU's call (FMPy driving a test
C FMU in the worker), xdist started another, and the session then waited for ever with every worker idle (its
scheduler never handed out the rest of the crashed worker's group). CI would have waited out its 90 minutes. The
controller now notes the time of every test report; when none came for :data:`STALL_S` (``COSIM_TEST_STALL_S``), it
prints what it knows and ends the run with exit status 3. Loaded by tests/conftest.py; only in xdist's controller.
"""

from __future__ import annotations

import os
import sys
import threading
import time

import pytest

STALL_S = float(os.environ.get("COSIM_TEST_STALL_S", "600"))
"""s without any test report after which the run is stopped: several times the longest test under load (about
60 s), the workers' start and collection included."""

_STATE: dict = {"last": None, "nodeid": None, "done": threading.Event()}


def pytest_sessionstart(session):
    config = session.config
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return  # a worker, or no xdist: nothing waits on a scheduler
    _STATE["last"] = time.monotonic()
    threading.Thread(target=_watch, name="suite-stall-guard", daemon=True).start()


def _progress() -> None:
    _STATE["last"] = time.monotonic()


def pytest_runtest_logreport(report):
    _progress()
    _STATE["nodeid"] = report.nodeid


@pytest.hookimpl(optionalhook=True)
def pytest_testnodeready(node):
    _progress()  # a worker up is progress: its start under load is not counted as a stall


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_node_collection_finished(node, ids):
    _progress()  # so is a worker's collection


def pytest_sessionfinish(session):
    _STATE["done"].set()


def _watch() -> None:
    done = _STATE["done"]
    while not done.wait(min(10.0, STALL_S / 4)):
        idle = time.monotonic() - _STATE["last"]
        if idle > STALL_S:
            sys.__stderr__.write(f"\nsuite stalled: no test reported for {idle:.0f} s (at most {STALL_S:g} s; the "
                                 f"last report: {_STATE['nodeid']}, maybe the test that hangs); stopped: a worker "
                                 "that crashed (its 'node down' line above) or a test that hangs\n")
            sys.__stderr__.flush()
            os._exit(3)
