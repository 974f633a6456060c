"""Shared test configuration: hypothesis profile, markers, the suite's temp folder."""

import os
import shutil
import tempfile

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "default",
    max_examples=200,
    deadline=None,
    suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow],
)
settings.load_profile("default")



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
