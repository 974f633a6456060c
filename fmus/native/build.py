"""Build native FMUs: trace the model on symbols, generate C with CasADi, compile, zip with the sources.

For an FMU's definition (:class:`fmus.definition.FmuDefinition`) that has a native model, and FMI version 2 or 3:

1. the interface comes from the definition's python adapter (:func:`fmus.native.interface.interface`);
2. each model function (start, refresh, advance, derivatives) is traced on ``SX`` symbols: time, step,
   the values array (one element per value reference) and the internal state; CasADi's code generator
   writes the four as one self-contained C file (``model_functions.c``);
3. ``model.c`` binds them to the contract of ``c/model.h`` (the variable table, which values each
   function sets, which of its checks are errors) and the FMI glue written once (``c/runtime.c`` and ``c/state.c``,
   ``c/fmi2Functions.c`` or ``c/fmi3Functions.c``) makes the FMU;
4. the sources go into ``sources/`` (FMI 2 ``SourceFiles``, FMI 3 ``buildDescription.xml``) with the FMI
   headers, so a tool on another platform can compile them; a binary for this platform is compiled
   with the system C compiler (``$CC``, default ``cc``).

Generated code is built into the cache, never committed. The cache key hashes every source that goes
into a native FMU (the ``delta`` formulas, the adapters that declare the interface and the layer they declare
it with, the definitions, this package, the C glue) and the CasADi version.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import zipfile
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

from ..builder import announce, cache_folder, cached, deliver, install, is_current, prune, scratch, user_cache
from ..definition import FmuDefinition
from .errors import CompilerMissingError, NativeError
from .interface import Interface, interface, model_description
from .models import NativeModel, Result, Symbols
from .symbolic import tracing

__all__ = ["build_native", "compiler", "fingerprint", "generate", "FMI_VERSIONS"]

FMI_VERSIONS = (2, 3)
_HERE = Path(__file__).resolve().parent
_ROOT = _HERE.parent.parent
_GLUE = {2: ("runtime.c", "state.c", "fmi2Functions.c"), 3: ("runtime.c", "state.c", "fmi3Functions.c")}
_HEADERS = {2: ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"),
            3: ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")}
_FUNCTIONS = ("start", "refresh", "advance", "derivatives", "accept")
MAX_DETAIL = 4  # values a check may print into its reason (MODEL_MAX_DETAIL of c/model.h)
CFLAGS = ("-std=c99", "-O2", "-fPIC", "-shared", "-Wall", "-Wextra")
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
    import casadi

    h = hashlib.sha256(f"casadi {casadi.__version__}".encode())
    for path, _, _ in stats:
        h.update(path.relative_to(_ROOT).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


# ----------------------------------------------------------------------------- code generation

@dataclass
class _Function:
    name: str
    sets: list[int]  # value references the function writes, in output order
    checks: list[tuple[str, bool, int]]  # (reason, is error, number of values it prints), in output order
    n_w: int
    n_iw: int
    sets_state: bool


def _trace(model: NativeModel, itf: Interface, which: str):  # noqa: ANN202
    import casadi as ca

    variables = itf.variables
    t, h = ca.SX.sym("t"), ca.SX.sym("h")
    values = ca.SX.sym("v", len(variables))
    state = ca.SX.sym("s", max(model.n_state, 1))
    sym = Symbols(t, h, {v.name: values[v.vr] for v in variables}, [state[i] for i in range(model.n_state)])
    with tracing() as trace:
        result: Result = getattr(model, which)(sym, trace)
    if trace.checks:
        raise NativeError(f"FMU {itf.name}: {which} left checks unhandled: {[r for _, r in trace.checks]}")
    vr = {v.name: v.vr for v in variables}
    unknown = [n for n in result.values if n not in vr]
    if unknown:
        raise NativeError(f"FMU {itf.name}: {which} sets {unknown}, which are not variables of the FMU")
    sets = sorted(vr[n] for n in result.values)
    by_vr = {vr[n]: x for n, x in result.values.items()}
    out_values = ca.vertcat(*[ca.SX(by_vr[k]) for k in sets]) if sets else ca.SX(1, 1)
    new_state = result.state if result.state is not None else [state[i] for i in range(model.n_state)]
    if len(new_state) != model.n_state:
        raise NativeError(f"FMU {itf.name}: {which} gives {len(new_state)} state values, the model has {model.n_state}")
    out_state = ca.vertcat(*[ca.SX(x) for x in new_state]) if new_state else ca.SX(1, 1)
    checks = result.checks
    wide = [c.reason for c in checks if len(c.values) > MAX_DETAIL]
    if wide:
        raise NativeError(f"FMU {itf.name}: {which}: checks print at most {MAX_DETAIL} values: {wide}")
    out_checks = ca.vertcat(*[ca.SX(c.ok) for c in checks]) if checks else ca.SX(1, 1)
    details = [x for c in checks for x in c.values]
    out_details = ca.vertcat(*[ca.SX(x) for x in details]) if details else ca.SX(1, 1)
    # cse: one node per distinct operation on the same operands (the formulas compute some twice, e.g. a leg's
    # J row in leg_rates and in the plant's system): the same numbers, 16 % fewer operations in the plant's step
    fn = ca.Function(f"{itf.name}_{which}", [t, h, values, state], [out_values, out_state, out_checks, out_details],
                     {"cse": True})
    return fn, _Function(which, sets, [(c.reason, c.error, len(c.values)) for c in checks], fn.sz_w(), fn.sz_iw(),
                         result.state is not None)


def _c_string(text: str) -> str:
    return json.dumps(text)


def _model_c(model: NativeModel, itf: Interface, token: str, functions: list[_Function], constants: Any,
             params: list[int]) -> str:
    """``model.c``: the model's tables (:func:`_tables_c`), its constants (:func:`_constants_c`) and one C function
    per traced function (:func:`_function_c`), which the FMI glue in ``native/c`` calls."""
    checks: list[tuple[str, bool, int]] = []
    for f in functions:
        checks += f.checks
    lines = _tables_c(model, itf, token, checks, constants, params) + _constants_c(itf, constants, params)
    if checks:
        lines += [
            "",
            "/* The first failed check: an error before any warning; 0 when all hold. */",
            "static int first_failed(const double *ok, size_t n, size_t offset) {",
            "    size_t k;",
            "    int warning = 0;",
            "    for (k = 0; k < n; k++) {",
            "        if (ok[k] != 0.0) continue;",
            "        if (MODEL_CHECK_IS_ERROR[offset + k]) return (int)(offset + k + 1);",
            "        if (!warning) warning = (int)(offset + k + 1);",
            "    }",
            "    return warning;",
            "}",
        ]
    offset = 0
    for f in functions:
        lines += _function_c(model, itf, f, offset)
        offset += len(f.checks)
    return "\n".join(lines) + "\n"


_CAUSALITY = {"parameter": "CAUSALITY_PARAMETER", "input": "CAUSALITY_INPUT", "output": "CAUSALITY_OUTPUT",
              "local": "CAUSALITY_LOCAL", "independent": "CAUSALITY_INDEPENDENT"}
_VARIABILITY = {"constant": "VARIABILITY_CONSTANT", "fixed": "VARIABILITY_FIXED", "tunable": "VARIABILITY_TUNABLE",
                "discrete": "VARIABILITY_DISCRETE", "continuous": "VARIABILITY_CONTINUOUS"}
_VTYPE = {"real": "TYPE_REAL", "boolean": "TYPE_BOOLEAN", "integer": "TYPE_INTEGER", "string": "TYPE_STRING"}


def _tables_c(model: NativeModel, itf: Interface, token: str, checks: list[tuple[str, bool, int]], constants: Any,
              params: list[int]) -> list[str]:
    """The model's identity and tables: its variables, states, checks, options and default experiment."""
    vr = {v.name: v.vr for v in itf.variables}
    return [
        f"/* model.c of the native FMU {itf.name}: generated by fmus.native.build; do not edit. */",
        '#include <string.h>', '#include "model.h"', '#include "model_functions.h"', "",
        f"const char *const MODEL_IDENTIFIER = {_c_string(itf.name)};",
        f"const char *const MODEL_TOKEN = {_c_string(token)};",
        f"const size_t MODEL_N_VARIABLES = {len(itf.variables)};",
        *(f"static const char *const CHOICES_{v.vr}[] = {{{', '.join(_c_string(c) for c in v.choices)}}};"
          for v in itf.variables if v.choices),
        "const ModelVariable MODEL_VARIABLES[] = {",
        *(f"    {{{_c_string(v.name)}, {_VTYPE[v.type]}, {_CAUSALITY[v.causality]}, {_VARIABILITY[v.variability]}, "
          f"{float(v.start or 0.0)!r}, {f'CHOICES_{v.vr}, {len(v.choices)}' if v.choices else 'NULL, 0'}}},"
          for v in itf.variables),
        "};",
        f"const size_t MODEL_N_STATES = {model.n_state};",
        *([f"static const double INITIAL_STATE[] = {{{', '.join(repr(float(x)) for x in model.initial_state())}}};"]
          if model.n_state else []),
        f"const size_t MODEL_N_CONTINUOUS = {len(itf.states)};",
        f"const size_t MODEL_STATE_VRS[] = {{{', '.join(str(vr[s]) for s, _ in itf.states) or '0'}}};",
        f"const size_t MODEL_DERIVATIVE_VRS[] = {{{', '.join(str(vr[d]) for _, d in itf.states) or '0'}}};",
        f"const size_t MODEL_N_CHECKS = {len(checks)};",
        f"const char *const MODEL_CHECKS[] = {{{', '.join(_c_string(r) for r, _, _ in checks) or _c_string('')}}};",
        f"const int MODEL_CHECK_IS_ERROR[] = {{{', '.join('1' if e else '0' for _, e, _ in checks) or '0'}}};",
        f"const int MODEL_CHECK_N_VALUES[] = {{{', '.join(str(n) for _, _, n in checks) or '0'}}};",
        f"const size_t MODEL_MAX_STEP_VR = {vr[model.max_step] if model.max_step else 0};",
        f"const int MODEL_ME_ADVANCES = {1 if model.me_advances else 0};",
        f"const int MODEL_ME_ACCEPTS = {1 if model.me_accepts else 0};",
        f"const double MODEL_DEFAULT_EXPERIMENT[3] = {{{', '.join(repr(float(x)) for x in itf.experiment)}}};",
        f"const size_t MODEL_N_SCRATCH = {1 + len(params) + constants.nnz_out(0)};",
    ]


def _constants_c(itf: Interface, constants: Any, params: list[int]) -> list[str]:
    """``constants(values)``: what depends on parameters only, kept after the variables (``MODEL_N_SCRATCH``) and
    computed again when a parameter differs."""
    return [
        "",
        "/* The constants (what depends on parameters only), kept after the variables (MODEL_N_SCRATCH): a flag, the",
        "   parameter values they were computed from, the constants; computed again when a parameter differs. */",
        f"static const size_t PARAMETER_VRS[] = {{{', '.join(map(str, params)) or '0'}}};",
        "static const double *constants(double *values) {",
        "    double *scratch = values + MODEL_N_VARIABLES + 1, *known = scratch + 1;",
        f"    double *k = known + {len(params)};",
        "    const casadi_real *arg[1];",
        "    casadi_real *res[1];",
        f"    casadi_int iw[{max(constants.sz_iw(), 1)}];",
        f"    casadi_real w[{max(constants.sz_w(), 1)}];",
        "    size_t i;",
        "    int same = scratch[0] != 0.0;",
        f"    for (i = 0; same && i < {len(params)}; i++)",
        "        same = memcmp(&known[i], &values[PARAMETER_VRS[i]], sizeof(double)) == 0;",
        "    if (same) return k;",
        "    arg[0] = values; res[0] = k;",
        f"    if ({itf.name}_constants(arg, res, iw, w, 0)) return k;",
        f"    for (i = 0; i < {len(params)}; i++) known[i] = values[PARAMETER_VRS[i]];",
        "    scratch[0] = 1.0;",
        "    (void)PARAMETER_VRS;",
        "    return k;",
        "}",
    ]


def _function_c(model: NativeModel, itf: Interface, f: _Function, offset: int) -> list[str]:
    """``model_<name>``: one traced function called with the values, the state and the constants; its checks are
    the model's from ``offset`` on."""
    fn = f"{itf.name}_{f.name}"
    n_sets, n_checks = len(f.sets), len(f.checks)
    firsts, n_details = [], 0  # where each check's values start in the function's details
    for _, _, n in f.checks:
        firsts.append(n_details)
        n_details += n
    args = "double time, double h, double *values, double *state, double *detail" if f.name == "advance" else \
        "double time, double *values, double *state, double *detail"
    lines = [
        "",
        f"int model_{f.name}({args}) {{",
        f"    static const size_t sets[] = {{{', '.join(map(str, f.sets)) or '0'}}};",
        f"    static const size_t first_value[] = {{{', '.join(map(str, firsts)) or '0'}}};",
        (f"    double out[{max(n_sets, 1)}], new_state[{max(model.n_state, 1)}], ok[{max(n_checks, 1)}], "
         f"details[{max(n_details, 1)}];"),
        f"    casadi_int iw[{max(f.n_iw, 1)}];",
        f"    casadi_real w[{max(f.n_w, 1)}];",
        "    double h_arg = " + ("h" if f.name == "advance" else "0.0") + ";",
        "    double state_arg[" + str(max(model.n_state, 1)) + "] = {0.0};",
        "    const casadi_real *arg[5];",
        "    casadi_real *res[4];",
        "    size_t k;",
        "    int failed;",
        "    (void)sets; (void)k; (void)first_value; (void)failed;",
        f"    memcpy(state_arg, state, sizeof(double) * {model.n_state});" if model.n_state else "    (void)state;",
        "    arg[0] = &time; arg[1] = &h_arg; arg[2] = values; arg[3] = state_arg; arg[4] = constants(values);",
        "    res[0] = out; res[1] = new_state; res[2] = ok; res[3] = details;",
        f"    if ({fn}(arg, res, iw, w, 0)) return -1;",
    ]
    if n_sets:
        lines.append(f"    for (k = 0; k < {n_sets}; k++) values[sets[k]] = out[k];")
    if f.name == "start" and model.n_state:
        lines.append(f"    memcpy(state, INITIAL_STATE, sizeof(double) * {model.n_state});")
    if f.sets_state and model.n_state:
        lines.append(f"    memcpy(state, new_state, sizeof(double) * {model.n_state});")
    if n_checks:
        lines += [
            f"    failed = first_failed(ok, {n_checks}, {offset});",
            "    if (failed > 0)  /* the values its reason prints */",
            "        for (k = 0; k < (size_t)MODEL_CHECK_N_VALUES[failed - 1]; k++)",
            f"            detail[k] = details[first_value[failed - 1 - {offset}] + k];",
            "    return failed;",
        ]
    else:
        lines += ["    (void)ok; (void)details; (void)detail;", "    return 0;"]
    lines.append("}")
    return lines


def generate(fmu: FmuDefinition, out: Path, token: str) -> tuple[Interface, list[str]]:
    """Write the generated C of the FMU (``model.c``, ``model_functions.c/.h``) into ``out``; return the interface
    and the generated file names."""
    import casadi as ca

    model = fmu.native_model()
    itf = interface(fmu.name, model)
    traced = [_trace(model, itf, which) for which in _FUNCTIONS]
    functions, constants, params = _hoisted(itf, traced)
    gen = ca.CodeGenerator("model_functions.c", {"with_header": True, "casadi_real": "double",
                                                 "casadi_int": "long long int"})
    for fn in (constants, *(fn for fn, _ in functions)):
        gen.add(fn)
    gen.generate(str(out) + os.sep)
    (out / "model.c").write_text(_model_c(model, itf, token, [f for _, f in functions], constants, params))
    return itf, ["model_functions.c", "model.c"]


def _hoisted(itf: Interface, traced: list) -> tuple[list, Any, list[int]]:
    """The traced functions with what depends on parameters only taken out of them (``casadi.extract_parametric``
    over all of them at once): ``(functions taking the constants as a fifth input, the constants function of the
    values, the parameters' value references)``. The generated glue computes the constants when the parameters
    change (:func:`_model_c`), not at every call: the leg angles' cosines, the mass lumps, the geometry's squares.
    The same operations on the same numbers, so the same results."""
    import casadi as ca

    n_state = traced[0][0].size1_in(3)
    t, h = ca.SX.sym("t"), ca.SX.sym("h")
    values, state = ca.SX.sym("v", len(itf.variables)), ca.SX.sym("s", n_state)
    params = [v.vr for v in itf.variables if v.causality == "parameter"]
    outs = [fn.call([t, h, values, state]) for fn, _ in traced]
    flat = ca.vertcat(*[o for os_ in outs for o in os_])
    expr, syms, parametric = ca.extract_parametric(flat, ca.vertcat(*[values[i] for i in params]))
    k = ca.vertcat(*syms) if len(syms) else ca.SX.sym("k", 0)
    constants = ca.Function(f"{itf.name}_constants", [values], [ca.vertcat(*parametric) if len(parametric) else
                                                                ca.SX(0, 1)], {"cse": True})
    functions, at = [], 0
    for (fn, f), os_ in zip(traced, outs):
        parts = []
        for o in os_:
            parts.append(ca.reshape(expr[at:at + o.numel()], o.size1(), o.size2()))
            at += o.numel()
        hoisted = ca.Function(fn.name(), [t, h, values, state, k], parts, {"cse": True})
        functions.append((hoisted, replace(f, n_w=hoisted.sz_w(), n_iw=hoisted.sz_iw())))
    return functions, constants, params


# ----------------------------------------------------------------------------- FMU assembly

def _build_description(sources: list[str]) -> bytes:
    files = "\n".join(f'      <SourceFile name="{s}"/>' for s in sources)
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<fmiBuildDescription fmiVersion="3.0">\n'
            f'  <BuildConfiguration modelIdentifier="{{id}}">\n    <SourceFileSet language="C99">\n{files}\n'
            f'    </SourceFileSet>\n  </BuildConfiguration>\n</fmiBuildDescription>\n').encode()


def _compile(cc: str, src: Path, sources: list[str], target: Path, name: str) -> None:
    target.parent.mkdir(parents=True, exist_ok=True)
    cmd = [cc, *CFLAGS, "-Wno-unused-parameter", "-I", str(src), *(str(src / s) for s in sources),
           "-o", str(target), "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        text = (proc.stderr or proc.stdout).strip().splitlines()
        raise NativeError(f"compiling native FMU {name} failed ({cc}): " + " | ".join(text[:6]))


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
    fmu.native_model()  # raises when the FMU has none
    cc = compiler()
    out = cache_folder(user_cache() / "native" / f"fmi{fmi}")
    digest = fingerprint()
    target, stamp = cached(out, name, digest)
    if force or not is_current(target, stamp, digest):
        announce(f"building FMU {name} (native, FMI {fmi}) into {out}")
        _build(fmu, fmi, cc, out, digest)
        prune(out, name)
    return deliver(target, None if out_dir is None else Path(out_dir) / "native" / f"fmi{fmi}", name)


def _build(fmu: FmuDefinition, fmi: int, cc: str, out: Path, digest: str) -> Path:
    """Generate, compile, load once and cache the native FMU as :func:`fmus.builder.cached` names it."""
    name = fmu.name
    own = hashlib.sha256((digest + name).encode()).hexdigest()
    token = "{" + f"{own[:8]}-{own[8:12]}-{own[12:16]}-{own[16:20]}-{own[20:32]}" + "}"
    with scratch(name, "native") as tmp:
        root = tmp / "fmu"
        src = root / "sources"
        src.mkdir(parents=True)
        itf, generated = generate(fmu, src, token)
        for f in ("model.h", "runtime.h", *_GLUE[fmi]):
            shutil.copy2(_HERE / "c" / f, src / f)
        for f in _HEADERS[fmi]:
            shutil.copy2(_fmi_headers() / f, src / f)
        sources = [*generated, *_GLUE[fmi]]
        (root / "modelDescription.xml").write_bytes(model_description(itf, fmi, token, sources))
        if fmi == 3:
            (src / "buildDescription.xml").write_bytes(_build_description(sources).replace(b"{id}", name.encode()))
        binary = root / "binaries" / ("linux64" if fmi == 2 else "x86_64-linux") / f"{name}.so"
        _compile(cc, src, sources, binary, name)
        _loads(binary, name, cc)

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
