"""Small FMI 1 / FMI 2 / FMI 3 test FMUs of our own, written in C and built on demand.

``build(model, fmi)`` compiles ``c/models/<model file>`` with the FMI wrapper
of that version and zips it with its generated modelDescription.xml into
``<repo>/.fmu_cache/cfmus/<model>-fmi<fmi>-<key>.fmu``. An FMI 1.0 FMU has one
interface, so FMI 1 takes it too: ``build(model, 1, "cs")`` or ``"me"`` (file
``<model>-fmi1-<interface>-<key>.fmu``). ``key`` hashes every
C source and header, the Python that generates the description, the FMI
headers and ``gcc --version``, so an edit to any of them rebuilds and an
unchanged FMU is reused. Files are written under a temporary name in the
cache directory and renamed into place, so concurrent test processes never
see half an FMU, and nothing is left in /tmp.

    >>> from cfmus import build, MODELS          # tests/ on sys.path
    >>> fmu = build("BouncingBall", 3)           # pathlib.Path to the .fmu
    >>> fmu1 = build("Stair", 1, "cs")           # FMI 1.0 co-simulation
"""

from __future__ import annotations

import functools
import hashlib
import os
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from pathlib import Path

from .generate import model_description, variables_header
from .models import MODEL_SPECS, state_space_defaults

__all__ = ["build", "MODELS", "MODELS_FMI1", "BuildError", "CACHE_DIR", "state_space_defaults"]

HERE = Path(__file__).resolve().parent
C_DIR = HERE / "c"
CACHE_DIR = HERE.parents[1] / ".fmu_cache" / "cfmus"
MODELS: list[tuple[str, int]] = sorted(k for k in MODEL_SPECS if k[1] > 1)  # FMUs with both interfaces
MODELS_FMI1: list[str] = sorted(m for m, fmi in MODEL_SPECS if fmi == 1)  # built per interface
CFLAGS = ("-std=c11", "-O1", "-fPIC", "-shared", "-fvisibility=hidden", "-Wall", "-Wextra", "-Werror")


class BuildError(RuntimeError):
    """The C compiler failed; the message holds the command and gcc's stderr."""


def _fmi_headers() -> Path:
    import fmpy

    return Path(fmpy.__file__).resolve().parent / "c-code"


@functools.lru_cache(maxsize=1)
def _compiler_version() -> bytes:
    try:
        return subprocess.run(["gcc", "--version"], capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError) as e:
        raise BuildError(f"gcc is needed to build the C test FMUs: {e}") from e


@functools.lru_cache(maxsize=None)
def _source_key() -> str:
    """Hash of everything an FMU is built from (except the model choice)."""
    h = hashlib.sha256(_compiler_version())
    files = sorted(C_DIR.rglob("*.[ch]")) + sorted(HERE.glob("*.py"))
    files += sorted(_fmi_headers().glob("fmi[123]*.h"))
    for f in files:
        h.update(f.name.encode() + b"\0" + f.read_bytes() + b"\0")
    h.update(" ".join(CFLAGS).encode())
    return h.hexdigest()


def _compile(model: str, fmi: int, token: str, workdir: Path) -> Path:
    spec = MODEL_SPECS[(model, fmi)]
    (workdir / "variables.h").write_text(variables_header(spec))
    library = workdir / f"{model}.so"
    cmd = [
        "gcc", *CFLAGS,
        f"-I{C_DIR}", f"-I{_fmi_headers()}", f"-I{workdir}",
        f"-DINSTANTIATION_TOKEN=\"{token}\"", f"-DMODEL_IDENTIFIER={model}", f"-DCFMU_FMU_STATE={int(spec.fmu_state)}",
        str(C_DIR / "core.c"), str(C_DIR / f"fmi{fmi}_wrapper.c"), str(C_DIR / "models" / spec.source),
        "-o", str(library), "-lm",
    ]
    env = {**os.environ, "TMPDIR": str(workdir)}  # gcc's own temporary files stay in the work directory
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise BuildError(f"compiling {model} (FMI {fmi}) failed:\n$ {' '.join(cmd)}\n{proc.stderr}")
    return library


def build(model: str, fmi: int, interface: str | None = None) -> Path:
    """Path of the FMU ``model`` for FMI version ``fmi`` (1, 2 or 3), built if needed; ``interface``
    ("cs" or "me") is the one interface of an FMI 1.0 FMU (FMI 2 and 3 files carry both).

    Raises ``KeyError`` for an unknown pair (see ``MODELS``, ``MODELS_FMI1``), ``ValueError`` for a
    missing or needless ``interface`` and ``BuildError`` with gcc's stderr when the compilation fails.
    """
    if (model, fmi) not in MODEL_SPECS:
        raise KeyError(f"no test FMU {model!r} for FMI {fmi}; available: {MODELS}, FMI 1: {MODELS_FMI1}")
    if (fmi == 1) != (interface in ("cs", "me")) or (fmi > 1 and interface is not None):
        raise ValueError(f"FMI {fmi}: interface {interface!r}, expected 'cs' or 'me' for FMI 1 and none otherwise")
    kind = f"fmi{fmi}" if fmi > 1 else f"fmi1-{interface}"
    key = _source_key()
    target = CACHE_DIR / f"{model}-{kind}-{key[:16]}.fmu"
    if target.exists():
        return target
    CACHE_DIR.mkdir(parents=True, exist_ok=True)
    token = "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"cfmus/{model}/{kind}/{key}")) + "}"
    workdir = Path(tempfile.mkdtemp(prefix=f".build-{model}-{fmi}-", dir=CACHE_DIR))
    try:
        library = _compile(model, fmi, token, workdir)
        xml = model_description(MODEL_SPECS[(model, fmi)], token, interface)
        partial = workdir / "fmu.zip"
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("modelDescription.xml", xml)
            z.write(library, f"binaries/linux64/{model}.so")
            if fmi == 3:
                z.write(library, f"binaries/x86_64-linux/{model}.so")
        os.replace(partial, target)  # atomic: readers see no FMU or a whole one
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    _remove_stale(model, kind, keep=target)
    return target


def _remove_stale(model: str, kind: str, keep: Path) -> None:
    """Drop builds of the same FMU from older sources (best effort)."""
    for old in CACHE_DIR.glob(f"{model}-{kind}-????????????????.fmu"):
        if old != keep:
            old.unlink(missing_ok=True)
