"""FMU access layer: the only package that calls fmpy.

One protocol, :class:`~cosim.fmi.slave.Slave`, over six wrappers: FMI 1.0, 2.0 and 3.0 (:mod:`.fmi1`,
:mod:`.fmi2`, :mod:`.fmi3`), co-simulation (:mod:`.slave`) and model exchange (:mod:`.model_exchange`, numerics in :mod:`.integrators`).
What an FMU declares is read once per file (:mod:`.description`); archives are checked and extracted once
per file and process (:mod:`.extract`); FMU log messages reach the user through :mod:`.logger`; PythonFMU's
libraries get the care of :mod:`.pythonfmu`. The hot path calls the C functions directly with pre-built
ctypes buffers, one call per turn where the C helper (:mod:`.turn`) can be built.

Every FMI 3.0 variable type is exchanged: Float32/64, Int8..UInt64, Boolean, String, Binary, Enumeration,
and arrays (buffers hold every element; ``Variable.shape`` gives the dimensions, fixed or from structural
parameters). Clocks are rejected when loading. Every FMI status passes through one check
(:meth:`~cosim.fmi.slave.Base._check`); a failure raises :class:`~cosim.errors.FMIError` naming the
component, the function, the simulation time and the FMU's last log message. An FMU that asks to end the
simulation raises :class:`~cosim.fmi.slave.Terminated`, which the algorithm turns into a normal end of the run.
"""

from __future__ import annotations

import math

from ..errors import ComponentSourceError, Issue
from .description import BINARY, BOOLEAN, INTEGER, PY_KINDS, REAL, STRING, FMUInfo, Variable, load_fmu
from .extract import Extractions, cleanup_extracted
from .fmi1 import FMI1CoSimulation, FMI1ModelExchange
from .fmi2 import FMI2CoSimulation, FMI2ModelExchange
from .fmi3 import FMI3CoSimulation, FMI3ModelExchange
from .slave import Slave, Terminated

__all__ = ["Variable", "FMUInfo", "load_fmu", "Slave", "make_slave", "Terminated", "cleanup_extracted", "Extractions",
           "REAL", "INTEGER", "BOOLEAN", "STRING", "BINARY", "PY_KINDS"]


def make_slave(name: str, info: FMUInfo, interface: str = "auto", rtol: float = 1e-6, solver: str = "cvode",
               max_step: float | None = None) -> Slave:
    """The wrapper for ``info``'s FMI version and the requested interface (auto: co-simulation first).

    ``rtol``, ``solver`` and ``max_step`` (s; None: unbounded but for the communication step) apply
    to model exchange.
    """
    available = info.interfaces
    if interface == "auto":
        interface = "cs" if "cs" in available else "me"
    if interface not in available:
        # Refused (correctness): an interface the FMU does not have cannot run
        raise ComponentSourceError(Issue(f"components.{name}.interface",
                                         f"{info.path.name} has no {interface} interface (it has: "
                                         f"{', '.join(available) or 'none'})"))
    cls = {(1, "cs"): FMI1CoSimulation, (1, "me"): FMI1ModelExchange,
           (2, "cs"): FMI2CoSimulation, (2, "me"): FMI2ModelExchange,
           (3, "cs"): FMI3CoSimulation, (3, "me"): FMI3ModelExchange}.get((info.fmi_major, interface))
    if cls is None:
        # Refused (correctness): an FMI version we cannot call: its functions differ
        raise ComponentSourceError(Issue(f"components.{name}", f"FMI {info.md.fmiVersion} is not supported "
                                                               "(FMI 1.0, 2.0 and 3.0 are)"))
    slave = cls(name, info)
    if slave.model_exchange:
        slave.rtol = rtol
        slave.solver = solver
        slave.max_step = math.inf if max_step is None else max_step
    return slave
