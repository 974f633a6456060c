"""The third number namespace: the ``delta/`` formulas evaluated on CasADi symbols.

:data:`SYMBOLIC` has the functions of :data:`delta.actuators.SCALAR` and :data:`~delta.actuators.ARRAY`
on CasADi ``SX`` expressions. A per-pose algorithm run with a model compiled on symbols
(:func:`symbolic_model`) builds the expression graph of its result instead of a number; CasADi then
writes that graph as self-contained C (:mod:`fmus.native.build`). Nothing is written twice: the C is
the Python formula, traced.

Branches on computed values cannot be traced: ``bool`` of a symbol raises (CasADi: "Cannot compute the
truth value"), so an ``if`` that goes around the namespace fails the build instead of generating wrong
C. The algorithms branch through the namespace instead (see :data:`delta.actuators.SCALAR`): ``where``
becomes ``if_else`` and ``check`` records its condition and reason in the active :class:`Trace` and
lets the trace follow the valid path; the generated function returns the recorded conditions, and the
C glue turns a failed one into an FMI status with its reason logged. A ``math`` function called on a
symbol returns NaN silently, which the float-path comparison of ``tests/unit/test_native_trace.py``
catches.
"""

from __future__ import annotations

from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any, Callable, Iterator

import casadi as ca

from delta.actuators import kind_of
from delta.numbers import namespace
from delta.masses import validate as validate_masses
from delta.model import Model, compile_model
from delta.robots import validate as validate_robot

from ..adapters.common import GEOMETRY_PARAMETERS, MASS_PARAMETERS

__all__ = ["SYMBOLIC", "Trace", "tracing", "symbolic_model", "instance"]


@dataclass
class Trace:
    """The conditions ``check`` recorded while tracing: (condition, reason), 1 where it holds."""

    checks: list[tuple[Any, str]] = field(default_factory=list)
    parameters: list[tuple[Any, str]] = field(default_factory=list)  # conditions on parameters alone (errors)

    def set_aside(self, before: list[tuple[Any, str]]) -> None:
        """Move what was recorded since ``before`` (the checks taken just before) to :attr:`parameters`."""
        self.parameters += self.checks
        self.checks = before

    def take(self) -> list[tuple[Any, str]]:
        """The conditions recorded so far, and forget them (a model keeps each group apart)."""
        taken, self.checks = self.checks, []
        return taken


_ACTIVE: ContextVar[Trace | None] = ContextVar("delta_native_trace", default=None)


@contextmanager
def tracing() -> Iterator[Trace]:
    """Record the ``check`` conditions of the formulas traced inside the block."""
    trace = Trace()
    token = _ACTIVE.set(trace)
    try:
        yield trace
    finally:
        _ACTIVE.reset(token)


def _check(ok: Any, reason: str | Callable[[], str]) -> bool:
    trace = _ACTIVE.get()
    if trace is None:
        raise RuntimeError("a formula checked a symbolic condition outside fmus.native.symbolic.tracing()")
    if ok is True:
        return True
    trace.checks.append((ca.SX(ok), reason() if callable(reason) else reason))
    return True


def _isfinite(x: Any) -> Any:
    return ca.logic_and(x == x, ca.fabs(x) < ca.inf)


SYMBOLIC = namespace("delta.symbolic_math", cos=ca.cos, sin=ca.sin, sqrt=ca.sqrt, atan2=ca.atan2, acos=ca.acos,
                      maximum=ca.fmax, minimum=ca.fmin, both=ca.logic_and, where=ca.if_else, check=_check,
                      isfinite=_isfinite, symbolic=True)
"""CasADi's functions on ``SX`` for the formulas of :mod:`delta` (see the module docstring)."""


def symbolic_model(kind: str, geometry: dict[str, Any], masses: dict[str, Any] | None = None) -> Model:
    """A :class:`~delta.model.Model` of robot ``kind`` whose geometry (``rail_radius``, ``leg_angles``, ``q_min``,
    ...: the robot dataclass's field names) and masses (the mass dataclass's field names; defaults to the
    kind's defaults as numbers) are symbols, compiled by :func:`delta.model.compile_model` itself."""
    actuator_cls = kind_of(kind)
    robot = SimpleNamespace(kind=kind, name=f"{kind} delta (symbolic)", **geometry)
    validate_robot(robot, SYMBOLIC, names=GEOMETRY_PARAMETERS)  # the robot's and masses' checks, recorded under the
    # FMU's parameter names (as the python build's, fmus.adapters.common.check_parameters)
    if masses is None:
        defaults = actuator_cls.masses_type()
        masses = {f: getattr(defaults, f) for f in defaults.__dataclass_fields__}
    else:
        validate_masses(SimpleNamespace(**masses), SYMBOLIC, names=MASS_PARAMETERS)
    return compile_model(robot, SimpleNamespace(**masses), actuator_cls(robot), SYMBOLIC)


def instance(cls: type, **fields: Any) -> Any:
    """An instance of the (frozen) dataclass ``cls`` holding symbols, without its numeric validation."""
    obj = object.__new__(cls)
    for name, value in fields.items():
        object.__setattr__(obj, name, value)
    return obj
