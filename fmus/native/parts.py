"""Compiled parts of native FMUs, compiled once and linked into many: what makes a cold build fast.

A native FMU's library is linked from two parts:

* its **model**: the generated ``model_functions.c/.h`` and ``model.c`` and their objects. They are the same for FMI 2
  and FMI 3 (the instantiation token is the FMU's, not the version's), so the second version links the first one's;
* the **glue** of its FMI version: ``runtime.c``, ``state.c`` and ``fmi2Functions.c`` or ``fmi3Functions.c``, the same
  for every FMU, compiled once for all of them.

Compiling the glue was about 0.6 s of every native build's 1-2 s, and the pick_place trajectory's model about 9 s of
each of its two builds. Each part is a folder of the user's cache (``native/parts/<fingerprint>-<compiler>/``, keyed
by the native fingerprint and by the compiler's file and flags), made in a folder of its own and renamed into place
whole, and only after a library linked from it loaded: a reader never sees half a part, concurrent builders each make
their own and the first rename wins, and a compiler that writes something unloadable leaves nothing behind. A library
that does not link or load from cached parts is linked again from parts compiled now, which replace them.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Callable

from ..builder import CACHE_ENV, KEEP, BuildError, cache_folder, user_cache
from .errors import NativeError

__all__ = ["CFLAGS", "link"]

CFLAGS = ("-std=c99", "-O2", "-fPIC", "-Wall", "-Wextra", "-Wno-unused-parameter")
_GLUE = {2: ("runtime.c", "state.c", "fmi2Functions.c"), 3: ("runtime.c", "state.c", "fmi3Functions.c")}
_PARTIAL = ".partial-"


def glue_sources(fmi: int) -> tuple[str, ...]:
    """The C files of the FMI ``fmi`` glue (in ``c/``), as they go into an FMU's ``sources/``."""
    return _GLUE[fmi]


def link(cc: str, digest: str, name: str, fmi: int, src: Path, binary: Path, generate: Callable[[Path], object],
         loads: Callable[[Path], None], *, force: bool = False) -> list[str]:
    """Link FMU ``name``'s library ``binary`` for FMI ``fmi`` from its model part and the glue part, each from the
    cache or compiled now; copy the model's generated sources into ``src`` (which holds the glue's sources and every
    header already) and return the names of its C files. ``generate(folder)`` writes the model's sources into
    ``folder``; ``loads(binary)`` raises :class:`NativeError` unless the library loads. Parts compiled now are cached
    once the library loaded; cached parts that do not link or load are compiled again, once; ``force`` compiles
    them all again (and replaces the cached ones)."""
    home = cache_folder(user_cache() / "native" / "parts" / f"{digest[:16]}-{_compiler_key(cc)}")
    headers = hashlib.sha256(b"".join(p.read_bytes() for p in sorted(src.glob("*.h")) if p.name.startswith("fmi")))
    parts: dict[str, Callable[[Path], object]] = {
        f"models/{name}": generate,
        f"fmi{fmi}-{headers.hexdigest()[:12]}": lambda folder: _copy(src, glue_sources(fmi), folder)}
    for fresh in (True,) if force else (False, True):
        made: dict[str, Path] = {}
        try:
            folders = {}
            for key, write in parts.items():
                if not fresh and _complete(home / key):
                    folders[key] = home / key
                else:
                    made[key] = folders[key] = _make(home, cc, write, src, name)
            objects = sorted(o for f in folders.values() for o in (f / "objects").glob("*.o"))
            try:
                _link(cc, objects, binary, name)
                loads(binary)
            except NativeError:
                if len(made) == len(parts):
                    raise  # everything compiled now: the compiler's or the sources' fault, said as it is
                for key in parts.keys() - made.keys():  # a damaged or foreign cached part: compiled again
                    shutil.rmtree(home / key, ignore_errors=True)
                continue
            model = folders[f"models/{name}"]
            generated = sorted(p.name for p in model.iterdir() if p.is_file())
            for f in generated:
                shutil.copy2(model / f, src / f)
            for key, folder in made.items():
                _publish(folder, home / key, replace=fresh or not _complete(home / key))
            if made:
                _prune(home.parent, home)
            return [f for f in generated if f.endswith(".c")]
        finally:
            for folder in made.values():
                shutil.rmtree(folder, ignore_errors=True)
    raise NativeError(f"native FMU {name}: its library did not link or load from parts compiled now")


def _complete(part: Path) -> bool:
    """Whether the cached ``part`` holds C sources, each with its object: one that lost a file (a source the FMU
    would ship without, an object the link would miss) is compiled again, not used."""
    try:
        sources = {p.stem for p in part.glob("*.c")}
        objects = {p.stem for p in (part / "objects").glob("*.o")}
    except OSError:
        return False
    return bool(sources) and sources == objects


def _copy(src: Path, names: tuple[str, ...], folder: Path) -> list[str]:
    for n in names:
        shutil.copy2(src / n, folder / n)
    return list(names)


def _compiler_key(cc: str) -> str:
    """12 hex digits naming the compiler's file (resolved: ``cc`` is usually a chain of links), its size and time,
    and the flags: parts compiled by another compiler are never linked together."""
    found = shutil.which(cc) or cc
    path = os.path.realpath(found)
    try:
        st = os.stat(path)
        stamp = f"{path}\0{st.st_size}\0{st.st_mtime_ns}"
    except OSError:
        stamp = path
    return hashlib.sha256(f"{stamp}\0{' '.join(CFLAGS)}".encode()).hexdigest()[:12]


def _make(home: Path, cc: str, write: Callable[[Path], object], src: Path, name: str) -> Path:
    """A new part in a folder of this process's own in ``home``: its sources written by ``write``, compiled into
    ``objects/`` (the files at once, each its own compiler process), with the headers of ``src``."""
    _sweep(home)
    try:
        folder = Path(tempfile.mkdtemp(prefix=f"{_PARTIAL}{os.getpid()}-", dir=home))
    except OSError as exc:
        raise BuildError(f"cannot build native FMU {name} in {home}: {exc.strerror or exc} (the cache must be a "
                         f"folder this user can write; name another with {CACHE_ENV}=FOLDER)") from None
    try:
        write(folder)
        sources = sorted(p.name for p in folder.glob("*.c"))
        objects = folder / "objects"
        objects.mkdir()
        procs = [(s, subprocess.Popen([cc, *CFLAGS, "-c", "-I", str(folder), "-I", str(src), str(folder / s),
                                       "-o", str(objects / (s[:-2] + ".o"))],
                                      stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True))
                 for s in sources]
        failed = []
        for s, proc in procs:
            out, _ = proc.communicate()
            if proc.returncode != 0:
                failed.append(f"{s}: " + " | ".join(out.strip().splitlines()[:6]))
        if failed:
            raise NativeError(f"compiling native FMU {name} failed ({cc}): " + "; ".join(failed))
        return folder
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise


def _link(cc: str, objects: list[Path], binary: Path, name: str) -> None:
    binary.parent.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run([cc, "-shared", "-fPIC", *map(str, objects), "-o", str(binary), "-lm"],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        text = (proc.stderr or proc.stdout).strip().splitlines()
        raise NativeError(f"linking native FMU {name} failed ({cc}): " + " | ".join(text[:6]))


def _publish(folder: Path, target: Path, *, replace: bool) -> None:
    """Rename the part ``folder`` to ``target`` whole; another process's part already there stays (the same
    sources by the same compiler) unless ``replace`` (it is moved aside and removed first). A cache that refuses
    it only loses the reuse."""
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        if replace and target.exists():
            old = Path(tempfile.mkdtemp(prefix=f"{_PARTIAL}{os.getpid()}-", dir=target.parent))
            target.rename(old / "old")
            shutil.rmtree(old, ignore_errors=True)
        folder.rename(target)
    except OSError:
        pass


def _sweep(home: Path) -> None:
    """Remove part folders left by builders that ended before they renamed them (killed): their pid is gone."""
    for partial in home.glob(f"{_PARTIAL}*"):
        try:
            pid = int(partial.name[len(_PARTIAL):].split("-", 1)[0])
            os.kill(pid, 0)
        except ProcessLookupError:
            shutil.rmtree(partial, ignore_errors=True)
        except (ValueError, OSError):
            continue


def _prune(parts: Path, current: Path) -> None:
    """Keep the :data:`~fmus.builder.KEEP` newest sets of parts (fingerprints and compilers), the current one always."""
    homes = []
    for home in parts.iterdir():
        try:
            if home != current and home.is_dir():
                homes.append((home.stat().st_mtime, home))
        except OSError:
            continue
    for _, home in sorted(homes, reverse=True)[max(KEEP - 1, 0):]:
        shutil.rmtree(home, ignore_errors=True)
