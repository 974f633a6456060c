"""The native build of our FMUs: each FMU's behaviour traced on CasADi symbols and generated as C.

:mod:`~fmus.native.models` (what each native FMU computes: the :mod:`delta` formulas called on symbols),
:mod:`~fmus.native.symbolic` (the symbolic number namespace), :mod:`~fmus.native.interface` (the variables, read
from the python adapter, and ``modelDescription.xml``), :mod:`~fmus.native.build` (trace, generate, compile,
zip), ``c/`` (the FMI 2 / 3 glue, written once for every model), :mod:`~fmus.native.errors`.
Which FMU has which native model is its definition's (:mod:`fmus.definition`, :data:`fmus.registry.REGISTRY`).
"""
