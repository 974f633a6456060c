"""Generate the C of a native FMU: trace its model's functions on CasADi symbols and write them as C.

Steps 2 and 3 of :mod:`fmus.native.build`: each model function (start, refresh, advance, derivatives, accept)
of the definition's native model is traced on ``SX`` symbols, what depends on parameters only is hoisted into a
constants function, CasADi's code generator writes them as ``model_functions.c``, and ``model.c`` binds them to the
contract of ``c/model.h``. Imported by a build only: a run of cached FMUs loads neither this module nor CasADi.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..traced import CALLS, Call, TracedModel, first_values
from .errors import NativeError
from .interface import Interface, interface
from .models import NativeModel, Result, Symbols
from .symbolic import tracing

MAX_DETAIL = 4  # values a check may print into its reason (MODEL_MAX_DETAIL of c/model.h)


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


def _model_c(model: NativeModel, itf: Interface, token: str, functions: list[_Function], constants: Any) -> str:
    """``model.c``: the model's tables (:func:`_tables_c`), its constants (:func:`_constants_c`) and one C function
    per traced function (:func:`_function_c`), which the FMI glue in ``native/c`` calls."""
    checks: list[tuple[str, bool, int]] = []
    for f in functions:
        checks += f.checks
    lines = _tables_c(model, itf, token, checks, constants) + _constants_c(itf, constants)
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


def _tables_c(model: NativeModel, itf: Interface, token: str, checks: list[tuple[str, bool, int]],
              constants: Any) -> list[str]:
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
        f"const int MODEL_ME_OUTPUTS = {1 if model.me_outputs else 0};",
        f"const double MODEL_DEFAULT_EXPERIMENT[3] = {{{', '.join(repr(float(x)) for x in itf.experiment)}}};",
        f"const size_t MODEL_N_SCRATCH = {1 + constants.nnz_out(0)};",
    ]


def _constants_c(itf: Interface, constants: Any) -> list[str]:
    """``constants(values)``: what depends on parameters only, kept after the variables (``MODEL_N_SCRATCH``) and
    computed again when their flag says a parameter may have changed (the runtime clears it: ``rt_constants_stale``).
    Comparing every parameter at every call instead cost about a fifth of a model-exchange derivative evaluation."""
    return [
        "",
        "/* The constants (what depends on parameters only), kept after the variables (MODEL_N_SCRATCH): a flag, then",
        "   the constants; computed again when the runtime cleared the flag (a parameter may have changed). */",
        "static const double *constants(double *values) {",
        "    double *scratch = values + MODEL_N_VARIABLES + 1, *k = scratch + 1;",
        "    const casadi_real *arg[1];",
        "    casadi_real *res[1];",
        f"    casadi_int iw[{max(constants.sz_iw(), 1)}];",
        f"    casadi_real w[{max(constants.sz_w(), 1)}];",
        "    if (scratch[0] != 0.0) return k;",
        "    arg[0] = values; res[0] = k;",
        f"    if ({itf.name}_constants(arg, res, iw, w, 0)) return k;",
        "    scratch[0] = 1.0;",
        "    return k;",
        "}",
    ]


def _function_c(model: NativeModel, itf: Interface, f: _Function, offset: int) -> list[str]:
    """``model_<name>``: one traced function called with the values, the state and the constants; its checks are
    the model's from ``offset`` on."""
    fn = f"{itf.name}_{f.name}"
    n_sets, n_checks = len(f.sets), len(f.checks)
    firsts = first_values(f.checks)  # where each check's values start in the function's details
    n_details = sum(n for _, _, n in f.checks)
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


def _traced(fmu: Any) -> tuple[NativeModel, Interface, list, Any]:
    """``fmu`` (an :class:`fmus.definition.FmuDefinition`, which imports this module when first asked for its traced
    model): its native model, its interface, its traced functions with their parameter-only part hoisted, and the
    constants function: what both builds evaluate (the native one as C, the python one in CasADi's machine)."""
    model = fmu.native_model()
    if model.me_outputs and not model.me_accepts:
        raise NativeError(f"FMU {fmu.name}: me_outputs needs me_accepts (accept computes the outputs)")
    itf = interface(fmu.name, model)
    functions, constants = _hoisted(itf, [_trace(model, itf, which) for which in CALLS])
    return model, itf, functions, constants


def traced_model(fmu: Any) -> TracedModel:
    """The python build's step of ``fmu`` (:mod:`fmus.traced`): the functions :func:`generate` writes as C."""
    model, itf, functions, constants = _traced(fmu)
    vr = {v.name: v.vr for v in itf.variables}
    return TracedModel(fmu.name, tuple((v.name, v.type, float(v.start or 0.0), v.choices) for v in itf.variables),
                       model.n_state, tuple(float(x) for x in model.initial_state()),
                       vr[model.max_step] if model.max_step else 0, model.me_advances, model.me_accepts,
                       model.me_outputs, constants,
                       {f.name: Call(fn, tuple(f.sets), tuple(f.checks), f.sets_state) for fn, f in functions})


def generate(fmu: Any, out: Path, token: str) -> tuple[Interface, list[str]]:
    """Write the generated C of the FMU (``model.c``, ``model_functions.c/.h``) into ``out``; return the interface
    and the generated file names."""
    import casadi as ca

    model, itf, functions, constants = _traced(fmu)
    gen = ca.CodeGenerator("model_functions.c", {"with_header": True, "casadi_real": "double",
                                                 "casadi_int": "long long int"})
    for fn in (constants, *(fn for fn, _ in functions)):
        gen.add(fn)
    gen.generate(str(out) + os.sep)
    (out / "model.c").write_text(_model_c(model, itf, token, [f for _, f in functions], constants))
    return itf, ["model_functions.c", "model.c"]


def _hoisted(itf: Interface, traced: list) -> tuple[list, Any]:
    """The traced functions with what depends on parameters only taken out of them (``casadi.extract_parametric``
    over all of them at once): ``(functions taking the constants as a fifth input, the constants function of the
    values)``. The generated glue computes the constants when a parameter may have changed (:func:`_constants_c`), not at every call: the leg angles' cosines, the mass lumps, the geometry's squares.
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
    return functions, constants
