"""Variable names and connections: ``name`` or ``base[i,j]`` resolved to a variable (or one element of an FMI 3.0
array), and connections by prefix: ``{from: traj.p_ref, to: ik.p_ref}`` wires every element with a matching suffix.

A connection end that names a variable (a scalar, a whole FMI 3.0 array or one element of it)
is used as is. Otherwise it is a prefix: the variables named ``prefix.SUFFIX`` or
``prefix[SUFFIX]`` of the wanted causality (``p_ref.x/.y/.z``, ``q_ref[1]..[3]``). Both ends
must then have the same suffixes; the pairs are made suffix by suffix, in the source's order,
and each pair is checked (kind, size, unit) as a connection written element by element.
Two bare component names (``{from: traj, to: ik}``) wire every output of the first to the
input of the same name of the second (at least one).
"""

from __future__ import annotations

import re

from ..fmi import FMUInfo, Variable
from .names import ref, split_ref

__all__ = ["expand_connection", "find_variable", "index_text"]


_ELEMENT = re.compile(r"^(?P<base>.+)\[(?P<idx>\d+(?:\s*,\s*\d+)*)\]$")


def index_text(var: Variable, element: int | None) -> str:
    if element is None:
        return ""
    idx, rest = [], element
    for n in reversed(var.shape):
        idx.append(rest % n + 1)
        rest //= n
    return "[" + ",".join(str(i) for i in reversed(idx)) + "]"


def find_variable(info: FMUInfo, name: str) -> tuple[Variable | None, int | None, str]:
    """``name`` in ``info``: a variable, or one element ``base[i]`` / ``base[i,j]`` of an FMI 3.0 array.

    Returns (variable, element or None, problem); the problem is empty when found.
    """
    var = info.variables.get(name)
    if var is not None:
        return var, None, ""
    m = _ELEMENT.match(name)
    if m is None:
        return None, None, ""
    base = info.variables.get(m.group("base"))
    if base is None or not base.is_array:
        return None, None, ""
    idx = [int(i) for i in m.group("idx").split(",")]
    if len(idx) != len(base.shape) or any(not 1 <= i <= n for i, n in zip(idx, base.shape)):
        return None, None, f"{name}: index out of range ({base.name} has shape {'x'.join(map(str, base.shape))}, " \
                           f"indices start at 1)"
    flat = 0
    for i, n in zip(idx, base.shape):
        flat = flat * n + (i - 1)
    return base, flat, ""


def _members(info: FMUInfo, prefix: str, causality: str) -> list[tuple[str, str]]:
    """(suffix, variable name) of ``prefix.*`` / ``prefix[*]`` variables with ``causality``, in declaration order."""
    out = []
    for v in info.variables.values():
        if v.causality != causality:
            continue
        if v.name.startswith(prefix + ".") or v.name.startswith(prefix + "["):
            out.append((v.name[len(prefix):], v.name))
    return out


def expand_connection(src: str, dst: str,
                      infos: dict[str, FMUInfo]) -> tuple[list[tuple[str | None, str | None]], str]:
    """The element connections of ``src -> dst`` (``comp.name`` each), and a problem ('' if none).

    Ends that resolve to variables give ``[(src, dst)]`` unchanged (the caller checks them). An end that is neither
    a variable nor a prefix is given back for the caller to report as unknown; the other end, when it is a prefix of
    the right causality, is None then (it is not what is wrong: a typo in ``to`` must not flag a good ``from``).
    """
    (sc, sname, _), (dc, dname, _) = split_ref(src), split_ref(dst)  # the scenario checked the quoting
    if sname is None and dname is None:  # component to component: every output with a same-named input
        if sc not in infos or dc not in infos:
            return [], ""  # an unknown component: reported by the scenario validation
        inputs = {v.name for v in infos[dc].variables.values() if v.causality == "input"}
        names = [v.name for v in infos[sc].variables.values() if v.causality == "output" and v.name in inputs]
        if not names:
            return [], f"{src} has no output named like an input of {dst}"
        return [(ref(sc, n), ref(dc, n)) for n in names], ""
    if sname is None or dname is None:
        return [], f"give both ends as components ({ref(sc, '')} -> {ref(dc, '')}) or both as variables"
    if sc not in infos or dc not in infos:
        return [(src, dst)], ""
    s_var = find_variable(infos[sc], sname)[0]
    d_var = find_variable(infos[dc], dname)[0]
    if s_var is not None or d_var is not None:
        return [(src, dst)], ""
    s_mem, d_mem = _members(infos[sc], sname, "output"), _members(infos[dc], dname, "input")
    if not s_mem or not d_mem:  # neither a variable nor a prefix: reported as an unknown variable
        return [(None if s_mem else src, None if d_mem else dst)], ""
    s_suf, d_suf = [s for s, _ in s_mem], [s for s, _ in d_mem]
    if sorted(s_suf) != sorted(d_suf):
        return [], (f"prefix connection: {src} has {len(s_suf)} output(s) ({' '.join(s_suf)}), {dst} has "
                    f"{len(d_suf)} input(s) ({' '.join(d_suf)}); they must match suffix by suffix")
    d_by = dict(d_mem)
    return [(ref(sc, name), ref(dc, d_by[suf])) for suf, name in s_mem], ""
