"""Build FMUs into a cache directory, keyed by a hash of everything they bundle.

Shadowing: pythonfmu's binary appends the FMU's ``resources/`` to ``sys.path`` and
imports the slave module by name, so every FMU loaded into one interpreter shares
``sys.modules``. Each FMU therefore bundles its project code under a name that is
unique to its sources: the packages it needs (``delta``, ``multibody``, and of ``fmus``
the adapter's module with every module of ``fmus`` it imports, directly or not) are copied into
``resources/_dcosim_<hash>/`` with their absolute imports rewritten to that name, and the slave
module is ``<fmu name>_<hash>``. Two FMUs (or two versions of one FMU) never import each
other's code, and neither imports nor replaces the installed ``delta`` package.

Host requirements: ``resources/requirements.json`` records the Python version and the
third-party packages the bundled code imports (with the project's version specifiers); the
generated module checks them before anything else is imported (:mod:`fmus.requirements`).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import sys
import tempfile
import zipfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator

from cosim.errors import refused_by_system
from delta.errors import DeltaError

from . import requirements
from .definition import FmuDefinition

__all__ = ["CACHE_ENV", "user_cache", "source_files", "fingerprint", "bundle_name", "is_current", "install",
           "cache_folder", "cached", "deliver", "prune", "on_build", "build_python", "scratch", "build_lock",
           "built", "BuildError"]

CACHE_ENV = "DELTA_COSIM_CACHE"
"""Environment variable naming the FMU cache folder (default: :func:`user_cache`)."""
KEEP = 4
"""Builds of one FMU kept in the cache (the newest): checkouts at different commits share it without rebuilding."""
_ROOT = Path(__file__).resolve().parent.parent
_PROJECT_PACKAGES = ("delta", "multibody", "fmus")
_FROM = re.compile(r"^(\s*)from\s+(delta|multibody|fmus)(\.|\s)", re.M)
_IMPORT = re.compile(r"^(\s*)import\s+(delta|multibody|fmus)((?:\.\w+)*)(\s+as\s+\w+)?\s*$", re.M)
_LEFT = re.compile(r"^\s*(from|import)\s+(delta|multibody|fmus)\b", re.M)
_IMPORTS = re.compile(r"^[ \t]*(?:import[ \t]+([\w., \t]+)"
                      r"|from[ \t]+(\.*)([\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n;]*))", re.M)
"""An import statement at any indentation (functions included): ``import a.b, c as d`` (group 1) or ``from ..a
import (b, c)`` (its dots, module and names: groups 2 to 4)."""


class BuildError(DeltaError, RuntimeError):
    """An FMU could not be built; the message names the FMU and the cause."""


def _package_files(package: str) -> list[Path]:
    return sorted(p for p in (_ROOT / package).rglob("*.py") if "__pycache__" not in p.parts)


def source_files(fmu: FmuDefinition) -> dict[str, Path]:
    """Files bundled with the FMU, by their path inside the bundle package: its ``packages`` whole, and of
    ``fmus`` the adapter's module, :mod:`fmus.requirements` (the generated module's host check) and every module
    of ``fmus`` they import (at module level or in a function), with their packages' ``__init__.py``."""
    files: dict[str, Path] = {}
    for package in fmu.packages:
        for path in _package_files(package):
            files[path.relative_to(_ROOT).as_posix()] = path
    for path in _imported_closure(["fmus.requirements", fmu.adapter.__module__]):
        files[path.relative_to(_ROOT).as_posix()] = path
    return files


def _module_file(module: str) -> Path | None:
    """The file of project module ``module`` (a package: its ``__init__.py``), or None."""
    base = _ROOT.joinpath(*module.split("."))
    return next((p for p in (base.with_suffix(".py"), base / "__init__.py") if p.is_file()), None)


def _fmus_imports(module: str, path: Path) -> set[str]:
    """The modules of ``fmus`` that ``module`` (its file ``path``) imports, anywhere in it: its import statements
    read with :data:`_IMPORTS` (a few ms per FMU, where parsing the modules took 80 ms; a line of a docstring that
    reads as an import can only add a file)."""
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    named: set[str] = set()
    for m in _IMPORTS.finditer(path.read_text()):
        if m[1] is not None:
            named.update(part.split()[0] for part in m[1].split(",") if part.strip())
            continue
        parts = package[:len(package) - len(m[2]) + 1] if m[2] else []
        base = ".".join(parts + ([m[3]] if m[3] else []))
        names = re.sub(r"#[^\n]*", "", m[4]).strip("() \t\n")
        named.update([base, *(f"{base}.{n.split()[0]}" for n in names.split(",") if n.strip())])
    return {m for m in named if m.split(".")[0] == "fmus" and _module_file(m) is not None}


def _imported_closure(modules: list[str]) -> list[Path]:
    """The files of ``modules``, of every module of ``fmus`` they import, directly or not, and of their packages."""
    seen: set[str] = set()
    todo = list(modules)
    while todo:
        module = todo.pop()
        if module in seen:
            continue
        seen.add(module)
        parts = module.split(".")
        todo += [".".join(parts[:i]) for i in range(1, len(parts))]  # its packages' __init__.py run first
        todo += sorted(_fmus_imports(module, _module_file(module)))
    return sorted(_module_file(m) for m in seen)


def fingerprint(fmu: FmuDefinition) -> str:
    """SHA-256 of the FMU's definition, the bundled sources, this builder and the exporter version."""
    import pythonfmu
    import pythonfmu3

    h = hashlib.sha256()
    h.update(repr(fmu).encode())
    h.update(f"{fmu.adapter.__module__}.{fmu.adapter.__qualname__}".encode())  # the repr holds no classes
    h.update(Path(__file__).read_bytes())
    h.update(f"pythonfmu {pythonfmu.__version__} pythonfmu3 {pythonfmu3.__version__}".encode())
    h.update(repr(requirements.project_requirements(_ROOT)).encode())  # recorded in requirements.json
    bundled = source_files(fmu)
    traced = {p.relative_to(_ROOT).as_posix(): p for p in _traced_sources(fmu)}  # resources/traced.json's sources
    for rel, path in sorted({**bundled, **traced}.items()):  # each file once
        h.update(rel.encode() + b"\0" + path.read_bytes() + b"\0")
    if fmu.has_native:  # and the version of CasADi that traced and serialized it
        h.update(f"casadi {_version('casadi')}".encode())
    return h.hexdigest()


def _traced_sources(fmu: FmuDefinition) -> list[Path]:
    """The files a python FMU's traced model (:mod:`fmus.traced`) is made from: the native models, their tracer,
    and the formulas of ``delta``."""
    if not fmu.has_native:
        return []
    return [*_imported_closure(["fmus.native.generate"]), *_package_files("delta")]


def _version(distribution: str) -> str:
    """The installed version of ``distribution`` from its metadata (importing CasADi to ask it costs 25 ms)."""
    from importlib.metadata import PackageNotFoundError, version  # lazy: a fingerprint only

    try:
        return version(distribution)
    except PackageNotFoundError:
        return "not installed"


def bundle_name(digest: str) -> str:
    """Top-level package name of the bundled code: unique per source hash."""
    return f"_dcosim_{digest[:16]}"


def rewrite_imports(text: str, bundle: str, where: str) -> str:
    """Point absolute imports of project packages at the bundle package."""
    text = _FROM.sub(lambda m: f"{m[1]}from {bundle}.{m[2]}{m[3]}", text)

    def _imp(m: re.Match) -> str:
        alias = m[4] or f" as {m[2]}"
        if m[3] and not m[4]:
            raise BuildError(f"{where}: 'import {m[2]}{m[3]}' without 'as' cannot be bundled; use 'from ... import'")
        return f"{m[1]}import {bundle}.{m[2]}{m[3]}{alias}"

    text = _IMPORT.sub(_imp, text)
    left = _LEFT.search(text)
    if left:
        raise BuildError(f"{where}: import of a project package left unbundled: {left.group(0).strip()!r}")
    return text


def _stub(fmu: FmuDefinition, bundle: str) -> str:
    """The FMU's module: the class of :meth:`FmuDefinition.python_class`, on the bundled adapter."""
    kind = "None" if fmu.kind is None else repr(fmu.kind)
    adapter = fmu.adapter
    # pythonfmu3 finds the slave class by a regex that needs Fmi3SlaveBase among the written bases.
    base, extra = ("_Adapter, Fmi3SlaveBase", "from pythonfmu3 import Fmi3SlaveBase\n") if fmu.fmi == 3 \
        else ("_Adapter", "")
    # The host check comes first (standard library only): with a requirement unmet, the adapter is
    # not imported and instantiation fails naming what is missing (fmus.requirements).
    return (
        f'"""FMU {fmu.name}: {fmu.summary} (generated by fmus.builder)."""\n'
        f"import os as _os\n\n{extra}from {bundle}.fmus.requirements import load_adapter as _load_adapter\n\n"
        f"_Adapter = _load_adapter(_os.path.dirname(_os.path.abspath(__file__)), {fmu.name!r},\n"
        f"                         {bundle + '.' + adapter.__module__!r}, {adapter.__qualname__!r}, {fmu.fmi})\n"
        + (f"from {bundle}.fmus.traced import loader as _traced  # noqa: E402 (after the host check)\n"
           if fmu.has_native else "") + "\n\n"
        f"class {fmu.name}({base}):\n"
        f"    KIND = {kind}\n"
        + ("    TRACED = staticmethod(_traced(_os.path.dirname(_os.path.abspath(__file__))))\n"
           if fmu.has_native else "")
        + "\n\n"
        "# One spare reference to this module's globals for the exporter's class lookup, which\n"
        "# releases one per instantiation; each instance gives it back (fmus._names).\n"
        "_SPARE_GLOBALS_REFERENCE = globals()\n"
    )


def user_cache() -> Path:
    """The one FMU cache of this user, wherever a command runs: ``$DELTA_COSIM_CACHE``, else the platform's cache
    folder (``$XDG_CACHE_HOME``, else ``~/.cache``, as the XDG base directory convention says) ``/delta-cosim/fmus``.
    Entries are keyed by content (:func:`cached`), so one cache serves every checkout and working directory."""
    named = os.environ.get(CACHE_ENV)
    if named:
        return Path(named)
    base = os.environ.get("XDG_CACHE_HOME")
    return (Path(base) if base and Path(base).is_absolute() else Path.home() / ".cache") / "delta-cosim" / "fmus"


def cached(folder: Path, name: str, digest: str) -> tuple[Path, Path]:
    """(FMU, stamp) of the build of ``name`` whose fingerprint is ``digest`` in the cache ``folder``: the file keeps
    its name, ``name.fmu`` (a log names the FMU file its schemas came from), in a folder named by the hash."""
    key = folder / digest[:16]
    return key / f"{name}.fmu", key / f"{name}.json"


_ANNOUNCE: list[Callable[[str], None]] = []


def on_build(callback: Callable[[str], None] | None) -> None:
    """Have ``callback(message)`` told of every FMU that is built (not taken from the cache); None: nobody."""
    _ANNOUNCE[:] = [callback] if callback is not None else []


def announce(message: str) -> None:
    for callback in _ANNOUNCE:
        callback(message)


def prune(folder: Path, name: str) -> None:
    """Keep the :data:`KEEP` newest builds of ``name`` in ``folder``; a file another process removes first is fine."""
    builds = []
    for path in folder.glob(f"*/{name}.fmu"):
        try:
            if _HASH.fullmatch(path.parent.name):
                builds.append((path.stat().st_mtime, path))
        except OSError:
            continue
    for _, path in sorted(builds, reverse=True)[KEEP:]:
        path.with_suffix(".json").unlink(missing_ok=True)
        path.unlink(missing_ok=True)
        try:
            path.parent.rmdir()  # the hash's folder, once it holds no other FMU's build
        except OSError:
            pass


_HASH = re.compile(r"[0-9a-f]{16}")


def deliver(entry: Path, out_dir: str | Path | None, name: str) -> Path:
    """The cached FMU ``entry`` where the caller wants it: itself without ``out_dir``; else copied to
    ``out_dir/name.fmu`` (only the FMU: the cache's stamps stay in the cache), atomically, unless the same bytes
    are there already."""
    if out_dir is None:
        return entry
    out = cache_folder(Path(out_dir))
    target = out / f"{name}.fmu"
    try:
        if target.is_file() and target.stat().st_size == entry.stat().st_size \
                and target.read_bytes() == entry.read_bytes():
            return target
        partial = out / f".{name}.{os.getpid()}.partial.fmu"
        try:
            shutil.copyfile(entry, partial)
            partial.replace(target)
        finally:
            partial.unlink(missing_ok=True)
    except OSError as exc:
        raise BuildError(f"cannot write FMU {name} into {out}: {exc.strerror or exc}") from None
    return target


def cache_folder(folder: Path) -> Path:
    """``folder`` made (with its parents) to hold built FMUs; a :class:`BuildError` naming it and the remedy when the
    system refuses (a file in its place, no permission, a full or read-only disk)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _refused(folder, exc) from None
    return folder


def _refused(folder: Path, exc: OSError) -> BuildError:
    return BuildError(f"cannot use {folder} for built FMUs: {exc.strerror or exc} (it must be a folder this user "
                      f"can write: move what is in its place, or name another cache with {CACHE_ENV}=FOLDER; "
                      "fmus build writes elsewhere with --out)")


@contextmanager
def build_lock(folder: Path, name: str) -> Iterator[None]:
    """Hold the building of FMU ``name`` into the cache ``folder`` (its lock file ``.NAME.lock`` there). Processes
    that miss the same entry together (a test suite's workers, runs started at once on an empty cache) build it
    once: the others wait here, say so, and then find it current (the caller looks again). An ``flock``: the system
    releases it when the holder ends, however it ends. Without ``fcntl`` (Windows), no lock: each builds its own,
    atomically (:func:`install`)."""
    try:
        import fcntl  # POSIX
    except ImportError:
        yield
        return
    try:
        fd = os.open(folder / f".{name}.lock", os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        raise _refused(folder, exc) from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            announce(f"waiting for another process building FMU {name} into {folder}")
            fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def built(folder: Path, name: str, digest: str, what: str, build: Callable[[], Any], *, force: bool = False) -> Path:
    """The cache ``folder``'s FMU ``name`` of fingerprint ``digest``: ``build()`` (which installs it there) is called
    unless a current build is there, under the FMU's :func:`build_lock`, looking again once the lock is held (a
    process this one waited for built it), said (``what``: the kind of build) and followed by :func:`prune`."""
    target, stamp = cached(folder, name, digest)
    if force or not is_current(target, stamp, digest):
        with build_lock(folder, name):
            if force or not is_current(target, stamp, digest):
                announce(f"building FMU {name} ({what}) into {folder}")
                build()
                prune(folder, name)
    return target


def is_current(target: Path, stamp: Path, digest: str) -> bool:
    """Whether ``target`` is an FMU archive and its ``stamp`` (the JSON written beside it) records ``digest``; a
    missing, damaged or foreign entry (a stamp that is no JSON object, a folder, a truncated archive) is not, and
    is built again."""
    try:
        record = json.loads(stamp.read_text(encoding="utf-8"))
        return (isinstance(record, dict) and record.get("fingerprint") == digest and target.is_file()
                and zipfile.is_zipfile(target))
    except (OSError, ValueError):
        return False


def install(out: Path, name: str, write: Callable[[Path], None], record: dict[str, Any]) -> Path:
    """Put a built FMU into the cache ``out`` as ``name.fmu`` with its stamp ``name.json`` (``record``): ``write``
    fills a partial file of this process's own (concurrent builds never share one), which then replaces the FMU;
    the stamp is written the same way, last, so a reader sees a complete FMU before a stamp that vouches for it.
    Nothing is left behind when ``write`` fails."""
    target, stamp = out / f"{name}.fmu", out / f"{name}.json"
    own = f".{name}.{os.getpid()}.partial"
    partial, partial_stamp = out / f"{own}.fmu", out / f"{own}.json"
    try:
        write(partial)
        partial.replace(target)
        partial_stamp.write_text(json.dumps(record, indent=2), encoding="utf-8")
        partial_stamp.replace(stamp)
    except OSError as exc:
        raise BuildError(f"cannot write FMU {name} into {out}: {exc.strerror or exc}") from None
    finally:
        partial.unlink(missing_ok=True)
        partial_stamp.unlink(missing_ok=True)
    return target


@contextmanager
def scratch(name: str, kind: str) -> Iterator[Path]:
    """A temporary folder (in ``$TMPDIR``, else the system's) to build FMU ``name`` in, removed afterwards. A folder
    the system refuses to make or to fill (full, read-only, over quota) ends in one BuildError naming it and
    ``TMPDIR``, where it was an internal error."""
    try:
        tmp = tempfile.mkdtemp(prefix=f"{kind}_{name}_")
    except OSError as exc:
        raise BuildError(f"cannot make a temporary folder to build FMU {name} in {tempfile.gettempdir()}: "
                         f"{exc.strerror or exc} (set TMPDIR to a writable folder with room)") from None
    try:
        yield Path(tmp)
    except OSError as exc:
        if refused_by_system(exc, tmp):
            raise BuildError(f"cannot build FMU {name} in the temporary folder {tmp}: {exc.strerror or exc} "
                             "(set TMPDIR to a writable folder with room)") from None
        raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def build_python(fmu: FmuDefinition, out_dir: str | Path | None = None, *, force: bool = False) -> Path:
    """The python FMU that ``fmu`` defines, built into the user's cache (:func:`user_cache`) unless a build with the
    same fingerprint is there, then copied to ``out_dir`` if one is given (:func:`deliver`)."""
    cache = cache_folder(user_cache())
    digest = fingerprint(fmu)
    target = built(cache, fmu.name, digest, f"python, FMI {fmu.fmi}", lambda: _build_python(fmu, cache, digest),
                   force=force)
    return deliver(target, out_dir, fmu.name)


def _build_python(fmu: FmuDefinition, out: Path, digest: str) -> Path:
    """Build it into the cache folder ``out`` as :func:`cached` names it, with its stamp."""
    bundle = bundle_name(digest)
    module = f"{fmu.name}_{digest[:16]}"
    saved_path = list(sys.path)
    before = set(sys.modules)
    with scratch(fmu.name, "fmu") as tmp:
        pkg = tmp / bundle
        pkg.mkdir()
        (pkg / "__init__.py").write_text(f'"""Project code bundled with FMU {fmu.name} ({digest[:16]})."""\n')
        for rel, path in source_files(fmu).items():
            dest = pkg / rel
            dest.parent.mkdir(parents=True, exist_ok=True)
            dest.write_text(rewrite_imports(path.read_text(), bundle, rel))
        for package in {rel.split("/", 1)[0] for rel in source_files(fmu)}:
            init = pkg / package / "__init__.py"
            if not init.exists():
                init.write_text("")
        script = tmp / f"{module}.py"
        script.write_text(_stub(fmu, bundle))
        resources = []
        if fmu.has_native:  # its step: the traced functions of its native model (fmus.traced)
            from .traced import FILE

            (traced := tmp / FILE).write_text(fmu.traced_model().dumps())
            resources.append(traced)
        needs = tmp / requirements.FILE  # copied to resources/ (fmus.requirements)
        needs.write_text(json.dumps(requirements.collect(source_files(fmu).values(), _ROOT, _PROJECT_PACKAGES),
                                    indent=2))
        staging = tmp / "out"
        staging.mkdir()
        try:
            if fmu.fmi == 3:
                from pythonfmu3.builder import FmuBuilder
            else:
                from pythonfmu.builder import FmuBuilder
            built = Path(FmuBuilder.build_FMU(script, dest=staging, project_files=[pkg, needs, *resources]))
        except OSError:  # the system's refusal: named with the folder by scratch when it is there
            raise
        except Exception as exc:  # the exporter raises bare exceptions; name the FMU
            raise BuildError(f"building FMU {fmu.name!r} failed: {type(exc).__name__}: {exc}") from exc
        finally:
            sys.path[:] = saved_path
            for name in set(sys.modules) - before:
                if name == module or name.startswith(bundle):
                    del sys.modules[name]
        return install(cache_folder(cached(out, fmu.name, digest)[0].parent), fmu.name,
                       lambda partial: shutil.move(str(built), partial),
                       {"name": fmu.name, "fingerprint": digest, "module": module, "bundle": bundle, "fmi": fmu.fmi})


