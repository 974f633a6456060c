"""Common stepping machinery of the Exudyn delta plants.

A plant owns one Exudyn system and one persistent
``exu.MainSolverImplicitSecondOrder`` (generalized-alpha, index 3). ``step``
sets *both* ``timeIntegration.endTime`` and ``solver.it.endTime`` and calls
``SolveSteps`` (see docs/architecture.md, "Findings"). The renderer is never
started and no solution file is written.

``get_state`` / ``set_state`` save and restore everything a later step depends on,
so stepping on from a restored state repeats the original bit for bit, and
``set_payload`` changes the payload in the running system.

Every body is created in its reference configuration at the reset pose with
the identity as reference rotation, so body-local axes coincide with the base
frame at ``reset`` time and inertia tensors are given in base-frame axes.
"""

from __future__ import annotations

import math
from typing import Any, Callable, NamedTuple

import numpy as np

from delta.errors import ParameterError
from delta.masses import lumps

from .errors import PlantError
from .inertia import rigid_body_inertia, rod_end_masses
from .settings import SolverSettings, simulation_settings

__all__ = ["PlantOutput", "DeltaPlant", "JointTrajectory", "MIN_ROD_MASS", "PLATFORM_THICKNESS"]


JointTrajectory = Callable[[float], tuple[np.ndarray, np.ndarray]]
"""Prescribed joint motion ``t -> (q(t), qd(t))``, each (3,), used by the prescribed-motion mode."""


MIN_ROD_MASS = 1e-6
"""kg. A zero rod mass is represented by this in the rods' end masses (their weight stays zero), so that a rod's
end nodes keep a regular mass matrix."""

PLATFORM_THICKNESS = 0.01
"""Platform disc thickness, m (the full plants' platform inertia)."""


class PlantOutput(NamedTuple):
    """Plant outputs after a step (or after ``reset``).

    Attributes
    ----------
    t : float
        Simulation time, s.
    q, qd : (3,) arrays
        Joint positions and velocities (m, m/s for the linear delta; rad, rad/s for the rotary).
    p, v : (3,) arrays
        Platform centre position and velocity in the base frame, m, m/s.
    reaction : (3,) array
        Generalized force the actuator exerts on joint i along +q (linear: N, positive pushes
        the carriage down; rotary: N*m, positive turns the arm down). With applied efforts it
        equals the effort u held during the step; in prescribed-motion mode it is the drive
        constraint's reaction, i.e. the effort needed to follow the prescribed q(t).

    A named tuple (immutable, a quarter of a frozen dataclass's cost to build: one per plant step).
    """

    t: float
    q: np.ndarray
    qd: np.ndarray
    p: np.ndarray
    v: np.ndarray
    reaction: np.ndarray


def _time_tolerance(t: float) -> float:
    return 1e-9 * max(1.0, abs(t))


_ITERATION = ("adaptiveStep", "automaticStepSize", "automaticStepSizeError", "currentStepIndex", "currentStepSize",
              "currentTime", "discontinuousIteration", "discontinuousIterationsCount", "endTime", "initialStepSize",
              "lastStepSize", "maxStepSize", "minStepSize", "newtonJacobiCount", "newtonSteps", "newtonStepsCount",
              "numberOfSteps", "recommendedStepSize", "rejectedAutomaticStepSizeSteps", "rejectedModifiedNewtonSteps",
              "startTime")
"""The solver's iteration data (``solver.it``) a state holds: every field (time, step sizes, counters)."""


class DeltaPlant:
    """Base class: solver lifecycle, time bookkeeping, energy. Subclasses build the system."""

    kind = "delta"

    def __init__(self, robot, masses, fidelity: str, settings: SolverSettings | None,
                 prescribed: JointTrajectory | None, p0, v0, t0: float, h_nominal: float) -> None:
        if fidelity not in ("full", "lumped"):
            raise ParameterError(f"{type(self).__name__}: fidelity must be 'full' or 'lumped', got {fidelity!r}")
        self.robot = robot
        self.masses = masses
        self.fidelity = fidelity
        self.settings = settings or SolverSettings()
        self.prescribed = prescribed
        # joint range (m or rad): the end stops; a step that ends past one fails naming the joint
        self._q_lo, self._q_hi = float(robot.q_min), float(robot.q_max)
        self._h_nominal = float(h_nominal)
        self._output: PlantOutput | None = None
        self.reset(p0, v0, t0)

    # -- subclass interface -------------------------------------------------------------
    def _build(self, p0: np.ndarray, v0: np.ndarray, t0: float) -> None:  # pragma: no cover
        """Build the system at the platform state (p0, v0). Appends, in joint order, each joint's 1-coordinate node
        (carriage, arm) to ``self._joint_nodes``, and each actuator's effort variable (:meth:`_symbolic_load`) to
        ``self._effort_values``, or in prescribed-motion mode its drive constraint to ``self._drives``."""
        raise NotImplementedError

    def _read_joints(self, coords: np.ndarray, coords_t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Joint positions and velocities from the ODE2 coordinates and velocities (each (n,), fresh arrays)."""
        return self._q0 + coords[self._q_index], coords_t[self._q_index]

    def _apply_effort(self, u: list[float]) -> None:
        for value, ui in zip(self._effort_values, u):
            value.SetValue(ui)

    def _read_prescribed_reaction(self) -> np.ndarray:
        import exudyn as exu

        f = [self.mbs.GetObjectOutput(j, exu.OutputVariableType.Force) for j in self._drives]
        return _DRIVE_SIGN * np.array(f, dtype=float)

    # -- public API ---------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Current simulation time, s."""
        return self._t

    @property
    def output(self) -> PlantOutput:
        """Last output (after ``reset`` or ``step``)."""
        assert self._output is not None
        return self._output

    def reset(self, p0, v0=(0.0, 0.0, 0.0), t0: float = 0.0) -> PlantOutput:
        """Rebuild the system at platform position ``p0`` (m) and velocity ``v0`` (m/s).

        Joint positions and velocities come from the delta IK and Jacobian, every body is
        placed consistently; raises :class:`delta.errors.UnreachableError` if ``p0`` is
        outside the workspace.
        """
        import exudyn as exu

        p0 = np.asarray(p0, dtype=float).reshape(3)
        v0 = np.asarray(v0, dtype=float).reshape(3)
        self._t = float(t0)
        self._u = np.zeros(3)
        self._sc = exu.SystemContainer()
        self.mbs = self._sc.AddSystem()
        self._bodies: list[tuple[int, float, np.ndarray | None]] = []
        self._weights: list[tuple[int, list[float], float]] = []
        self._point_masses: list[tuple] = []  # (item, jacobian, reference, mass, weight): _add_point_masses
        self._symbolic: list = []  # symbolic user functions and their variables, kept alive with the system
        self._joint_nodes: list[int] = []
        self._effort_values: list = []
        self._drives: list[int] = []
        self._build(p0, v0, self._t)
        self.mbs.Assemble()
        self._system_data = self.mbs.systemData
        self._q_index = _gather([int(self._system_data.GetNodeLTGODE2(n)[0]) for n in self._joint_nodes])
        node = self.mbs.GetObject(self._platform)["nodeNumber"]
        first = int(self._system_data.GetNodeLTGODE2(node)[0])
        self._p_slice = slice(first, first + 3)  # a node's coordinates are contiguous: position first
        self._p_ref = np.asarray(self.mbs.GetNode(node)["referenceCoordinates"][:3], dtype=float)
        self._init_solver(self._h_nominal)
        self._output = self._make_output(self._u if self.prescribed is None else self._read_prescribed_reaction())
        return self._output

    def step(self, t: float, h: float, u=(0.0, 0.0, 0.0)) -> PlantOutput:
        """Advance from ``t`` (must equal :attr:`time`) to ``t + h`` with efforts ``u`` held constant.

        Any finite ``h > 0`` is accepted. The solver integrates from its own time to ``t + h`` in
        equal steps (``settings.substeps``, more if ``settings.max_step`` requires). A step that
        would leave the solver less than ``settings.min_step`` (the plant's resolution, 1 ns by
        default) to integrate, such as the 1e-13 s remainder a tool adding float steps produces,
        is *absorbed*: :attr:`time` advances but the solver does not, and the outputs keep the
        state of the solver's time (at most ``min_step`` old: a position error of at most
        ``|v| * min_step``). The next step integrates the absorbed interval with its own, so no
        time is lost; only the effort over those < 1 ns is the next step's instead of its own.

        Parameters
        ----------
        t, h : float
            Current time and macro step, s.
        u : (3,) array
            Actuator efforts along +q (N or N*m); ignored in prescribed-motion mode.

        Raises
        ------
        PlantError
            Wrong ``t``, bad ``h`` or ``u``, a solver failure, or a joint that ends the step outside
            ``[robot.q_min, robot.q_max]`` (carriage stroke / arm range: the end stops), named with
            its value and the time.
        """
        if abs(t - self._t) > _time_tolerance(self._t):
            raise PlantError(f"{type(self).__name__}.step: t = {t!r} s does not equal the plant time "
                             f"{self._t!r} s; steps must be contiguous")
        if not 0.0 < h < math.inf:
            raise PlantError(f"{type(self).__name__}.step at t = {t!r} s: h must be a finite step > 0 s, got {h!r}")
        t_end = t + h
        if self.prescribed is None:
            u = np.array(u, dtype=float).reshape(3)  # a copy: the caller may reuse its array
            values = u.tolist()
            if not all(map(math.isfinite, values)):
                raise PlantError(f"{type(self).__name__}.step at t = {t!r} s: non-finite effort u = {u}")
            self._apply_effort(values)
            self._u = u
        # Integrate from the solver's own time to t_end, never by a fixed h: Exudyn advances its time
        # by adding step sizes, which drifts from the caller's exact times (3.8e-16 s per 1 ms step,
        # 1e-10 s after 260 s), and Exudyn's loop ends only within 1e-10 s of endTime: past that it
        # adds a sliver step of ~1e-10 s whose Newton matrix (~1/h^2) cannot converge. Anchoring
        # every macro step on t_end keeps the drift below a few ulps for any length of run.
        span = t_end - self._it.currentTime  # h, plus any interval absorbed before
        if span < self.settings.min_step:  # below the resolution: absorbed (see the docstring)
            self._t = t_end
            self._output = self._make_output(self._u if self.prescribed is None else self._read_prescribed_reaction())
            return self._output
        n = self._substeps
        max_step = self.settings.max_step
        if max_step is not None and span > max_step * (1.0 + 1e-9):  # 1e-9: rounding of span never adds a step
            n = max(n, math.ceil(span / max_step * (1.0 - 1e-12)))
        step_size = span / n
        if step_size != self._step_size:
            if not math.isclose(step_size, self._step_size or 0.0, rel_tol=1e-9):
                # the Newton matrix scales with 1/h^2; the ulps by which span / n wanders (every step past
                # t = 1 s) do not matter
                self._refactorise[0] = True
            it = self._it
            it.currentStepSize = step_size
            it.minStepSize = step_size
            it.maxStepSize = step_size
            it.initialStepSize = step_size
            self._step_size = step_size
        self._it.endTime = t_end  # what SolveSteps reads (the settings' endTime is only InitializeSolver's)
        try:
            ok = self._solve_steps(self.mbs, self._sim)
        except Exception as exc:  # Exudyn raises plain RuntimeError/ValueError
            raise PlantError(f"{type(self).__name__}: solver failed between t = {t!r} s and "
                             f"{t_end!r} s: {exc}") from exc
        if not ok:
            raise PlantError(f"{type(self).__name__}: solver did not converge between t = {t!r} s and "
                             f"{t_end!r} s ({self._solver.GetErrorString()})")
        self._t = t_end
        self._output = out = self._make_output(self._u if self.prescribed is None else self._read_prescribed_reaction())
        q = out.q.tolist()
        if not (self._q_lo <= min(q) and max(q) <= self._q_hi):
            self._out_of_range(t_end, q)
        return out

    def _out_of_range(self, t: float, q: list[float]) -> None:
        """Raise the error of a joint driven past its range (the robot's end stops)."""
        from delta.actuators import kind_of
        from delta.kinematics import END_STOP

        actuator = kind_of(self.robot.kind)
        for i, qi in enumerate(q):
            if not self._q_lo <= qi <= self._q_hi:
                (value, lo, hi), unit = actuator.shown([qi, self._q_lo, self._q_hi])
                raise PlantError(
                    f"{type(self).__name__}: joint {i + 1} at q = {value:.6g} {unit} left its {actuator.joint_range} "
                    f"[{lo:.6g}, {hi:.6g}] {unit} at t = {t:.6f} s: {END_STOP}")

    def energy(self) -> tuple[float, float]:
        """Kinetic and gravitational potential energy of the model, J (potential zero at z = 0)."""
        import exudyn as exu

        ovt = exu.OutputVariableType
        kin = pot = 0.0
        for body, mass, inertia in self._bodies:
            vel = np.asarray(self.mbs.GetObjectOutputBody(body, ovt.Velocity, [0.0, 0.0, 0.0]))
            kin += 0.5 * mass * float(vel @ vel)
            if inertia is not None:
                w = np.asarray(self.mbs.GetObjectOutputBody(body, ovt.AngularVelocityLocal, [0.0, 0.0, 0.0]))
                kin += 0.5 * float(w @ inertia @ w)
        for body, local, gravity_mass in self._weights:
            pos = np.asarray(self.mbs.GetObjectOutputBody(body, ovt.Position, list(local)))
            pot += gravity_mass * self.masses.gravity * pos[2]
        if self._point_masses:
            coords, coords_t = self._system_data.GetODE2Coordinates(), self._system_data.GetODE2Coordinates_t()
        for item, jacobian, reference, mass, weight in self._point_masses:
            index = np.asarray(self._system_data.GetObjectLTGODE2(item), dtype=int)
            v = (jacobian @ coords_t[index]).reshape(-1, 3)
            z = (reference + jacobian @ coords[index])[2::3]
            kin += 0.5 * float(np.sum(mass * (v @ v.T)))
            pot += float(weight @ z) * self.masses.gravity
        return kin, pot

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

    def set_payload(self, payload: float) -> None:
        """Carry ``payload`` kg on the platform from the next step on, in the running system (not rebuilt).

        The platform body's mass (full fidelity: and its inertia, a uniform disc) and its weight load change; the
        solver's mass matrix, which Exudyn computes once for these constant-mass systems, is computed again, and the
        Newton matrix is refactorised at the next step. The motion state is kept. Raises
        :class:`delta.errors.ParameterError` for a payload the masses refuse (nothing changes then).
        """
        if payload == self.masses.payload:
            return
        masses = self.masses.with_(payload=float(payload))
        mass, weight = self._platform_masses(masses)
        mbs, body = self.mbs, self._platform
        inertia = self._platform_inertia(mass) if self.fidelity == "full" else None
        mbs.SetObjectParameter(body, "mass", mass)
        if inertia is not None:
            mbs.SetObjectParameter(body, "inertia", rigid_body_inertia(mass, inertia).GetInertia6D())
        mbs.SetLoadParameter(self._platform_weight, "loadVector", [0.0, 0.0, -weight * masses.gravity])
        self.masses = masses
        self._bodies = [(body, mass, inertia) if entry[0] == body else entry for entry in self._bodies]
        self._weights = [(body, entry[1], weight) if entry[0] == body else entry for entry in self._weights]
        self._solver.ComputeMassMatrix(mbs)
        self._refactorise[0] = True

    def platform_tilt(self) -> float:
        """Rotation angle of the platform from level, rad (0 for the translational lumped platform)."""
        import exudyn as exu

        if self.fidelity != "full":
            return 0.0
        rot = self.mbs.GetObjectOutputBody(self._platform, exu.OutputVariableType.RotationMatrix, [0.0, 0.0, 0.0])
        return tilt_angle(rot)

    # -- helpers ------------------------------------------------------------------------
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

    def _platform_masses(self, masses) -> tuple[float, float]:  # noqa: ANN001
        """(mass, weight) of the platform body, kg (:func:`delta.masses.lumps`): platform and payload (full fidelity,
        whose rods are bodies of their own), or the lumped platform with the rods' shares of the inertial and of
        the gravity terms."""
        lumped = lumps(masses, self.kind)
        if self.fidelity == "full":
            return lumped.platform_alone, lumped.platform_alone
        return lumped.platform_inertial, lumped.platform_weight_mass

    def _platform_inertia(self, mass: float) -> np.ndarray:
        """Inertia tensor (3, 3) about its centre of the full plants' platform: a uniform disc of ``mass`` kg, radius
        ``robot.platform_radius`` and :data:`PLATFORM_THICKNESS`, kg m^2."""
        r = self.robot.platform_radius
        return np.diag([mass * (3 * r**2 + PLATFORM_THICKNESS**2) / 12.0] * 2 + [mass * r**2 / 2.0])

    def _add_platform(self, p0: np.ndarray, v0: np.ndarray) -> None:
        """The platform body at (p0, v0) and its weight (a load even when it weighs nothing, for :meth:`set_payload`):
        a rigid disc (full fidelity) or a point mass carrying the rods' shares (lumped)."""
        mass, weight = self._platform_masses(self.masses)
        inertia = self._platform_inertia(mass) if self.fidelity == "full" else None
        self._platform = self._add_body(mass, inertia, p0, v0)
        self._platform_weight = self._add_weight(self._platform, (0.0, 0.0, 0.0), weight, keep=True)

    def _add_body(self, mass: float, inertia: np.ndarray | None, position, velocity) -> int:
        """Add a rigid body (``inertia`` given, about its centre of mass, base axes) or a point mass.

        The body reference point is its centre of mass, so the kinetic energy is
        ``m v.v / 2 + w.J w / 2``. A rigid body turns on a rotation-vector node integrated on the rotation group
        (Exudyn's ``NodeRigidBodyRotVecLG``): its mass matrix is constant (the mass, and the inertia tensor in body
        axes), so with the rods' and carriages' constant ones Exudyn builds the system's mass matrix once instead
        of at every Newton residual, and it needs no Euler-parameter constraint. The platform, the one rigid body
        of the full plants, hardly turns: pick_place_ctc and the helices give the same samples as on Euler
        parameters within 3e-16 m and 4e-13 m.
        """
        import exudyn as exu
        from exudyn.itemInterface import MassPoint, NodePoint

        position = [float(x) for x in position]
        velocity = [float(x) for x in velocity]
        if inertia is None:
            node = self.mbs.AddNode(NodePoint(referenceCoordinates=position, initialVelocities=velocity))
            body = self.mbs.AddObject(MassPoint(mass=mass, nodeNumber=node))
        else:
            body = self.mbs.CreateRigidBody(
                referencePosition=position,
                referenceRotationMatrix=np.eye(3),
                initialVelocity=velocity,
                inertia=rigid_body_inertia(mass, inertia),
                nodeType=exu.NodeType.RotationRotationVector,
            )
        self._bodies.append((body, mass, inertia))
        return body

    def _add_rod(self, parent: int, start: np.ndarray, end: np.ndarray, v_start: np.ndarray,
                 v_end: np.ndarray) -> None:
        """One parallelogram rod from ``start`` (on ``parent``) to ``end`` (on the platform), spherical joints at
        both ends: its two ends are point nodes (initial velocities ``v_start``, ``v_end``) carrying the rod's
        mass and weight (:func:`rod_end_masses`, :meth:`_add_point_masses`), held at the rod's length by one
        distance constraint. A rod whose lower end moves linearly with a joint coordinate (a linear delta's
        carriage) is built by the plant with :meth:`_add_rod_end` alone, its lower end a point of the carriage."""
        from exudyn.itemInterface import MarkerNodePosition

        m = self.masses
        low = self._add_node_point(start, v_start)
        low_marker = self.mbs.AddMarker(MarkerNodePosition(nodeNumber=low))
        self._add_spherical_joint(parent, start, low_marker)
        up = self._add_rod_end(low_marker, start, end, v_end)
        self._add_point_masses([low, up], np.eye(6), np.stack([start, end]), self._rod_mass(start, end),
                               np.array([0.5 * m.rod, 0.5 * m.rod]))

    def _rod_mass(self, start: np.ndarray, end: np.ndarray) -> np.ndarray:
        """The (2, 2) mass matrix of the rod from ``start`` to ``end`` over its two ends (:func:`rod_end_masses`;
        a zero rod mass counts as :data:`MIN_ROD_MASS`); its weight is ``masses.rod``, half at each end."""
        a, b = rod_end_masses(max(self.masses.rod, MIN_ROD_MASS), self.masses.rod_radius,
                              float(np.linalg.norm(end - start)))
        return np.array([[a, b], [b, a]])

    def _add_rod_end(self, low_marker: int, start: np.ndarray, end: np.ndarray, v_end: np.ndarray) -> int:
        """A rod's upper end: a point node at ``end`` (initial velocity ``v_end``) joined to the platform by a
        spherical joint, at the rod's length from the lower end's marker ``low_marker`` (at ``start`` now) by a
        distance constraint. Returns the node; its mass is the caller's (:meth:`_add_point_masses`)."""
        from exudyn.itemInterface import DistanceConstraint, MarkerNodePosition, VObjectConnectorDistance

        up = self._add_node_point(end, v_end)
        up_marker = self.mbs.AddMarker(MarkerNodePosition(nodeNumber=up))
        self._add_spherical_joint(self._platform, end, up_marker)
        self.mbs.AddObject(DistanceConstraint(markerNumbers=[low_marker, up_marker],
                                              distance=float(np.linalg.norm(end - start)),
                                              visualization=VObjectConnectorDistance(show=False)))
        return up

    def _add_point_masses(self, nodes: list[int], jacobian: np.ndarray, reference: np.ndarray, mass: np.ndarray,
                          weight: np.ndarray) -> int:
        """Masses at points that move linearly with the coordinates x of ``nodes`` (in their order, each node's
        coordinates relative to its reference): point k is at ``reference[k] + jacobian[3k:3k+3] @ x``, the
        kinetic energy is ``sum_kl mass[k, l] v_k.v_l / 2`` (``mass`` symmetric, kg) and ``weight[k]`` kg weigh
        at point k. Both are constant in x: an Exudyn ``ObjectGenericODE2`` with the mass matrix
        ``J^T (mass (x) I3) J`` and the weights' generalized force ``J^T w``, no rotation parameters and nothing
        evaluated per Newton iteration but a product with a constant matrix."""
        import exudyn as exu
        from exudyn.itemInterface import ObjectGenericODE2, VObjectGenericODE2

        jacobian = np.asarray(jacobian, dtype=float)
        forces = np.zeros(jacobian.shape[0])
        forces[2::3] = -np.asarray(weight, dtype=float) * self.masses.gravity
        matrix = exu.MatrixContainer()
        matrix.SetWithDenseMatrix(jacobian.T @ np.kron(mass, np.eye(3)) @ jacobian, useDenseMatrix=False)
        item = self.mbs.AddObject(ObjectGenericODE2(nodeNumbers=list(nodes), massMatrix=matrix,
                                                    forceVector=(jacobian.T @ forces).tolist(),
                                                    visualization=VObjectGenericODE2(show=False)))
        self._point_masses.append((item, jacobian, np.asarray(reference, dtype=float).reshape(-1),
                                   np.asarray(mass, dtype=float), np.asarray(weight, dtype=float)))
        return item

    def _add_node_point(self, position: np.ndarray, velocity: np.ndarray) -> int:
        from exudyn.itemInterface import NodePoint

        return self.mbs.AddNode(NodePoint(referenceCoordinates=[float(x) for x in position],
                                          initialVelocities=[float(x) for x in velocity]))

    def _body_marker(self, body: int, point: np.ndarray) -> int:
        """A position marker on ``body`` at the global point ``point`` of the reset pose."""
        import exudyn as exu
        from exudyn.itemInterface import MarkerBodyPosition

        ovt, reference = exu.OutputVariableType, exu.ConfigurationType.Reference
        origin = np.asarray(self.mbs.GetObjectOutputBody(body, ovt.Position, [0.0, 0.0, 0.0], configuration=reference))
        rotation = np.asarray(self.mbs.GetObjectOutputBody(body, ovt.RotationMatrix, [0.0, 0.0, 0.0],
                                                           configuration=reference)).reshape(3, 3)
        local = rotation.T @ (np.asarray(point, dtype=float) - origin)
        return self.mbs.AddMarker(MarkerBodyPosition(bodyNumber=body, localPosition=[float(x) for x in local]))

    def _add_spherical_joint(self, body: int, point: np.ndarray, marker: int) -> None:
        """Join ``marker`` to ``body`` at the global point ``point`` of the reset pose."""
        from exudyn.itemInterface import SphericalJoint, VObjectJointSpherical

        self.mbs.AddObject(SphericalJoint(markerNumbers=[self._body_marker(body, point), marker],
                                          visualization=VObjectJointSpherical(show=False)))

    def _add_weight(self, body: int, local, gravity_mass: float, keep: bool = False) -> int | None:
        """Apply the weight of ``gravity_mass`` at body-local point ``local`` (-z); returns the load, None when
        nothing weighs (zero mass or gravity) unless ``keep``.

        At a rigid body's or mass point's reference point (its centre of mass, ``local`` = 0) the weight acts on
        its node's position coordinates directly: the same generalized force as through a body marker, whose
        position Jacobian there is [I, 0], without evaluating the body's rotation at every residual."""
        from exudyn.itemInterface import LoadForceVector, MarkerBodyPosition, MarkerNodePosition

        if not keep and (gravity_mass == 0.0 or self.masses.gravity == 0.0):
            return None
        local = [float(x) for x in local]
        item = self.mbs.GetObject(body)
        if not any(local) and item["objectType"] in ("RigidBody", "MassPoint"):
            marker = self.mbs.AddMarker(MarkerNodePosition(nodeNumber=item["nodeNumber"]))
        else:
            marker = self.mbs.AddMarker(MarkerBodyPosition(bodyNumber=body, localPosition=local))
        load = self.mbs.AddLoad(LoadForceVector(markerNumber=marker,
                                                loadVector=[0.0, 0.0, -gravity_mass * self.masses.gravity]))
        self._weights.append((body, local, gravity_mass))
        return load

    def _init_solver(self, h: float) -> None:
        import exudyn as exu

        s = self.settings
        reuse = s.reuse_for(self.fidelity)
        self._sparse = s.sparse_for(self.fidelity)
        sim = self._sim = simulation_settings(s, self.fidelity, self._t, h)
        self._solver = exu.MainSolverImplicitSecondOrder()
        self._solver.InitializeSolver(self.mbs, sim)
        # with reuse_jacobian, refactorise on the next step (InitializeSolver's factorisation is of its
        # initial-acceleration system, and step() sets it when the step size changes)
        self._refactorise = [True]
        if reuse:
            self._solver.SetUserFunctionFinishStep(self.mbs, _keep_jacobian(self._refactorise))
        self._it = self._solver.it
        self._solve_steps = self._solver.SolveSteps
        self._substeps = s.substeps
        self._step_size = None

    def _make_output(self, reaction: np.ndarray) -> PlantOutput:
        """Outputs from one read of the coordinates; ``reaction`` must be a fresh array."""
        sd = self._system_data
        coords = sd.GetODE2Coordinates()  # fresh numpy arrays (copies of the solver state)
        coords_t = sd.GetODE2Coordinates_t()
        q, qd = self._read_joints(coords, coords_t)
        # v: a view of the fresh coords_t, which only this output holds
        return PlantOutput(self._t, q, qd, self._p_ref + coords[self._p_slice], coords_t[self._p_slice], reaction)

    def _symbolic_load(self, load: int, parameter: str, value):
        """Drive load ``load``'s ``parameter`` through a symbolic user function returning a
        variable; returns the variable (``SetValue`` / ``SetVector`` is ~3x cheaper than
        ``SetLoadParameter``). The function and the variable live as long as the system."""
        import exudyn as exu
        from exudyn.advancedUtilities import CreateSymbolicUserFunction

        variable = exu.symbolic.Real(float(value)) if np.ndim(value) == 0 else exu.symbolic.Vector(list(value))

        def user_function(mbs, t, load_index):
            return variable

        function = CreateSymbolicUserFunction(self.mbs, user_function, parameter, load)
        self.mbs.SetLoadParameter(load, parameter, function)
        self._symbolic.append((function, variable))
        return variable


_DRIVE_SIGN = -1.0
"""A drive (``CoordinateConstraint``) reports its force on the ground side: flipped, the effort on the joint along +q."""


def _gather(index: list[int]) -> slice | np.ndarray:
    """Indexing that picks ``index`` from a coordinate vector: a slice (a view, ~10x cheaper than an index array)
    when the indices are evenly spaced, as the joints' are (each leg's bodies are added alike)."""
    stride = index[1] - index[0] if len(index) > 1 else 1
    if stride > 0 and index == list(range(index[0], index[-1] + 1, stride)):
        return slice(index[0], index[-1] + 1, stride)
    return np.array(index)


def _keep_jacobian(refactorise: list[bool]):
    """Exudyn's ``FinishStep`` replaced (it only prints, writes files and draws, all off in a plant) by one
    that keeps the factorised Newton matrix: ``SolveSteps`` requests a new one on entry, just before it calls
    ``FinishStep``; this withdraws the request unless ``refactorise[0]`` (then cleared) asks for it. Newton's
    own requests (slow convergence) happen inside a step and are never withdrawn. Holds no reference to the
    plant or the solver, so no reference cycle runs through Exudyn's C++ side."""

    def finish_step(solver, mbs, settings) -> bool:
        if refactorise[0]:
            refactorise[0] = False
        else:
            solver.conv.jacobianUpdateRequested = False
        return True

    return finish_step


def tilt_angle(rotation: np.ndarray) -> float:
    """Rotation angle of a rotation matrix, accurate for small angles, rad."""
    rot = np.asarray(rotation, dtype=float).reshape(3, 3)
    skew = 0.5 * (rot - rot.T)
    s = np.linalg.norm([skew[2, 1], skew[0, 2], skew[1, 0]])
    c = 0.5 * (np.trace(rot) - 1.0)
    return float(np.arctan2(s, c))
