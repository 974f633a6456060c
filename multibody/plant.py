"""The stepping of the Exudyn delta plants (:class:`DeltaPlant`, the base of the linear and rotary plants).

A plant owns one Exudyn system and one persistent
``exu.MainSolverImplicitSecondOrder`` (generalized-alpha, index 3). ``step``
sets *both* ``timeIntegration.endTime`` and ``solver.it.endTime`` and calls
``SolveSteps`` (see docs/architecture.md, "Findings"). The renderer is never
started and no solution file is written.

``set_payload`` changes the payload in the running system. The system is built with
:class:`multibody.builder.SystemBuilder`'s methods, saved and restored with
:class:`multibody.state.StateCheckpoint`'s; the solver's settings are :class:`multibody.settings.SolverSettings`.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

import numpy as np

from delta.errors import ParameterError

from .builder import SystemBuilder
from .errors import PlantError
from .inertia import rigid_body_inertia
from .settings import SolverSettings, simulation_settings
from .state import StateCheckpoint

__all__ = ["PlantOutput", "DeltaPlant", "JointTrajectory"]


JointTrajectory = Callable[[float], tuple[np.ndarray, np.ndarray]]
"""Prescribed joint motion ``t -> (q(t), qd(t))``, each (3,), used by the prescribed-motion mode."""


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


class DeltaPlant(SystemBuilder, StateCheckpoint):
    """Base class: solver lifecycle, time bookkeeping, stepping, energy, payload. Subclasses build the system
    (``_build``, with :class:`multibody.builder.SystemBuilder`'s methods); the state is saved and restored by
    :class:`multibody.state.StateCheckpoint`'s."""

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
