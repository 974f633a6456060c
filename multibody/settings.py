"""A plant's integrator settings (:class:`SolverSettings`, checked when made), their per-model defaults and the
Exudyn ``SimulationSettings`` they make (:func:`simulation_settings`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from delta.errors import ParameterError

__all__ = ["SolverSettings", "REUSE_MAX_MODIFIED_ITERATIONS", "simulation_settings"]


REUSE_MAX_MODIFIED_ITERATIONS = 3
"""With ``SolverSettings.reuse_jacobian``: modified Newton iterations on a kept matrix before it is
refactorised (Exudyn's ``maxModifiedNewtonIterations``, default 8). A kept matrix contracts Newton's error by
~1e-4 a step after it was factorised and by ~1e-3 some steps later (the constraint Jacobians turn with the rods),
so converging to the default 1e-10 takes it 3, then 4 iterations; a fresh one takes 2. With 3 the matrix is
refactorised as soon as it needs a 4th. Measured with the rods' end-point model (``benchmarks/plant_step.py``
conditions, full linear plant): 3.8 iterations and 0.02 factorisations per step with 3, 4.3 and 0.007 with 4,
4.7 with 5, and 3 the fastest (74 against 77 us); while the platform moves (a 2 Hz effort wobble,
tests/integration/test_multibody_plants.py) 3, 4 and 5 take the same time (0.24 / 0.09 / 0.04 factorisations
per step)."""


@dataclass(frozen=True)
class SolverSettings:
    """Integrator settings of a plant.

    Attributes
    ----------
    spectral_radius : float
        Generalized-alpha spectral radius at infinity (0.8: stable at h = 1 ms for
        every delta tried; use ~0.5 with small steps for force comparisons).
    newton_rel_tol : float
        Relative Newton tolerance (Exudyn's, against the step's initial residual). 1e-10 converges every step:
        on pick_place_ctc (full linear plant, closed loop, 2 s) the platform closes on its joints
        (``|p - fk(q)|``) within 1.0e-11 m at every 1 ms sample with the kept Newton matrix, 8.8e-12 m with a
        fresh one, and the two runs end within 1.2e-11 m of each other. At 1e-6 a fresh matrix stops after one
        iteration, up to 7.3e-7 m off that closure at the cycle's jerk steps; a kept matrix up to 6.1e-9 m.
        (Measured with the rods as rigid bodies; with their end-point masses the closure holds to 1.7e-15 m at
        every 1 ms sample of pick_place_ctc, 4.5e-16 m on the helices: tests/integration/test_golden.py.)
    newton_abs_tol : float
        Absolute Newton tolerance (Exudyn's default scale for these small systems).
    modified_newton : bool
        Reuse the Jacobian across Newton iterations and steps where possible.
    substeps : int
        Integrator steps per macro step ``h`` of :meth:`multibody.plant.DeltaPlant.step` (1 = one step of size h).
    max_step : float or None
        Longest integrator step, s: a longer macro step is split into the fewest equal steps no
        longer than this (None: no limit, ``substeps`` steps whatever ``h``).
    min_step : float
        Resolution of the plant, s: a macro step that would leave less than this to integrate is
        absorbed (see :meth:`multibody.plant.DeltaPlant.step`). Generalized-alpha's Newton iteration fails below
        ~1e-12 s on the full linear delta (its matrix scales with 1/h^2); 1e-9 s converged on every
        model, and is the master's time resolution (integer nanoseconds).
    sparse : bool or None
        Use the EigenSparse linear solver (with its analysed sparsity pattern reused from step
        to step: the pattern never changes); False = Eigen's dense LU; None (default) = the
        faster per model as measured by ``benchmarks/plant_step.py`` (sparse for the full models,
        dense for the small lumped ones).
    reuse_jacobian : bool or None
        Keep the factorised Newton matrix from one macro step to the next (Exudyn refactorises it on
        every ``SolveSteps`` entry otherwise). Newton still iterates to the same tolerances, and the
        matrix is refactorised when modified Newton has not converged within
        ``REUSE_MAX_MODIFIED_ITERATIONS`` iterations, when the step size changes and after a reset.
        Its steps take ~4 modified Newton iterations where a fresh matrix takes two; at the default
        tolerance both converge to the same step (see ``newton_rel_tol``). None (default) = per model
        (:meth:`reuse_for`): on for the full plants, off for the lumped plants (their factorisation is
        cheap: the kept matrix costs more than it saves).
    """

    spectral_radius: float = 0.8
    newton_rel_tol: float = 1e-10
    newton_abs_tol: float = 1e-10
    modified_newton: bool = True
    substeps: int = 1
    sparse: bool | None = None
    max_step: float | None = None
    min_step: float = 1e-9
    reuse_jacobian: bool | None = None

    def __post_init__(self) -> None:
        if not 0.0 <= self.spectral_radius <= 1.0:
            raise ParameterError(f"SolverSettings.spectral_radius must be in [0, 1], got {self.spectral_radius!r}")
        if self.substeps < 1:
            raise ParameterError(f"SolverSettings.substeps must be >= 1, got {self.substeps!r}")
        if self.max_step is not None and not 0.0 < self.max_step < math.inf:
            raise ParameterError(f"SolverSettings.max_step must be a finite time > 0 s or None, got {self.max_step!r}")
        if not 0.0 <= self.min_step < math.inf:
            raise ParameterError(f"SolverSettings.min_step must be a finite time >= 0 s, got {self.min_step!r}")

    def sparse_for(self, fidelity: str) -> bool:
        """Whether a plant of ``fidelity`` uses the sparse linear solver: ``sparse``, or when None the faster one
        per model, measured with ``benchmarks/plant_step.py``: sparse LU (pattern analysed once) for the full models
        (51 unknowns linear, 87 rotary; with the rods as rigid bodies, 95 each, dense LU took 1.15x as long, and at
        53 the two took the same time), Eigen's dense LU for the lumped ones (9 unknowns each). Exudyn's own
        EXUdense inverts the matrix and is slower than both from ~50 unknowns on."""
        return fidelity == "full" if self.sparse is None else self.sparse

    def reuse_for(self, fidelity: str) -> bool:
        """Whether a plant of ``fidelity`` keeps its Newton matrix across steps: ``reuse_jacobian``, or when None
        per model: the full plants keep theirs (a fresh one costs a Jacobian and a sparse LU, ~50 us of the linear
        plant's step against ~25 us for the two iterations it saves); the lumped plants (9 unknowns) do not: their
        factorisation is cheap."""
        return fidelity == "full" if self.reuse_jacobian is None else self.reuse_jacobian


def simulation_settings(settings: SolverSettings, fidelity: str, t0: float, h: float):
    """Exudyn's ``SimulationSettings`` of a plant of ``fidelity`` with ``settings``, starting at ``t0`` with steps
    of ``h`` s (the plant sets each step's size and end itself): fixed-step generalized-alpha, Newton as
    ``settings`` say, the linear solver of :meth:`SolverSettings.sparse_for`, no solution file, no sensors,
    nothing shown."""
    import exudyn as exu

    s = settings
    sim = exu.SimulationSettings()
    ti = sim.timeIntegration
    ti.startTime = t0
    ti.endTime = t0 + h
    ti.numberOfSteps = s.substeps
    ti.verboseMode = 0
    ti.automaticStepSize = False
    ti.generalizedAlpha.spectralRadius = s.spectral_radius
    ti.generalizedAlpha.computeInitialAccelerations = True
    ti.newton.useModifiedNewton = s.modified_newton
    ti.newton.relativeTolerance = s.newton_rel_tol
    ti.newton.absoluteTolerance = s.newton_abs_tol
    if s.reuse_for(fidelity):
        ti.newton.maxModifiedNewtonIterations = REUSE_MAX_MODIFIED_ITERATIONS
    sim.solution.file.write = False
    sim.solution.sensors.active = False
    sim.solution.sensors.writePeriod = 1e30
    sim.show.computationTime = False
    sim.show.statistics = False
    if s.sparse_for(fidelity):
        sim.linearSolver.solverType = exu.LinearSolverType.EigenSparse
        sim.linearSolver.reuseAnalyzedPattern = True  # the sparsity pattern is fixed: analyse it once
    else:
        sim.linearSolver.solverType = exu.LinearSolverType.EigenDense
    return sim
