"""FMU archives on disk: size limits before anything is read, one extraction per file shared by the runs of a
process, removal at the end of each run and of the process (orphans of killed processes swept)."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import threading
import zipfile
from contextvars import ContextVar
from pathlib import Path
from typing import Any, Iterable

from ..errors import ComponentSourceError, Issue, refused_by_system

Key = tuple  # (resolved FMU path, its stamp): one extraction per file as it was read


_EXTRACTED: dict[Key, Path] = {}  # FMU file -> its extraction directory
_USERS: dict[Key, int] = {}  # FMU file -> how many running runs hold its extraction
_LOCK = threading.RLock()  # _EXTRACTED, _USERS and library loading: runs may run in threads of one process


def _fresh_lock() -> None:
    """In a forked child: a new lock. The parent's may have been held by another thread at the
    fork, and that thread does not exist in the child (an offload worker would wait for ever)."""
    global _LOCK
    _LOCK = threading.RLock()


if hasattr(os, "register_at_fork"):  # POSIX
    os.register_at_fork(after_in_child=_fresh_lock)


def file_stamp(st: os.stat_result) -> tuple[int, ...]:
    """What tells one build of a file from the next at the same path: inode, size, mtime and ctime
    (a copy that keeps the mtime still changes the ctime)."""
    return st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns


MAX_FMU_BYTES = 4 * 1024 ** 3
"""What an FMU archive may unpack to, all members together (ours are under 100 kB, the Exudyn plant's a few MB)."""
MAX_DESCRIPTION_BYTES = 64 * 1024 ** 2
"""What its modelDescription.xml may unpack to."""


def check_archive(path: Path) -> None:
    """Refuse an FMU archive whose members unpack past :data:`MAX_FMU_BYTES` (or whose modelDescription.xml
    does past :data:`MAX_DESCRIPTION_BYTES`) before anything is read or extracted: a zip bomb. Python's zip
    reader reads no member past its declared size, so the declared sizes bound what is written."""

    try:
        with zipfile.ZipFile(path) as zf:
            members = zf.infolist()
    except (zipfile.BadZipFile, OSError) as exc:
        # Refused (correctness): not a zip: nothing of the FMU can be read
        raise ComponentSourceError(Issue("", f"{path}: not an FMU (a zip archive): {exc}")) from None
    total = sum(m.file_size for m in members)
    description = sum(m.file_size for m in members if m.filename == "modelDescription.xml")
    if total > MAX_FMU_BYTES or description > MAX_DESCRIPTION_BYTES:
        # Refused (security): a zip bomb: refused before anything is read or extracted
        raise ComponentSourceError(Issue("", f"{path}: unpacks to {total:,} bytes (modelDescription.xml "
                                             f"{description:,}); at most {MAX_FMU_BYTES:,} "
                                             f"({MAX_DESCRIPTION_BYTES:,}) are accepted: refused"))


UNUSED = ("sources/", "documentation/")
"""Members a run never reads (the C sources of a source FMU, its documentation): not extracted. Our native FMUs
carry their sources (13 files of their 14): extracting them tripled the time of every run's extraction."""

_PREFIX = "cosim-fmu-"  # extraction directories: cosim-fmu-<pid>-<FMU stem>-<random>
SSP_PREFIX = "cosim-ssp-"  # unpacked SSP archives (cosim.io.ssp.open_ssp): cosim-ssp-<pid>-<archive stem>-<random>


def sweep_orphans() -> None:
    """Remove extraction directories and unpacked archives left by processes that no longer exist (killed with
    SIGKILL, which no handler can catch). A directory whose process is alive, or not ours to see, stays."""
    for prefix in (_PREFIX, SSP_PREFIX):
        for d in Path(tempfile.gettempdir()).glob(prefix + "*"):
            try:
                pid = int(d.name[len(prefix):].split("-", 1)[0])
                os.kill(pid, 0)
            except ProcessLookupError:
                shutil.rmtree(d, ignore_errors=True)
            except (ValueError, PermissionError, OSError):
                continue


class Extractions:
    """The FMU extractions one run uses, so that runs in threads of one process share them safely.

    ``with Extractions() as held:`` makes ``held`` the current run's (a context variable: each thread
    has its own); every extraction the run asks for is then held until ``held.release()``, which
    removes each one that no other running run holds. Extractions made outside a run stay until
    :func:`cleanup_extracted` (at the latest at interpreter exit).
    """

    def __init__(self) -> None:
        self.keys: set[Key] = set()
        self._token = None

    def __enter__(self) -> "Extractions":
        self._token = _RUN.set(self)
        return self

    def __exit__(self, *exc: Any) -> None:
        _RUN.reset(self._token)

    def hold(self, key: Key) -> None:
        if key not in self.keys:
            self.keys.add(key)
            _USERS[key] = _USERS.get(key, 0) + 1

    def release(self) -> None:
        """Let go of this run's extractions (any thread: the watchdog's shutdown calls it too)."""
        with _LOCK:
            for key in self.keys:
                users = _USERS.pop(key, 1) - 1
                if users > 0:
                    _USERS[key] = users
                elif key in _EXTRACTED:
                    shutil.rmtree(_EXTRACTED.pop(key), ignore_errors=True)
            self.keys.clear()


_RUN: ContextVar[Extractions | None] = ContextVar("cosim_run_extractions", default=None)


def extraction(key: Key) -> Path:
    """The extraction directory of the FMU file ``key`` = (path, stamp), held by the current run."""
    import fmpy  # lazy: --help loads this module without it

    path = key[0]
    with _LOCK:
        held = _RUN.get()
        unzipdir = _EXTRACTED.get(key)
        if unzipdir is None:
            if not _EXTRACTED:
                sweep_orphans()
            try:
                unzipdir = Path(tempfile.mkdtemp(prefix=f"{_PREFIX}{os.getpid()}-{path.stem}-"))
            except OSError as exc:
                # Refused (correctness): without a folder to unpack it into the FMU cannot be loaded
                raise ComponentSourceError(Issue("", f"{path}: cannot make a folder to extract it into in "
                                                     f"{tempfile.gettempdir()}: {exc.strerror or exc} (set TMPDIR "
                                                     "to a writable folder with room)")) from None
            try:
                fmpy.extract(str(path), str(unzipdir), include=_used)
            except OSError as exc:
                shutil.rmtree(unzipdir, ignore_errors=True)
                if not refused_by_system(exc, unzipdir):
                    # Refused (correctness): its files cannot be read out of the archive: it cannot run
                    raise ComponentSourceError(Issue("", f"{path}: cannot extract: {exc}")) from None
                # Refused (correctness): the system refuses the temporary folder (full, read-only), not the archive
                raise ComponentSourceError(Issue("", f"{path}: cannot extract it into {unzipdir}: "
                                                     f"{exc.strerror or exc} (set TMPDIR to a writable folder with "
                                                     "room)")) from None
            except Exception as exc:  # a corrupt archive  # noqa: BLE001
                shutil.rmtree(unzipdir, ignore_errors=True)
                # Refused (correctness): a corrupt archive: its files cannot be unpacked, it cannot run
                raise ComponentSourceError(Issue("", f"{path}: cannot extract: {exc}")) from None
            _EXTRACTED[key] = unzipdir
        if held is not None:
            held.hold(key)
        return unzipdir


def _used(member: str) -> bool:
    return not member.startswith(UNUSED)


def forget_extractions(path: Path) -> None:
    """Remove the extractions of earlier builds of ``path`` that no running run holds (a run that
    holds one removes it at its end)."""
    with _LOCK:
        for key in [k for k in _EXTRACTED if k[0] == path and not _USERS.get(k)]:
            shutil.rmtree(_EXTRACTED.pop(key), ignore_errors=True)


def cleanup_extracted(keep: Iterable[Key] = ()) -> None:
    """Remove every extracted FMU directory of the process but those of the FMU files in ``keep``
    (keys of ``_EXTRACTED``).

    Called at interpreter exit, when a worker process ends and when the watchdog leaves the process
    (a run releases its own through :class:`Extractions`). A forked worker process keeps its parent's
    extractions (``keep``): they are still in use. Libraries already loaded stay loaded (Linux keeps
    a removed file's mapping).
    """
    keep = set(keep)
    with _LOCK:
        for key in [k for k in _EXTRACTED if k not in keep]:
            _USERS.pop(key, None)
            shutil.rmtree(_EXTRACTED.pop(key), ignore_errors=True)


atexit.register(cleanup_extracted)
