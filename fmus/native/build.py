"""Build native FMUs: trace the model on symbols, generate C with CasADi, compile, zip with the sources.

For an FMU's definition (:class:`fmus.definition.FmuDefinition`) that has a native model, and FMI version 2 or 3:

1. the interface comes from the definition's python adapter (:func:`fmus.native.interface.interface`);
2. each model function (start, refresh, advance, derivatives, accept) is traced on ``SX`` symbols: time,
   step, the values array (one element per value reference) and the internal state; CasADi's code generator
   writes them as one self-contained C file (``model_functions.c``);
3. ``model.c`` binds them to the contract of ``c/model.h`` (the variable table, which values each
   function sets, which of its checks are errors) and the FMI glue written once (``c/runtime.c`` and ``c/state.c``,
   ``c/fmi2Functions.c`` or ``c/fmi3Functions.c``) makes the FMU;
4. the sources go into ``sources/`` (FMI 2 ``SourceFiles``, FMI 3 ``buildDescription.xml``) with the FMI
   headers, so a tool on another platform can compile them; a binary for this platform is linked from parts
   compiled with the system C compiler (``$CC``, default ``cc``): the FMU's generated model, compiled once for both
   FMI versions, and the FMI version's glue, compiled once for every FMU (:mod:`fmus.native.parts`).

Generated code is built into the cache, never committed. The cache key hashes every source that goes
into a native FMU (the ``delta`` formulas, the adapters that declare the interface and the layer they declare
it with, the definitions, this package, the C glue) and the CasADi version.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import zipfile
from functools import lru_cache
from pathlib import Path

from ..builder import built, cache_folder, cached, deliver, install, scratch, user_cache
from ..definition import FmuDefinition
from .errors import CompilerMissingError, NativeError
from .interface import interface, model_description
from .parts import glue_sources, link

__all__ = ["build_native", "compiler", "fingerprint", "FMI_VERSIONS"]

FMI_VERSIONS = (2, 3)
_HERE = Path(__file__).resolve().parent
_ROOT = _HERE.parent.parent
_HEADERS = {2: ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"),
            3: ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")}
_FMUS = ("__init__.py", "_names.py", "export2.py", "export3.py", "definition.py", "registry.py")
"""The modules of :mod:`fmus` a native FMU is made from (besides the adapters and this package)."""


def compiler() -> str:
    """The C compiler to use (``$CC`` or ``cc``); raises :class:`CompilerMissingError` when there is none."""
    cc = os.environ.get("CC", "cc")
    if shutil.which(cc) is None:
        raise CompilerMissingError(f"native FMUs need a C compiler: {cc!r} is not on PATH (install gcc or clang, "
                                   f"e.g. 'apt install gcc', or set CC); the python build (fmus: python) works without")
    return cc


def _fmi_headers() -> Path:
    import fmpy

    return Path(fmpy.__file__).resolve().parent / "c-code"


def fingerprint() -> str:
    """SHA-256 of everything a native FMU is made from (the same for every native FMU of this checkout). The
    files are read again only when one of them changed (size or time), not for every FMU of every run."""
    files = sorted([*(_ROOT / "delta").glob("*.py"), *(_ROOT / "fmus" / "adapters").glob("*.py"),
                    *(_ROOT / "fmus" / name for name in _FMUS), *_HERE.glob("*.py"),
                    *(_HERE / "c").glob("*.[ch]")])
    return _digest(tuple((p, p.stat().st_mtime_ns, p.stat().st_size) for p in files))


@lru_cache(maxsize=4)
def _digest(stats: tuple[tuple[Path, int, int], ...]) -> str:
    from importlib.metadata import version  # not the import of CasADi (~0.03 s), which a cached build does not need

    h = hashlib.sha256(f"casadi {version('casadi')}".encode())
    for path, _, _ in stats:
        h.update(path.relative_to(_ROOT).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


# ----------------------------------------------------------------------------- FMU assembly

def _build_description(sources: list[str]) -> bytes:
    files = "\n".join(f'      <SourceFile name="{s}"/>' for s in sources)
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<fmiBuildDescription fmiVersion="3.0">\n'
            f'  <BuildConfiguration modelIdentifier="{{id}}">\n    <SourceFileSet language="C99">\n{files}\n'
            f'    </SourceFileSet>\n  </BuildConfiguration>\n</fmiBuildDescription>\n').encode()


def build_native(fmu: FmuDefinition, fmi: int = 2, out_dir: str | Path | None = None, *, force: bool = False) -> Path:
    """Build (or reuse from the cache) the native build of the FMU ``fmu`` defines, for FMI ``fmi`` (2 or 3); return
    its path.

    It is built into the user's cache (:func:`fmus.builder.user_cache`) ``/native/fmi<fmi>``, keyed by its
    fingerprint, unless there already; given ``out_dir``, copied to ``<out_dir>/native/fmi<fmi>/<name>.fmu``.
    Raises :class:`CompilerMissingError` without a C compiler and :class:`NativeError` when the FMU has no native
    build or does not compile.
    """
    name = fmu.name
    if fmi not in FMI_VERSIONS:
        raise NativeError(f"native FMU {name}: FMI version must be 2 or 3, got {fmi!r}")
    if not fmu.has_native:
        raise NativeError(f"FMU {name!r} has no native build")
    cc = compiler()
    out = cache_folder(user_cache() / "native" / f"fmi{fmi}")
    digest = fingerprint()
    target = built(out, name, digest, f"native, FMI {fmi}", lambda: _build(fmu, fmi, cc, out, digest, force),
                   force=force)
    return deliver(target, None if out_dir is None else Path(out_dir) / "native" / f"fmi{fmi}", name)


def _build(fmu: FmuDefinition, fmi: int, cc: str, out: Path, digest: str, force: bool) -> Path:
    """Generate, compile (``force``: every part again), load once and cache the native FMU as
    :func:`fmus.builder.cached` names it."""
    name = fmu.name
    own = hashlib.sha256((digest + name).encode()).hexdigest()
    token = "{" + f"{own[:8]}-{own[8:12]}-{own[12:16]}-{own[16:20]}-{own[20:32]}" + "}"
    with scratch(name, "native") as tmp:
        root = tmp / "fmu"
        src = root / "sources"
        src.mkdir(parents=True)
        from .generate import generate  # lazy: CasADi and the models, which a cached build does not load

        for f in ("model.h", "runtime.h", *glue_sources(fmi)):
            shutil.copy2(_HERE / "c" / f, src / f)
        for f in _HEADERS[fmi]:
            shutil.copy2(_fmi_headers() / f, src / f)
        binary = root / "binaries" / ("linux64" if fmi == 2 else "x86_64-linux") / f"{name}.so"
        generated = link(cc, digest, name, fmi, src, binary, lambda folder: generate(fmu, folder, token),
                         lambda lib: _loads(lib, name, cc), force=force)
        sources = [*generated, *glue_sources(fmi)]
        (root / "modelDescription.xml").write_bytes(model_description(interface(name, fmu.native_model()), fmi,
                                                                      token, sources))
        if fmi == 3:
            (src / "buildDescription.xml").write_bytes(_build_description(sources).replace(b"{id}", name.encode()))

        def write(partial: Path) -> None:
            with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as zf:
                for path in sorted(root.rglob("*")):
                    if path.is_file():
                        zf.write(path, path.relative_to(root).as_posix())

        return install(cache_folder(cached(out, name, digest)[0].parent), name, write,
                       {"name": name, "fingerprint": digest, "fmi": fmi, "build": "native"})


def _loads(binary: Path, name: str, cc: str) -> None:
    """Raise :class:`NativeError` unless the compiled library loads with every symbol resolved (a compiler that
    exits 0 and writes no loadable library must not leave an FMU in the cache behind a current stamp)."""
    import ctypes  # lazy: only a build loads its library here

    try:
        ctypes.CDLL(str(binary), mode=ctypes.RTLD_LOCAL)
    except OSError as exc:
        raise NativeError(f"native FMU {name}: {cc} made a library that does not load ({exc}); nothing was "
                          "cached") from None
