"""One definition per FMU of ours: what it is, and the code of both its builds, by reference.

A :class:`FmuDefinition` names the FMU and holds, as objects (no class-name strings, nothing looked up by
``importlib``), behind two functions of the registry that import their modules when first asked (``adapter_class``,
``native_class``: a run of cached FMUs reads what an FMU is without loading pythonfmu3, and the pre-flight that
reads a controller's declared gains does not load CasADi and the native models, about 0.03 s):

* ``adapter``: the adapter class (:mod:`fmus.adapters`). Its ``__init__`` declares the FMU's interface once
  (variables, units, start values, causality, variability and tunability, ModelStructure dependencies, default
  experiment), for both builds;
* ``native``: the native model class (:mod:`fmus.native.models`, None for the Exudyn plants): what each FMI call
  computes, as functions of the :mod:`delta` formulas, over the interface the adapter declares. Traced on CasADi
  symbols (:meth:`FmuDefinition.traced_model`), it is the step of both builds: written as C by the native build,
  run in CasADi's machine by the python build (:mod:`fmus.traced`). An FMU without one (the Exudyn plants) has its
  step in its adapter (``start`` / ``advance`` / ``refresh``).

The python FMU's class is made from the definition (:meth:`FmuDefinition.python_class`: the adapter with the
robot kind and the traced model; the builder writes the same class into the FMU's generated module), and so is its
native model (:meth:`FmuDefinition.native_model`). The table of our definitions is :data:`fmus.registry.REGISTRY`.

This module imports nothing of :mod:`fmus` but the adapters' ``declared``, the native build's errors and (when a
traced model is first asked for) its generator: the builders take a definition without knowing the registry.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Callable

from .adapters.common import declared
from .native.errors import NativeError

__all__ = ["FmuDefinition"]


@dataclass(frozen=True)
class FmuDefinition:
    """One FMU of ours.

    ``adapter_class()`` and ``native_class()`` return the classes themselves, each importing its module on the
    first call: :attr:`adapter` (the python build, and the interface of both builds) and :attr:`native` (the native
    model class; None where ``native_class`` is None: ``has_native`` says which without importing anything); ``kind`` is the robot kind given to both
    (None for robot-independent components); ``packages`` are the project packages bundled (under a unique name)
    with the python build;
    ``fmi`` is the python build's FMI version: 2 (co-simulation, pythonfmu) or 3 (model exchange, pythonfmu3);
    ``requires`` are further modules that must be importable for the adapter to run (those it imports lazily,
    such as ``multibody.plant``).

    What the FMU is, for the tools that look at scenarios and logs (compare, report, table) instead of
    matching names: ``role`` (one of :data:`fmus.registry.ROLES`), ``variant`` within the role (the control law,
    the plant's model, the trajectory type) and ``label`` (how a table prints it: ``PD+``, ``CTC``).
    """

    name: str
    adapter_class: Callable[[], type] = field(repr=False, compare=False)
    native_class: Callable[[], type] | None = field(repr=False, compare=False)
    kind: str | None
    packages: tuple[str, ...] = ("delta",)
    fmi: int = 2
    requires: tuple[str, ...] = ()
    summary: str = ""
    role: str = ""
    variant: str = ""
    label: str = ""

    @cached_property
    def adapter(self) -> type:
        """The python adapter class (its module imported on first use)."""
        return self.adapter_class()

    @cached_property
    def native(self) -> type | None:
        """The native model class, None where there is no native build (its module imported on first use)."""
        return None if self.native_class is None else self.native_class()

    @property
    def has_native(self) -> bool:
        """Whether the FMU has a native build (nothing imported to say so)."""
        return self.native_class is not None

    def python_class(self) -> type:
        """The FMU's own class: its adapter with the robot kind (the class the FMU's generated module declares) and,
        where the FMU has a native model, its traced model (:meth:`traced_model`, traced when first started)."""
        extra = {"TRACED": staticmethod(self.traced_model)} if self.has_native else {}
        return type(self.name, (self.adapter,), {"KIND": self.kind, **extra})

    def traced_model(self) -> Any:
        """The traced functions of the native model (:class:`fmus.traced.TracedModel`): the python build's step,
        the native build's C. Traced once per definition (CasADi, 1 to 60 ms)."""
        return self._traced

    @cached_property
    def _traced(self) -> Any:
        from .native.generate import traced_model  # lazy: CasADi and the native models

        return traced_model(self)

    def declared(self) -> Any:
        """An instance of :meth:`python_class` made in Python (not by an FMU's binary): its declarations are the
        FMU's interface; nothing is computed until it is started."""
        return declared(self.adapter, self.kind, self.name)

    def native_model(self) -> Any:
        """The native model of this FMU (:mod:`fmus.native.models`); raises :class:`NativeError` when it has none
        (:func:`fmus.registry.build` names the FMUs that have one)."""
        if not self.has_native:
            raise NativeError(f"FMU {self.name!r} has no native build")
        return self.native(self.kind, self.adapter)
