"""A plant's state saved and restored exactly (:class:`StateCheckpoint`, a base of
:class:`multibody.plant.DeltaPlant`): ``get_state`` / ``set_state`` save and restore everything a later step depends
on, as plain data, so stepping on from a restored state repeats the original bit for bit (the FMUs' state
checkpoints)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import PlantError

__all__ = ["StateCheckpoint"]


_ITERATION = ("adaptiveStep", "automaticStepSize", "automaticStepSizeError", "currentStepIndex", "currentStepSize",
              "currentTime", "discontinuousIteration", "discontinuousIterationsCount", "endTime", "initialStepSize",
              "lastStepSize", "maxStepSize", "minStepSize", "newtonJacobiCount", "newtonSteps", "newtonStepsCount",
              "numberOfSteps", "recommendedStepSize", "rejectedAutomaticStepSizeSteps", "rejectedModifiedNewtonSteps",
              "startTime")
"""The solver's iteration data (``solver.it``) a state holds: every field (time, step sizes, counters)."""


class StateCheckpoint:
    """:meth:`get_state` and :meth:`set_state` of a plant; they read and set the plant's Exudyn system and solver
    (``self._system_data``, ``self._solver``, ``self._sim``, ``self._sparse``, ``self.mbs``) and its own stepping state
    (``self._t``, ``self._u``, ``self._step_size``, ``self._refactorise``, ``self._h_nominal``), and call its
    ``set_payload``, ``_apply_effort``, ``_read_prescribed_reaction`` and ``_make_output``."""

    def get_state(self) -> dict[str, Any]:
        """Everything a later :meth:`step` depends on, as plain data (floats, ints, bools, lists; no numpy).

        Captured:

        - the plant's own: time ``t``, the last effort ``u``, the integrator step size in use, whether the Newton
          matrix is to be refactorised at the next step, the payload;
        - Exudyn's current state: the ODE2 coordinates, velocities and accelerations, the algebraic (AE)
          coordinates (Lagrange multipliers), the data coordinates (none in these systems) and the system time;
        - the generalized-alpha solver's algorithmic accelerations (``GetAAlgorithmic``) and iteration data
          (every field of ``solver.it``: time, end time, step sizes, counters);
        - the Newton matrix the solver holds factorised (kept across steps with ``reuse_jacobian``; otherwise the
          last one, whose sparsity pattern Eigen's LU keeps analysed): its non-zero entries (row-major flat
          ``index`` into the ``size`` x ``size`` matrix, and ``values``).

        Not captured, because they are the same in any plant built from the same robot, masses, fidelity and
        settings: the system's structure, the constant mass matrix, the solver settings. The systems have no ODE1
        coordinates.
        """
        sd, solver = self._system_data, self._solver
        jacobian = solver.GetSystemJacobian()
        index = np.flatnonzero(jacobian)
        return {
            "t": self._t, "u": self._u.tolist(), "step_size": self._step_size, "refactorise": self._refactorise[0],
            "payload": float(self.masses.payload), "time": sd.GetTime(),
            "q": sd.GetODE2Coordinates().tolist(), "v": sd.GetODE2Coordinates_t().tolist(),
            "a": sd.GetODE2Coordinates_tt().tolist(), "a_algorithmic": solver.GetAAlgorithmic().tolist(),
            "ae": sd.GetAECoordinates().tolist(), "data": sd.GetDataCoordinates().tolist(),
            "iteration": {name: getattr(solver.it, name) for name in _ITERATION},
            "jacobian": {"size": int(jacobian.shape[0]), "index": index.tolist(),
                         "values": jacobian.ravel()[index].tolist()},
        }

    def set_state(self, state: dict[str, Any]) -> None:
        """Continue from ``state`` (:meth:`get_state` of this plant or of another built from the same robot, masses
        (the payload aside), fidelity and settings), in place: the system is not rebuilt.

        A different payload is set first (:meth:`set_payload`). The solver then gets back what :meth:`get_state`
        lists; three parts have no setter in Exudyn's Python API and take a detour:

        - the Newton matrix: Exudyn factorises a matrix only inside ``Newton``, so one Newton iteration runs with a
          ``ComputeNewtonJacobian`` user function that only sets the saved matrix (removed again), on the state
          being restored (overwritten afterwards). An identity is factorised the same way just before: Eigen's
          sparse LU reuses its analysis of the sparsity pattern (its column ordering) while the number of
          non-zeros stays the same, so without it the factorisation would depend on what this plant factorised
          before; after it, the saved matrix's own pattern is analysed, as where it was first factorised (the
          dense LU of the lumped plants keeps no such analysis: no identity there);
        - the algorithmic accelerations: ``InitializeSolverInitialConditions`` without computing initial
          accelerations sets them to the accelerations of the system's initial configuration, so the state is
          written there (with them as accelerations; the initial configuration keeps it, nothing reads it after
          the solver's initialization), the call copies it into the current state, and the real accelerations are
          written back;
        - the iteration data that call resets is set again.

        Raises
        ------
        PlantError
            The state's sizes are not this system's (a plant of another robot kind or fidelity).
        """
        import exudyn as exu

        sd, solver, mbs = self._system_data, self._solver, self.mbs
        sizes = {"q": sd.ODE2Size(), "v": sd.ODE2Size(), "a": sd.ODE2Size(), "a_algorithmic": sd.ODE2Size(),
                 "ae": sd.AEsize(), "data": sd.DataSize()}
        wrong = {k: (len(state[k]), n) for k, n in sizes.items() if len(state[k]) != n}
        n_sys = sizes["q"] + sizes["ae"]
        if wrong or state["jacobian"]["size"] != n_sys:
            raise PlantError(f"{type(self).__name__}.set_state: the state's sizes (saved, this system's) differ: "
                             f"{wrong}, Newton matrix {state['jacobian']['size']} vs {n_sys}: a state of another "
                             "model")
        if state["payload"] != self.masses.payload:
            self.set_payload(state["payload"])
        it = solver.it
        self._set_iteration(state["iteration"])
        if not it.currentStepSize > 0.0:  # before the first step: the factorising iteration needs a step
            it.currentStepSize = self._h_nominal
        sd.SetODE2Coordinates(state["q"])
        sd.SetODE2Coordinates_t(state["v"])
        sd.SetODE2Coordinates_tt(state["a"])
        sd.SetAECoordinates(state["ae"])
        sd.SetDataCoordinates(state["data"])
        jacobian = np.zeros(n_sys * n_sys)
        jacobian[state["jacobian"]["index"]] = state["jacobian"]["values"]
        if self._sparse:
            self._factorise(np.eye(n_sys))
        self._factorise(jacobian.reshape(n_sys, n_sys))
        initial = exu.ConfigurationType.Initial
        sd.SetODE2Coordinates(state["q"], initial)
        sd.SetODE2Coordinates_t(state["v"], initial)
        sd.SetODE2Coordinates_tt(state["a_algorithmic"], initial)
        sd.SetAECoordinates(state["ae"], initial)
        sd.SetDataCoordinates(state["data"], initial)
        alpha = self._sim.timeIntegration.generalizedAlpha
        flags = alpha.computeInitialAccelerations, alpha.resetAccelerations
        alpha.computeInitialAccelerations, alpha.resetAccelerations = False, False
        try:
            solver.InitializeSolverInitialConditions(mbs, self._sim)  # current = initial; aAlgorithmic = its accel.
        finally:
            alpha.computeInitialAccelerations, alpha.resetAccelerations = flags
        sd.SetODE2Coordinates_tt(state["a"])
        sd.SetTime(state["time"])
        self._set_iteration(state["iteration"])
        self._t, self._u = state["t"], np.array(state["u"], dtype=float)
        self._step_size, self._refactorise[0] = state["step_size"], state["refactorise"]
        if self.prescribed is None:
            self._apply_effort(state["u"])
        self._output = self._make_output(self._u.copy() if self.prescribed is None
                                         else self._read_prescribed_reaction())

    def _set_iteration(self, fields: dict[str, Any]) -> None:
        it = self._solver.it
        for name in _ITERATION:
            setattr(it, name, fields[name])

    def _factorise(self, matrix: np.ndarray) -> None:
        """Leave ``matrix`` factorised as the solver's Newton matrix (see :meth:`set_state`): one Newton iteration
        whose Jacobian is ``matrix``, through a ``ComputeNewtonJacobian`` user function that only sets it; it holds
        no reference to the plant or the solver."""
        solver, mbs = self._solver, self.mbs

        def give(solver_, mbs_, settings) -> bool:  # noqa: ANN001
            solver_.SetSystemJacobian(matrix)
            return True

        newton = solver.newton
        iterations = newton.maxIterations
        solver.SetUserFunctionComputeNewtonJacobian(mbs, give)
        try:
            newton.maxIterations = 1
            solver.conv.jacobianUpdateRequested = True
            solver.Newton(mbs, self._sim)
        finally:
            newton.maxIterations = iterations
            solver.SetUserFunctionComputeNewtonJacobian(mbs, None)
