"""The FMU cache against concurrent builds and failed ones: each build writes a partial file of its own, an entry
is current only when its stamp is a JSON object with the fingerprint and its FMU is an archive, and a native
library that does not load is never cached."""

from __future__ import annotations

import json
import os
import zipfile

import pytest

from fmus.builder import install, is_current


def _zip(path) -> None:
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("modelDescription.xml", "<fmiModelDescription/>")


def test_install_leaves_a_current_entry_and_nothing_else(tmp_path):
    seen = []

    def write(partial):
        seen.append(partial.name)
        _zip(partial)

    target = install(tmp_path, "helix", write, {"fingerprint": "abc"})
    assert seen == [f".helix.{os.getpid()}.partial.fmu"], seen  # this process's own partial file
    assert is_current(target, tmp_path / "helix.json", "abc")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["helix.fmu", "helix.json"]


def test_a_failed_write_leaves_the_cache_as_it_was(tmp_path):
    install(tmp_path, "helix", _zip, {"fingerprint": "old"})

    def broken(partial):
        partial.write_bytes(b"half")
        raise RuntimeError("the exporter failed")

    with pytest.raises(RuntimeError):
        install(tmp_path, "helix", broken, {"fingerprint": "new"})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["helix.fmu", "helix.json"]
    assert is_current(tmp_path / "helix.fmu", tmp_path / "helix.json", "old")


@pytest.mark.parametrize("damage", ["list", "folder", "not json", "truncated fmu", "no fmu", "other fingerprint"])
def test_a_damaged_or_foreign_entry_is_not_current(tmp_path, damage):
    target, stamp = tmp_path / "x.fmu", tmp_path / "x.json"
    _zip(target)
    stamp.write_text(json.dumps({"fingerprint": "abc"}))
    if damage == "list":
        stamp.write_text("[]")
    elif damage == "folder":
        stamp.unlink()
        stamp.mkdir()
    elif damage == "not json":
        stamp.write_text("{")
    elif damage == "truncated fmu":
        target.write_bytes(target.read_bytes()[:10])
    elif damage == "no fmu":
        target.unlink()
    else:
        stamp.write_text(json.dumps({"fingerprint": "zzz"}))
    assert not is_current(target, stamp, "abc")


def test_a_native_library_that_does_not_load_is_refused(tmp_path):
    from fmus.native.build import _loads
    from fmus.native.errors import NativeError

    lib = tmp_path / "x.so"
    lib.write_bytes(b"\x7fELF not really a library")
    with pytest.raises(NativeError, match=r"native FMU x: cc made a library that does not load .*nothing was cached"):
        _loads(lib, "x", "cc")


def test_a_cache_folder_that_cannot_be_made_is_one_error_naming_it(tmp_path):
    from fmus.builder import BuildError, cache_folder

    blocker = tmp_path / ".fmu_cache"
    blocker.write_text("a file where the cache folder goes")
    with pytest.raises(BuildError, match=r"cannot use .*\.fmu_cache/native/fmi2 for built FMUs: Not a directory"):
        cache_folder(blocker / "native" / "fmi2")


def test_a_write_the_system_refuses_is_one_error_naming_the_folder(tmp_path):
    from fmus.builder import BuildError

    def write(partial):
        raise PermissionError(13, "Permission denied")

    with pytest.raises(BuildError, match=f"cannot write FMU helix into {tmp_path}: Permission denied"):
        install(tmp_path, "helix", write, {"fingerprint": "abc"})
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- one cache per user, keyed by content


def test_the_cache_is_the_users_wherever_a_command_runs(tmp_path, monkeypatch):
    from fmus.builder import CACHE_ENV, user_cache

    monkeypatch.delenv(CACHE_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert user_cache() == tmp_path / "xdg" / "delta-cosim" / "fmus"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/ignored")  # the XDG spec: a relative path is invalid
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert user_cache() == tmp_path / "home" / ".cache" / "delta-cosim" / "fmus"
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "mine"))
    assert user_cache() == tmp_path / "mine"


def test_entries_are_keyed_by_content_and_only_the_newest_builds_are_kept(tmp_path):
    from fmus.builder import KEEP, cached, prune

    digests = [f"{i:x}" * 64 for i in range(KEEP + 2)]
    for age, digest in enumerate(digests):
        target, stamp = cached(tmp_path, "helix", digest)
        target.parent.mkdir(exist_ok=True)
        assert target.name == "helix.fmu" and target.parent.name == digest[:16]
        _zip(target)
        stamp.write_text(json.dumps({"fingerprint": digest}))
        os.utime(target, (1000 + age, 1000 + age))
    other, _ = cached(tmp_path, "helix_me", digests[0])  # another FMU's build in an old hash's folder
    _zip(other)
    prune(tmp_path, "helix")
    kept = sorted(str(p) for p in tmp_path.glob("*/helix.fmu"))
    assert kept == sorted(str(cached(tmp_path, "helix", d)[0]) for d in digests[-KEEP:])
    assert not cached(tmp_path, "helix", digests[0])[1].exists()  # its stamp went with it
    assert other.exists() and not cached(tmp_path, "helix", digests[1])[0].parent.exists()  # an emptied folder goes


def test_a_delivery_leaves_only_the_fmu_and_replaces_a_different_one(tmp_path):
    from fmus.builder import deliver

    entry = tmp_path / "cache" / "helix-0123456789abcdef.fmu"
    entry.parent.mkdir()
    _zip(entry)
    out = tmp_path / "out"
    assert deliver(entry, None, "helix") == entry
    first = deliver(entry, out, "helix")
    assert first == out / "helix.fmu" and first.read_bytes() == entry.read_bytes()
    assert [p.name for p in out.iterdir()] == ["helix.fmu"]  # no stamp, no partial file
    entry.write_bytes(entry.read_bytes() + b"\0")  # a newer build
    assert deliver(entry, out, "helix").read_bytes() == entry.read_bytes()
    assert [p.name for p in out.iterdir()] == ["helix.fmu"]


def test_a_cache_folder_that_is_a_file_names_the_variable_to_choose_another(tmp_path, monkeypatch):
    from fmus import registry
    from fmus.builder import CACHE_ENV, BuildError

    blocker = tmp_path / "cache"
    blocker.write_text("a file")
    monkeypatch.setenv(CACHE_ENV, str(blocker))
    with pytest.raises(BuildError, match=rf"cannot use {blocker} for built FMUs: .*{CACHE_ENV}=FOLDER"):
        registry.build("helix")


def test_a_build_waits_for_the_one_under_way_and_says_so(tmp_path):
    """Two builders of one FMU into one cache (the suite's workers, runs started together on an empty cache): the
    second waits for the first's lock, saying so, and gets it only once the first is done; no lock file is
    needed afterwards for the entry to be current."""
    import threading

    from fmus.builder import build_lock, on_build

    told: list[str] = []
    on_build(told.append)
    first_in, first_out, second_in = threading.Event(), threading.Event(), threading.Event()

    def first():
        with build_lock(tmp_path, "linear_ik"):
            first_in.set()
            assert first_out.wait(10)

    def second():
        with build_lock(tmp_path, "linear_ik"):
            second_in.set()

    try:
        a = threading.Thread(target=first)
        a.start()
        assert first_in.wait(10)
        b = threading.Thread(target=second)
        b.start()
        assert not second_in.wait(0.3), "the second builder went in while the first held the lock"
        assert told == [f"waiting for another process building FMU linear_ik into {tmp_path}"], told
        first_out.set()
        a.join(10)
        assert second_in.wait(10), "the second builder never got the lock once the first was done"
        b.join(10)
    finally:
        on_build(None)
        first_out.set()
