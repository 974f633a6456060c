"""Shared test configuration: hypothesis profile, markers, the suite's temp folder, how xdist shares out the tests.

pyproject.toml runs the suite on pytest-xdist (``-n auto --dist loadgroup``, one worker more than the CPUs:
:func:`pytest_xdist_auto_num_workers`): each worker is a process with its
own session, so its own temp folder (:func:`_suite_temp_folder`), its own session fixtures and its own module
fixtures. The tests of a module that share a module-scoped fixture (a built FMU set, a long reference run) are put
in one group, which one worker runs; every other test goes to whichever worker is free."""

import compileall
import os
import shutil
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "default",
    max_examples=200,
    deadline=None,
    suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow],
)
settings.load_profile("default")


ROOT = Path(__file__).resolve().parents[1]

pytest_plugins = ["stall_guard"]  # a stalled xdist run stops, naming its last test (tests/stall_guard.py)


def pytest_configure(config):
    """The project's modules compiled to bytecode once, by the controller, before any worker or test starts.

    The suite's ``python -m cosim`` commands (642 in one run on 2026-11-29) start from interpreters: each worker's
    fork server (tests/forkserver.py) and the commands that need a new one. Where Python writes no bytecode of its
    own (``PYTHONDONTWRITEBYTECODE``, set on the CI machine) and the checkout is fresh, each of those compiled the
    ~200 modules it imports again from source: 0.15-0.3 s of a core per process (``import cosim.run`` 0.66-0.93 s
    against 0.51-0.58 s compiled, on this 2-core machine). ``compileall`` writes the bytecode whatever that
    setting; a checkout it cannot write to is left as it is (the processes then compile, as before)."""
    if hasattr(config, "workerinput"):  # an xdist worker: the controller did it
        return
    for package in ("cosim", "delta", "fmus", "multibody"):
        compileall.compile_dir(ROOT / package, quiet=2)


def pytest_xdist_auto_num_workers(config):
    """``-n auto``: one worker more than the CPUs this process may use, but none when every argument names single
    tests (``pytest tests/x.py::test_y``): starting workers would cost more than the test.

    The one more: a worker per CPU left the CPUs idle for a sixth of the suite (2026-11-29, 2 CPUs: 880 s of CPU in
    521 s), the time its tests spend waiting on purpose (a stop signal's grace, a watchdog's budget, a sweep
    scheduler's timeout, a run at wall-clock pace); a third worker runs other tests meanwhile: 466 s, with every test
    passing, measured the same hour on the same machine."""
    args = config.invocation_params.args
    named = [a for a in args if not str(a).startswith("-")]
    if named and all("::" in str(a) for a in named):
        return 0
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    return cpus + 1


def pytest_itemcollected(item):
    """Under ``--dist loadgroup``, the tests of a module that use a module- or class-scoped fixture form one
    group (xdist_group named by the module), so that fixture is made once, in one worker, as in a serial run.
    Marked as each test is collected: xdist names the groups in its own collection hook, which must see them."""
    option = item.config.option
    if getattr(option, "dist", "no") != "loadgroup" and not getattr(option, "loadgroup", False):
        return
    info = getattr(item, "_fixtureinfo", None)
    if info is None or any(True for _ in item.iter_markers("xdist_group")):
        return
    if any(defs and defs[-1].scope in ("module", "class", "package")
           for defs in (info.name2fixturedefs.get(name) for name in info.names_closure)):
        item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::")[0]))


ID_LIMIT = 4096
"""Characters of a test's id at most: pytest puts it in ``PYTEST_CURRENT_TEST``, which every process a test starts
inherits, and the system refuses one variable over 128 kB (every child then fails, "Argument list too long")."""


def pytest_collection_modifyitems(config, items):
    """Refuse, naming it, a test whose id is over :data:`ID_LIMIT` (a parametrized value written into it: give the
    case an ``id``)."""
    long = next((item.nodeid for item in items if len(item.nodeid) > ID_LIMIT), None)
    if long is not None:
        raise pytest.UsageError(f"a test id of {len(long)} characters (at most {ID_LIMIT}: it reaches every child's "
                                f"environment): {long[:200]}...; give its parametrized cases ids")


def pytest_collection_finish(session):
    """In a worker, the groups must reach xdist's scheduler: it reads a test's group from the ``@group`` its id
    ends with, which xdist 3.8 appends by assigning the item's ``_nodeid``. pytest 9 builds ids another way and
    ignores that: every group silently came apart (module fixtures made again in both workers, several times
    each as the tests of a module interleaved with others). Stop the suite instead of running it so."""
    if not getattr(session.config.option, "loadgroup", False):
        return
    for item in session.items:
        if next(item.iter_markers("xdist_group"), None) and "@" not in item.nodeid.rpartition("]")[2]:
            raise pytest.UsageError(f"pytest-xdist's --dist loadgroup does not group tests under pytest "
                                    f"{pytest.__version__} ({item.nodeid} has no @group): install pytest<9")


@pytest.fixture(scope="session", autouse=True)
def _suite_temp_folder():
    """Every temporary file of the suite in one folder, removed at its end: fmpy's extractions in tests that drive
    FMUs directly, the processes the tests start (they inherit TMPDIR), and ours. The suite leaves nothing in the
    machine's temp folder (pytest's own tmp_path folders follow pytest's retention)."""
    folder = tempfile.mkdtemp(prefix="cosim-tests-")
    saved_env, saved = os.environ.get("TMPDIR"), tempfile.tempdir
    os.environ["TMPDIR"] = folder
    tempfile.tempdir = folder
    try:
        yield folder
    finally:
        tempfile.tempdir = saved
        if saved_env is None:
            os.environ.pop("TMPDIR", None)
        else:
            os.environ["TMPDIR"] = saved_env
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(autouse=True)
def _fmpy_logger_proxy():
    """After each test, fmpy's C logging proxy points at a logger that is alive (:func:`fmu_helpers.repoint_fmpy_logger`:
    ``fmpy.simulate_fmu(..., logger=f)`` leaves it pointing at a freed thunk, and a later FMU's log call in the same
    worker then runs freed memory; once a CI worker segfaulted so)."""
    yield
    import sys

    if "fmpy.logging" in sys.modules:  # nothing to do where no test loaded the proxy
        from fmu_helpers import repoint_fmpy_logger

        repoint_fmpy_logger()
