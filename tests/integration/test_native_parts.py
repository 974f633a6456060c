"""Native builds link shared compiled parts (fmus/native/parts.py): an FMU's model is compiled once for both FMI
versions, the FMI glue once for every FMU; a damaged cached part is compiled again; a compiler that writes
something unloadable leaves no part behind. The compiler is a wrapper that logs what it compiles."""

from __future__ import annotations

import os
import shutil
import stat
import zipfile

import pytest
from fmpy import simulate_fmu

from fmus import registry
from fmus.builder import CACHE_ENV
from fmus.native.errors import NativeError

pytestmark = pytest.mark.skipif(shutil.which("cc") is None, reason="needs a C compiler")


def _wrapper(tmp_path, body: str):
    """A compiler script whose calls are logged (one line per call: the C files it was given)."""
    log = tmp_path / "cc.log"
    script = tmp_path / "cc-wrapper"
    script.write_text("#!/bin/sh\n"
                      f'for a in "$@"; do case "$a" in *.c) printf "%s " "${{a##*/}}" >> "{log}";; esac; done\n'
                      f'echo >> "{log}"\n{body}\n')
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    return script, log


def _compiled(log) -> list[str]:
    return sorted(name for line in log.read_text().splitlines() for name in line.split())


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    return tmp_path / "cache"


def test_the_model_compiles_once_for_both_versions_and_the_glue_once_for_every_fmu(tmp_path, cache, monkeypatch):
    script, log = _wrapper(tmp_path, 'exec cc "$@"')
    monkeypatch.setenv("CC", str(script))
    fmus = {}
    for name, fmi in (("helix", 2), ("helix", 3), ("linear_pd", 2), ("linear_pd", 3)):
        fmus[name, fmi] = registry.build(name, None, native=True, fmi=fmi)
    assert _compiled(log) == sorted(["model.c", "model_functions.c"] * 2 + ["runtime.c", "state.c"] * 2
                                    + ["fmi2Functions.c", "fmi3Functions.c"]), log.read_text()
    for (name, fmi), path in fmus.items():  # each FMU still carries every source it is made from, and runs
        with zipfile.ZipFile(path) as zf:
            sources = {n.rsplit("/", 1)[-1] for n in zf.namelist() if n.startswith("sources/")}
        assert {"model.c", "model_functions.c", "model_functions.h", "runtime.c", "state.c",
                f"fmi{fmi}Functions.c"} <= sources, sources
        result = simulate_fmu(str(path), stop_time=0.01, output_interval=0.005)
        assert len(result) == 3
    parts = cache / "native" / "parts"
    assert not list(parts.rglob(".partial-*")), "a part left half made"


def test_a_damaged_cached_part_is_compiled_again(tmp_path, cache, monkeypatch):
    registry.build("helix", None, native=True, fmi=2)
    objects = next((cache / "native" / "parts").glob("*/models/helix/objects"))
    for obj in objects.glob("*.o"):
        obj.write_bytes(b"not an object")
    path = registry.build("helix", None, native=True, fmi=3)
    assert len(simulate_fmu(str(path), stop_time=0.01, output_interval=0.005)) == 3
    assert all(obj.read_bytes()[:4] == b"\x7fELF" for obj in objects.glob("*.o")), "the damaged part was not replaced"


def test_a_compiler_that_writes_no_library_leaves_no_part(tmp_path, cache, monkeypatch):
    script, _ = _wrapper(tmp_path, 'while [ $# -gt 0 ]; do [ "$1" = -o ] && echo junk > "$2"; shift; done; exit 0')
    monkeypatch.setenv("CC", str(script))
    with pytest.raises(NativeError, match=r"native FMU helix: .*cc-wrapper made a library that does not load"):
        registry.build("helix", None, native=True, fmi=2)
    parts = cache / "native" / "parts"
    assert [p for p in parts.rglob("*") if p.is_file()] == [], "an unloadable build left parts in the cache"
    monkeypatch.setenv("CC", "cc")
    path = registry.build("helix", None, native=True, fmi=2)
    assert len(simulate_fmu(str(path), stop_time=0.01, output_interval=0.005)) == 3


def test_a_part_left_by_a_killed_builder_is_swept(tmp_path, cache):
    registry.build("helix", None, native=True, fmi=2)
    home = next((cache / "native" / "parts").iterdir())
    child = os.fork()
    if child == 0:
        os._exit(0)
    os.waitpid(child, 0)  # a pid that is surely gone
    left = home / f".partial-{child}-abc"
    (left / "objects").mkdir(parents=True)
    registry.build("linear_pd", None, native=True, fmi=2)
    assert not left.exists()


def test_force_compiles_every_part_again(tmp_path, cache, monkeypatch):
    script, log = _wrapper(tmp_path, 'exec cc "$@"')
    monkeypatch.setenv("CC", str(script))
    registry.build("helix", None, native=True, fmi=2)
    first = _compiled(log)
    registry.build("helix", None, native=True, fmi=2)  # current: nothing compiled
    assert _compiled(log) == first
    path = registry.build("helix", None, native=True, fmi=2, force=True)
    assert _compiled(log) == sorted(first * 2), log.read_text()
    assert len(simulate_fmu(str(path), stop_time=0.01, output_interval=0.005)) == 3
    assert not list((cache / "native" / "parts").rglob(".partial-*"))


def test_a_cached_part_that_lost_a_file_is_compiled_again(tmp_path, cache):
    """A model part without one of its sources would have linked (its objects are there) and shipped an FMU without
    that source: it is compiled again, and the FMU carries every source."""
    registry.build("helix", None, native=True, fmi=2)
    model = next((cache / "native" / "parts").glob("*/models/helix"))
    (model / "model_functions.c").unlink()
    path = registry.build("helix", None, native=True, fmi=3)
    with zipfile.ZipFile(path) as zf:
        assert "sources/model_functions.c" in zf.namelist(), zf.namelist()
    assert (model / "model_functions.c").is_file()
