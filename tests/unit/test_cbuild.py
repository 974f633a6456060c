"""The master's C helpers' cache (cosim.cbuild): an entry that is damaged, or another library in its place, is
compiled again rather than loaded (a damaged one used to fall back to the slow path without a word, a foreign one
ended in an internal error: "undefined symbol: cosim_turn")."""

from __future__ import annotations

import shutil

import pytest

from cosim import cbuild

pytestmark = pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler (cc)")

SOURCE = "int cosim_probe(void) { return 7; }\nstatic int helper(void) { return 1; }\n"
OTHER = "int cosim_other(void) { return 5; }\n"


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    return tmp_path / "xdg" / "cosim"


def _library(tmp_path, name: str, text: str) -> cbuild.Library:
    source = tmp_path / f"{name}.c"
    source.write_text(text)
    return cbuild.Library(source)


def test_the_exported_functions_are_read_from_the_source():
    assert cbuild._EXPORTED.findall(SOURCE.encode()) == [b"cosim_probe"]


def test_a_built_entry_is_loaded_from_the_cache(tmp_path, cache):
    lib = _library(tmp_path, "probe", SOURCE).build()
    assert lib.cosim_probe() == 7
    entries = sorted(p.name for p in cache.iterdir())
    assert len(entries) == 1 and entries[0].startswith("probe-") and entries[0].endswith(".so"), entries


@pytest.mark.parametrize("damage", ["garbage", "foreign library"])
def test_a_damaged_or_foreign_entry_is_compiled_again(tmp_path, cache, damage):
    _library(tmp_path, "probe", SOURCE).build()
    (entry,) = cache.glob("probe-*.so")
    good = entry.read_bytes()
    if damage == "garbage":
        entry.write_bytes(b"not a shared library\n")
    else:  # another of our libraries, loadable but without cosim_probe
        _library(tmp_path, "other", OTHER).build()
        shutil.copyfile(next(cache.glob("other-*.so")), entry)
    bad = entry.read_bytes()
    lib = _library(tmp_path, "probe", SOURCE).build()
    assert lib.cosim_probe() == 7
    # the entry is a build again (a process loading it by its name from now on gets cosim_probe; this one keeps
    # the foreign library it loaded under that name, so the bytes tell)
    now = entry.read_bytes()
    assert now != bad and now[:4] == b"\x7fELF" and len(now) == len(good), "the entry was not replaced by a build"
    assert not list(cache.glob(".probe-*")), "a temporary file was left in the cache"
