"""Our FMUs by name: the ``fmu: NAME`` components of a scenario, built by :mod:`fmus.registry` (python or native)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from delta.errors import DeltaError
from fmus import registry
from fmus.builder import on_build
from fmus.native.build import compiler
from fmus.native.errors import CompilerMissingError

from ..engine.structure import SystemStructure
from ..errors import ComponentSourceError, Issue

__all__ = ["RegistrySource"]


class RegistrySource:
    """:class:`cosim.engine.plugins.FmuSource` of our FMUs: a key is (FMU name, native, FMI version)."""

    def key(self, system: SystemStructure, name: str) -> tuple[str, bool, int]:
        """The native build where the system asks for it (``fmus: native``, or ``auto`` with a C compiler on this
        machine) and the FMU has one, else the python build (FMI 2 co-simulation, or 3 for ``*_me``)."""
        fmus = system.domain.get("fmus") or "auto"
        if fmus == "python" or name not in registry.native_names():
            return name, False, 2
        if fmus == "auto":
            try:
                compiler()
            except CompilerMissingError:
                return name, False, 2
        return name, True, system.domain.get("native_fmi") or 2

    def build(self, key: Any) -> Path:
        """Our FMU of ``key``, built (or taken from the cache). A native build that cannot be made (no C compiler)
        is one line naming what is missing."""
        name, native, fmi = key
        on_build(_tell)
        try:
            return Path(registry.build(name, native=native, fmi=fmi))
        except DeltaError as exc:  # a build error of ours: the master's error, one line
            raise ComponentSourceError(Issue("", str(exc))) from None


def _tell(message: str) -> None:
    """A build (not a cache hit) said on the terminal: the first run, or one after a change of sources, waits for
    it (a native pick_place trajectory takes seconds). Only to a terminal: logs and captured output stay as they
    were."""
    if sys.stderr is not None and sys.stderr.isatty():
        print(f"{message} ...", file=sys.stderr, flush=True)
