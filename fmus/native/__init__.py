"""The native build of our FMUs: each FMU's behaviour traced on CasADi symbols and generated as C.

:mod:`~fmus.native.models` (what each native FMU computes: the :mod:`delta` formulas called on symbols),
:mod:`~fmus.native.symbolic` (the symbolic number namespace), :mod:`~fmus.native.interface` (the variables, read
from the python adapter, and ``modelDescription.xml``), :mod:`~fmus.native.generate` (trace the model
functions, generate their C), :mod:`~fmus.native.build` (the cache, compile, zip: a cached build loads neither the
models nor CasADi), :mod:`~fmus.native.parts` (the compiled parts a library is linked from, shared between FMI
versions and FMUs), ``c/`` (the FMI 2 / 3 glue, written once for every model), :mod:`~fmus.native.errors`.
Which FMU has which native model is its definition's (:mod:`fmus.definition`, :data:`fmus.registry.REGISTRY`).
"""
