"""Small C helpers of the master compiled once and loaded with ctypes: :func:`load` compiles a C source
beside its module with the system C compiler (``$CC``, else ``cc``) into the user's cache
(``$XDG_CACHE_HOME/cosim``, default ``~/.cache/cosim``), once per version of the source, flags and machine;
processes building it at the same time each rename a complete file into place.

Two libraries use it: the master's FMI turn (``cosim/fmi/turn.c``, :mod:`cosim.fmi.turn`) and the log
writer's sample join (``cosim/observers/samples.c``, :mod:`cosim.observers.log_writer`). This module imports
the standard library only: the log's writer process loads its helper without numpy or fmpy (it starts in
about 0.05 s).
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import re
import shutil
import subprocess
import tempfile
import threading
from pathlib import Path
from typing import Any

__all__ = ["CFLAGS", "Library", "cache_dir"]

CFLAGS = ("-std=c99", "-O2", "-fPIC", "-shared")


_EXPORTED = re.compile(rb"^[A-Za-z_][\w \t*]*?\b(cosim_\w+)\s*\(", re.M)
"""A function the C source exports: its definitions start a line (``int cosim_turn(Turn *u)``); static ones are
not ``cosim_``-named."""


def _load(path: Path, exported: list[str]) -> Any:
    """The library at ``path`` loaded, or None when it does not load or lacks one of the ``exported`` functions."""
    try:
        lib = ctypes.CDLL(str(path))
    except OSError:
        return None
    return lib if all(hasattr(lib, name) for name in exported) else None


def cache_dir() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "cosim"


class Library:
    """One C source's library, looked for once per process: :meth:`get` is the loaded ``ctypes.CDLL``, or
    None when it cannot be built here (no compiler, a failed build), and :attr:`reason` then says why."""

    def __init__(self, source: Path) -> None:
        self.source = source
        self.reason: str | None = None
        self._lock = threading.Lock()
        self._found: list[Any] = []
        if hasattr(os, "register_at_fork"):  # POSIX: another thread of the parent may hold the lock at a fork
            os.register_at_fork(after_in_child=self._fresh_lock)

    def _fresh_lock(self) -> None:
        self._lock = threading.Lock()

    def build(self) -> Any:
        """The library: from the cache, else compiled into it. An entry that does not load or lacks a function the
        source exports (damaged, or another library in its place) is compiled again. Raises OSError or
        RuntimeError."""
        source = self.source.read_bytes()
        key = hashlib.sha256(source + "\0".join((*CFLAGS, platform.machine())).encode()).hexdigest()[:16]
        cache = cache_dir()
        stem = self.source.stem
        path = cache / f"{stem}-{key}.so"
        exported = sorted({m.decode() for m in _EXPORTED.findall(source)})
        if path.exists():
            found = _load(path, exported)
            if found is not None:
                return found
        cc = os.environ.get("CC", "cc")
        if shutil.which(cc) is None:
            raise RuntimeError(f"no C compiler ({cc!r} is not on PATH; set CC or install gcc)")
        cache.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{stem}-", suffix=".so", dir=cache)
        os.close(fd)
        try:
            out = subprocess.run([cc, *CFLAGS, "-o", tmp, str(self.source), "-lm"], capture_output=True, text=True)
            if out.returncode != 0:
                raise RuntimeError(f"{cc} failed on {self.source}: {out.stderr.strip()[-2000:]}")
            # loaded under its own new name: a damaged or foreign entry this process loaded keeps the cache's name
            built = _load(Path(tmp), exported)
            if built is None:
                raise RuntimeError(f"{cc} built {tmp} from {self.source}, but it does not load or lacks "
                                   f"{', '.join(exported)}")
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
        return built

    def get(self) -> Any:
        """The loaded library, or None when it cannot be built here (:attr:`reason` says why)."""
        with self._lock:
            if not self._found:
                try:
                    self._found.append(self.build())
                except (OSError, RuntimeError) as exc:
                    self._found.append(None)
                    self.reason = str(exc)
            return self._found[0]
