"""Variable-name helpers and unit definitions shared by the FMI 2 and FMI 3 layers (no exporter imports)."""

from __future__ import annotations

import ctypes
import sys

__all__ = ["XYZ", "UNITS", "joint_names", "axis_names", "compensate_exporter_refcount", "ValueAccess", "writer",
           "initial_knowns"]

XYZ = ("x", "y", "z")

# SI base-unit exponents of every unit used in the FMUs (FMI 2.0 UnitDefinitions).
UNITS: dict[str, dict[str, int]] = {
    "1": {},
    "s": {"s": 1},
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "rad": {"rad": 1},
    "rad/s": {"rad": 1, "s": -1},
    "rad/s2": {"rad": 1, "s": -2},
    "kg": {"kg": 1},
    "kg.m2": {"kg": 1, "m": 2},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "N/m": {"kg": 1, "s": -2},
    "N.s/m": {"kg": 1, "s": -1},
    "N.m/rad": {"kg": 1, "m": 2, "s": -2, "rad": -1},
    "N.m.s/rad": {"kg": 1, "m": 2, "s": -1, "rad": -1},
    "N.m/(rad.s)": {"kg": 1, "m": 2, "s": -3, "rad": -1},
    "N/(m.s)": {"kg": 1, "s": -3},
    "1/s": {"s": -1},
    "1/s2": {"s": -2},
    "1/s3": {"s": -3},
}


def initial_knowns(depends, inputs, parameters) -> set:
    """What an InitialUnknown depends on (FMI 2.0 2.2.8, FMI 3.0 2.4.8), from the knowns ``depends`` it
    depends on in a step (inputs, and states for model exchange): in initialization mode the knowns are
    the inputs and the variables with initial="exact", here the ``parameters``, which also fix the
    initial states. So: the inputs among ``depends`` plus every parameter (parameters are not tracked
    per unknown, an over-approximation the standard allows). The one rule of every build (python FMI 2
    and 3, native): an InitialUnknown written without ``dependencies`` depends on every known, every
    input included, and an importer that sorts initialization by these (OMSimulator) then sees an
    algebraic loop through each feedback connection (plant q -> controller u -> plant u)."""
    return {d for d in depends if d in inputs} | set(parameters)


def joint_names(prefix: str) -> list[str]:
    """``prefix[1] prefix[2] prefix[3]`` (conventions.md: 1-based joint indices)."""
    return [f"{prefix}[{i}]" for i in (1, 2, 3)]


def axis_names(prefix: str) -> list[str]:
    """``prefix.x prefix.y prefix.z``."""
    return [f"{prefix}.{a}" for a in XYZ]


def writer(*groups):
    """A function ``write(values, seq_1, ..., seq_n)`` storing ``seq_i[j]`` under ``groups[i][j]``.

    The per-step stores of the adapters (fmi2SetReal, refreshed outputs) as one compiled
    unpacking assignment per group: about half the time of ``values.update(zip(...))``,
    and a sequence of the wrong length raises ``ValueError``. The names are written into
    the generated source with ``repr``, so any string is safe.
    """
    groups = [tuple(g) for g in groups]
    if not groups or not all(groups) or not all(isinstance(n, str) for g in groups for n in g):
        raise ValueError(f"writer needs non-empty groups of variable names, got {groups!r}")
    args = [f"s{i}" for i in range(len(groups))]
    lines = [f"    {', '.join(f'values[{n!r}]' for n in g)}, = {a}" for g, a in zip(groups, args)]
    namespace: dict = {}
    exec(f"def write(values, {', '.join(args)}):\n" + "\n".join(lines) + "\n", namespace)  # noqa: S102
    return namespace["write"]


def compensate_exporter_refcount(slave_class: type) -> None:
    """Give back the reference pythonfmu's loader takes from the slave module's globals.

    pythonfmu 0.7 (and pythonfmu3) look the slave class up with a C++ ``findClass``
    that calls ``Py_DECREF`` on the module's ``__dict__``, a *borrowed* reference,
    once per instantiation, before the instance exists. Our generated slave modules
    hold no functions (whose ``__globals__`` would keep extra references), so the
    dict would be freed during the first lookup and its memory reused: a second
    instance in the same process then fails with "module has no attribute" or the
    interpreter crashes during garbage collection. The generated module keeps one
    spare reference to its globals (``fmus.builder``) and every instance gives back
    the one the lookup took; a leaked reference when an adapter is created outside
    the C++ loader (builder, direct use) is harmless.
    """
    module = sys.modules.get(slave_class.__module__)
    if module is not None:
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(vars(module)))


class ValueAccess:
    """Vector access to an adapter's ``values`` dict, shared by the FMI 2 and FMI 3 bases."""

    values: dict

    def vec(self, names):
        """Values of ``names`` as a float array."""
        import numpy as np

        return np.array([self.values[n] for n in names], dtype=float)

    def vec3(self, names) -> tuple[float, float, float]:
        """Values of three ``names`` as a tuple of floats (the per-step path; :meth:`vec` gives arrays)."""
        a, b, c = names
        v = self.values
        return v[a], v[b], v[c]

    def put(self, names, values) -> None:
        """Store ``values`` (floats, a tuple or an array) under ``names``; an array goes through one
        ``tolist`` instead of a ``float()`` per numpy scalar."""
        if hasattr(values, "tolist"):
            values = values.tolist()
        self.values.update(zip(names, map(float, values)))
