"""Inverse dynamics of the multibody plant against the analytic model on a prescribed motion.

The plant's joints are driven exactly along the trajectory's ``q(t)`` (drive constraints,
``prescribed`` mode) and the drive reactions are the actuator efforts the multibody model
needs; the analytic model's ``inverse_dynamics(q, qd, qdd)`` is evaluated at the same
instants. Rod masses in the full plant are distributed (rigid rods), so the analytic error
depends on the lumping factor ``w``; this module measures that dependence for the linear and
the rotary delta (:func:`validate_model`).

Why the best single ``w`` of the fast pick cycle is 1/3, not the thesis's 2/3
--------------------------------------------------------------------------------
A uniform rod of mass ``m`` between two spherical joints A and B (its spin about its own axis is
idle) has exactly the dynamics of three point masses on its axis: ``m/6`` at A, ``2m/3`` at the
middle, ``m/6`` at B (same mass, centre and transverse inertia ``m L^2 / 12``; the rod radius
changes this by ``(r/L)^2 ~ 1e-4``). With ``a_M = (a_A + a_B) / 2`` the virtual work of its
inertia is

    m/3 a_A.dr_A + m/3 a_B.dr_B + m/6 (a_A.dr_B + a_B.dr_A),

and its weight acts as ``m/2`` at each end. The analytic model lumps ``(1 - w) m`` at A (carriage
or elbow) and ``w m`` at B (platform). So gravity is exact at ``w_gravity = 1/2`` for every
motion, while no single ``w`` is exact for inertia: the platform side is right at ``w = 1/3``,
the carriage/elbow side at ``w = 2/3``, and the cross term belongs to neither. At ``w = 2/3``
the model carries ``m/3`` too much on the platform per rod (0.2 kg on the linear delta's 0.3 kg
platform, accelerating at up to 7 g); at ``w = 1/3`` the same excess sits on the carriages, whose
effort it reaches one to one instead of through the legs. Measured on the 25/305/25 mm,
0.5 s cycle (``validate_model(..., "pick_place")``, h = 0.2 ms):

====================  ==========  =================  ===========================================
robot                 RMS at 2/3  best single w      best separate (w_inertia, w_gravity), RMS
====================  ==========  =================  ===========================================
linear (thesis)       14.1 %      0.335: 6.7 %       (0.365, 1.0): 5.3 %
rotary (seed 004)     21.9 %      0.331: 2.5 %       (0.340, 0.62): 2.2 %
====================  ==========  =================  ===========================================

The 4-6 % expected at ``w = 2/3`` is not what rigid uniform rods give on this cycle; 2/3 is
right for the *elbow/carriage* share (Codourey's rule is usually quoted as 2/3 of the forearm at
the elbow, i.e. ``w = 1/3`` at the platform). On a fast cycle the weight hardly varies, so
``w_gravity`` is weakly determined there (it drifts to the box edge for the linear delta);
on the slow helix it comes out near the exact 1/2 (0.51 rotary over 2 s, 0.56 linear over
0.5 s). The residual 2-5 % with the best split is the cross term no lumping can express.

That cross term is the rod turning about its centre: the three masses' kinetic energy is the two end
halves' less ``m/12 |v_A - v_B|^2``. The analytic model has it as ``w_rotation`` (:mod:`delta.dynamics`), and
:func:`identify_model` fits with it (``w_rotation = 1``): both robots then come out at the exact uniform-rod
split, ``w_inertia = 0.500``, ``w_gravity = 0.500``, with 0.35 % (linear) and 0.29 % (rotary) RMS effort error on
the pick cycle and 0.06 % / 0.10 % on the helix (``python -m cosim validate-model --robot PRESET --trajectory
pick_place helix``).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Callable

import numpy as np

from delta.actuators import kind_of
from delta.dynamics import analytic_model
from delta.errors import ParameterError, UnreachableError
from delta.kinematics import joint_state_from_platform
from delta.robots import get_preset
from delta.trajectories import Helix, PickAndPlace

from .settings import SolverSettings

__all__ = [
    "FORCE_COMPARISON_SETTINGS",
    "VALIDATION_TRAJECTORIES",
    "PrescribedRun",
    "WError",
    "ValidationReport",
    "run_prescribed",
    "force_errors",
    "validation_trajectory",
    "validate_model",
    "TrajectoryFit",
    "Identification",
    "identify_model",
]

FORCE_COMPARISON_SETTINGS = SolverSettings(spectral_radius=0.5, newton_rel_tol=1e-8)
"""Spectral radius 0.5 (less numerical damping of the reactions) for force comparisons."""

Progress = Callable[[int, int], None]
"""``progress(done, total)``: called as a long validation advances (``done`` of ``total`` units)."""

VALIDATION_TRAJECTORIES = {
    ("linear", "helix"): Helix(duration=2.0),
    ("linear", "pick_place"): PickAndPlace(start=(-0.15, 0.0, -0.45)),
    ("rotary", "helix"): Helix(z0=-0.55, duration=2.0),
    ("rotary", "pick_place"): PickAndPlace(start=(-0.1525, 0.0, -0.55)),
}
"""Validation motions per robot kind: the thesis helix (one 2 s revolution, radius 0.1 m) and
the fast 25/305/25 mm pick cycle (0.5 s, ~7 g), each centred in that kind's workspace (checked
reachable by :func:`validation_trajectory`). The rotary ones sit 0.55 m below the base, the
height of ``scenarios/rotary_pick_place_ctc.yaml``."""


@dataclass(frozen=True)
class PrescribedRun:
    """Drive efforts of the plant along a prescribed motion: ``t`` (N,), ``q, qd, qdd, f_plant`` (N, 3)."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    f_plant: np.ndarray


class _JointMotion:
    """``t -> (q, qd)`` of a platform trajectory through IK, cached on the last time."""

    def __init__(self, robot, trajectory) -> None:
        self.robot, self.trajectory = robot, trajectory
        self._t = None
        self._value = None

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        if t != self._t:
            p, v, _ = self.trajectory.evaluate(t)
            q, qd, _ = joint_state_from_platform(self.robot, p, v)
            self._t, self._value = t, (q, qd)
        return self._value

    def full(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        p, v, a = self.trajectory.evaluate(t)
        return joint_state_from_platform(self.robot, p, v, a)


def _default_masses(robot):
    return kind_of(robot.kind).masses_type()


MAX_PRESCRIBED_STEPS = 1_000_000
"""Plant steps of one prescribed run at most (200 s of motion at the default 2e-4 s; about 100 MB of recorded
joint states and efforts, a few minutes of the full plant): a longer step or a shorter duration goes beyond it."""


def prescribed_steps(duration: float, h: float) -> int:
    """The plant steps of ``h`` s that cover ``duration`` s; a step longer than the motion, or more steps than
    :data:`MAX_PRESCRIBED_STEPS`, is a :class:`ParameterError` naming both."""
    if not (0.0 < h < math.inf and 0.0 < duration < math.inf):
        raise ParameterError(f"step {h!r} s and duration {duration!r} s must be finite times > 0 s")
    n = round(duration / h)
    if n < 1:
        raise ParameterError(f"step {h:g} s is longer than the motion ({duration:g} s): not one plant step fits")
    if n > MAX_PRESCRIBED_STEPS:
        raise ParameterError(f"{duration:g} s at a step of {h:g} s is {n:.3g} plant steps, more than the "
                             f"{MAX_PRESCRIBED_STEPS:.0e} a prescribed run takes: a longer step or a shorter duration")
    return n


def run_prescribed(robot, trajectory, masses=None, h: float = 2e-4, duration: float | None = None,
                   fidelity: str = "full", settings: SolverSettings | None = None,
                   progress: Progress | None = None) -> PrescribedRun:
    """Drive the plant along ``trajectory`` (platform motion, ``evaluate(t) -> (p, v, a)``) and record efforts.

    ``progress(done, total)`` is called about a hundred times, ``total`` = number of steps.
    """
    from . import make_plant

    motion = _JointMotion(robot, trajectory)
    n = prescribed_steps(float(trajectory.duration if duration is None else duration), h)
    p0, v0, _ = trajectory.evaluate(0.0)
    plant = make_plant(robot, masses, fidelity=fidelity, settings=settings or FORCE_COMPARISON_SETTINGS,
                       p0=p0, v0=v0, prescribed=motion, h_nominal=h)
    t = np.empty(n)
    q, qd, qdd, f = (np.empty((n, 3)) for _ in range(4))
    every = max(1, n // 100)
    for k in range(n):
        out = plant.step(plant.time, h, None)
        t[k] = (k + 1) * h
        q[k], qd[k], qdd[k] = motion.full(t[k])
        f[k] = out.reaction
        if progress is not None and ((k + 1) % every == 0 or k + 1 == n):
            progress(k + 1, n)
    return PrescribedRun(t, q, qd, qdd, f)


def _model_efforts(run: PrescribedRun, robot, masses) -> np.ndarray:
    model = analytic_model(robot, masses)
    return np.array([model.inverse_dynamics(q, qd, qdd) for q, qd, qdd in zip(run.q, run.qd, run.qdd)])


def force_errors(run: PrescribedRun, robot, masses) -> tuple[float, float]:
    """Relative RMS and peak error of the analytic efforts against the plant's, over all joints."""
    err = _model_efforts(run, robot, masses) - run.f_plant
    rms = float(np.sqrt(np.mean(err**2)) / np.sqrt(np.mean(run.f_plant**2)))
    peak = float(np.max(np.abs(err)) / np.max(np.abs(run.f_plant)))
    return rms, peak


# -- validate_model ---------------------------------------------------------------------------


@dataclass(frozen=True)
class WError:
    """Analytic-vs-plant effort error for one mass split (``w_inertia``, ``w_gravity``).

    ``rms_rel = rms(f_model - f_plant) / rms(f_plant)``, ``peak_rel = max|f_model - f_plant| /
    max|f_plant|`` over all joints and samples; ``rms_abs`` and ``peak_abs`` are the same
    numerators in effort units (N or N*m).
    """

    w_inertia: float
    w_gravity: float
    rms_rel: float
    peak_rel: float
    rms_abs: float
    peak_abs: float


@dataclass(frozen=True)
class ValidationReport:
    """Analytic model against the multibody plant on one prescribed motion (see :func:`validate_model`).

    Attributes
    ----------
    robot, trajectory, fidelity : str
    effort_unit : str
        "N" (linear delta) or "N*m" (rotary delta).
    h, duration : float
        Plant step and simulated time, s.
    samples : int
    plant_rms, plant_peak : float
        RMS and peak of the plant's efforts over all joints, effort unit.
    sweep : tuple of WError
        One row per ``w`` with ``w_inertia = w_gravity = w``.
    best : WError
        The sweep row with the smallest RMS error.
    best_w_continuous : float or None
        The RMS-optimal single ``w`` in [0, 1] (least squares; the analytic efforts are affine
        in ``w``); None when ``w`` changes nothing (massless rods).
    separate : WError or None
        The RMS-optimal ``(w_inertia, w_gravity)`` pair in [0, 1]^2 (least squares), evaluated,
        if requested (None for massless rods). On a fast cycle the weight barely changes along
        the motion, so ``w_gravity`` is weakly determined there; a slow motion (the helix)
        identifies it.
    """

    robot: str
    trajectory: str
    fidelity: str
    effort_unit: str
    h: float
    duration: float
    samples: int
    plant_rms: float
    plant_peak: float
    sweep: tuple[WError, ...]
    best: WError
    best_w_continuous: float | None
    separate: WError | None

    @property
    def best_w(self) -> float:
        """The swept ``w`` with the smallest RMS error."""
        return self.best.w_inertia

    @property
    def best_w_inertia(self) -> float | None:
        return None if self.separate is None else self.separate.w_inertia

    @property
    def best_w_gravity(self) -> float | None:
        return None if self.separate is None else self.separate.w_gravity

    def as_dict(self) -> dict:
        """Plain JSON-ready dict (floats, lists, None)."""
        out = asdict(self)
        out["sweep"] = [asdict(row) for row in self.sweep]
        out["best_w"] = self.best_w
        out["best_w_inertia"] = self.best_w_inertia
        out["best_w_gravity"] = self.best_w_gravity
        return out

    def text(self) -> str:
        """Human-readable table of the error against ``w`` and the best splits."""
        u = self.effort_unit
        lines = [
            f"{self.robot}, {self.trajectory}: analytic inverse dynamics vs the {self.fidelity} Exudyn plant "
            f"({self.samples} samples, h = {self.h * 1e3:g} ms, {self.duration:g} s)",
            f"plant effort: RMS {self.plant_rms:.4g} {u}, peak {self.plant_peak:.4g} {u}",
            f"{'w':>6s} {'RMS %':>8s} {'peak %':>8s} {'RMS ' + u:>12s} {'peak ' + u:>12s}",
        ]
        for row in self.sweep:
            mark = "  <- best" if row is self.best else ""
            lines.append(f"{row.w_inertia:6.3f} {100 * row.rms_rel:8.3f} {100 * row.peak_rel:8.3f} "
                         f"{row.rms_abs:12.4g} {row.peak_abs:12.4g}{mark}")
        if self.best_w_continuous is None:
            lines.append("the rods are massless: w changes nothing")
        else:
            lines.append(f"best single w (least squares): {self.best_w_continuous:.3f}")
        if self.separate is not None:
            s = self.separate
            lines.append(f"best separate split: w_inertia = {s.w_inertia:.3f}, w_gravity = {s.w_gravity:.3f}: "
                         f"RMS {100 * s.rms_rel:.3f} %, peak {100 * s.peak_rel:.3f} %")
        return "\n".join(lines)


def validation_trajectory(robot, name: str):
    """The validation motion ``name`` ("helix" or "pick_place") for ``robot``'s kind, checked reachable.

    Raises
    ------
    ParameterError, UnreachableError
        Unknown name, or the motion leaves ``robot``'s workspace (the message says where and why).
    """
    try:
        trajectory = VALIDATION_TRAJECTORIES[(robot.kind, name)]
    except KeyError:
        valid = sorted({n for _, n in VALIDATION_TRAJECTORIES})
        raise ParameterError(f"unknown validation trajectory {name!r}; valid: {', '.join(valid)}") from None
    check = trajectory.check(robot)
    if not check.ok:
        raise UnreachableError(f"{name} trajectory leaves the workspace of {robot.name} at t = {check.t} s, "
                         f"p = {check.p} m: {check.reason}")
    return trajectory


def _error(f_model: np.ndarray, f_plant: np.ndarray, w_inertia: float, w_gravity: float) -> WError:
    err = f_model - f_plant
    rms_abs = float(np.sqrt(np.mean(err**2)))
    peak_abs = float(np.max(np.abs(err)))
    return WError(float(w_inertia), float(w_gravity), rms_abs / float(np.sqrt(np.mean(f_plant**2))),
                  peak_abs / float(np.max(np.abs(f_plant))), rms_abs, peak_abs)


def _unit_box_least_squares(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """``argmin |a x - b|`` over ``x`` in [0, 1]^2 (``a`` (n, 2)): the unconstrained optimum if it
    lies inside, else the best of the four edges' 1-D optima (the problem is convex)."""
    x, *_ = np.linalg.lstsq(a, b, rcond=None)
    if np.all((x >= 0.0) & (x <= 1.0)):
        return float(x[0]), float(x[1])
    candidates = []
    for fixed in (0, 1):
        free = 1 - fixed
        for value in (0.0, 1.0):
            rest = b - a[:, fixed] * value
            col = a[:, free]
            y = float(np.clip(col @ rest / (col @ col), 0.0, 1.0))
            x = np.empty(2)
            x[fixed], x[free] = value, y
            candidates.append((float(np.linalg.norm(a @ x - b)), float(x[0]), float(x[1])))
    _, w_inertia, w_gravity = min(candidates)
    return w_inertia, w_gravity


def validate_model(robot_preset: str, trajectory: str = "pick_place", ws=None, separate: bool = True,
                   masses=None, h: float = 2e-4, duration: float | None = None, fidelity: str = "full",
                   progress: Progress | None = None, w_rotation: float | None = None) -> ValidationReport:
    """Compare the analytic model's inverse dynamics with the Exudyn plant along a validation motion.

    The plant is driven along the joint motion of ``trajectory`` (:data:`VALIDATION_TRAJECTORIES`)
    and its drive reactions are compared with ``analytic_model(robot, masses with w).inverse_dynamics``.
    The analytic efforts are affine in ``w_inertia`` and ``w_gravity`` (both only scale masses
    that enter linearly), so three model evaluations give them for every split; the best splits
    are least-squares optima, and every reported row is evaluated with the model itself.

    Parameters
    ----------
    robot_preset : str
        Name in :data:`delta.robots.PRESETS`, e.g. "linear_delta_thesis", "rotary_delta_prototype".
    trajectory : {"helix", "pick_place"}
    ws : (K,) array, optional
        Single ``w`` values to sweep (``w_inertia = w_gravity = w``); default ``linspace(0, 1, 11)``.
    separate : bool
        Also find the best separate ``(w_inertia, w_gravity)``.
    masses : LinearDeltaMasses or RotaryDeltaMasses, optional
        Defaults of :mod:`delta.dynamics` (their ``w`` fields are ignored).
    h, duration : float
        Plant step (s; 0.2 ms keeps the integrator's damping of the reactions negligible) and
        simulated time (default: the whole trajectory).
    fidelity : {"full", "lumped"}
    progress : callable ``(done, total)``, optional
        Called as the plant advances (about a hundred times) and once per ``w`` evaluated.
    w_rotation : float, optional
        The share of the rods' rotational inertia in the model (:class:`delta.masses.LinearDeltaMasses`),
        held while ``w`` is swept; default: that of ``masses`` (0, the thesis's lumping, by default).

    Returns
    -------
    ValidationReport
    """
    robot = get_preset(robot_preset)
    motion = validation_trajectory(robot, trajectory)
    masses = masses or _default_masses(robot)
    if w_rotation is not None:
        masses = masses.with_(w_rotation=float(w_rotation))
    ws = np.linspace(0.0, 1.0, 11) if ws is None else np.asarray(ws, dtype=float).reshape(-1)
    end = float(motion.duration if duration is None else duration)
    n_steps = int(round(end / h))
    n_evals = 3 + len(ws) + 1 + (1 if separate else 0)
    total = n_steps + n_evals
    done = [n_steps]
    run = run_prescribed(robot, motion, masses, h=h, duration=end, fidelity=fidelity,
                         progress=None if progress is None else (lambda k, n: progress(k, total)))
    return _analyse(run, robot, trajectory, masses, ws, separate, h, end, fidelity, done, total, progress)


def _analyse(run: PrescribedRun, robot, trajectory: str, masses, ws, separate: bool, h: float, end: float,
             fidelity: str, done: list, total: int, progress: Progress | None) -> ValidationReport:
    """The sweep and the best splits of :func:`validate_model` on a recorded run."""

    def tick() -> None:
        done[0] += 1
        if progress is not None:
            progress(done[0], total)

    def efforts(w_inertia: float, w_gravity: float) -> np.ndarray:
        f = _model_efforts(run, robot, masses.with_(w_inertia=float(w_inertia), w_gravity=float(w_gravity)))
        tick()
        return f

    f_plant = run.f_plant
    f00, f10, f01 = efforts(0.0, 0.0), efforts(1.0, 0.0), efforts(0.0, 1.0)
    d_inertia, d_gravity = f10 - f00, f01 - f00
    sweep = tuple(_error(efforts(w, w), f_plant, w, w) for w in ws)
    best = min(sweep, key=lambda row: row.rms_rel)
    d_single = (d_inertia + d_gravity).ravel()
    residual = (f_plant - f00).ravel()
    w_single = None if not d_single.any() else float(np.clip(d_single @ residual / (d_single @ d_single), 0.0, 1.0))
    tick()
    split = None
    basis = np.column_stack([d_inertia.ravel(), d_gravity.ravel()])
    if separate and np.linalg.matrix_rank(basis) == 2:
        w_i, w_g = _unit_box_least_squares(basis, residual)
        split = _error(efforts(w_i, w_g), f_plant, w_i, w_g)
    elif separate:  # massless rods: w changes nothing, nothing to fit
        tick()
    unit = kind_of(robot.kind).units[3].replace(".", "*")  # N or N*m
    return ValidationReport(
        robot=robot.name, trajectory=trajectory, fidelity=fidelity, effort_unit=unit, h=float(h), duration=end,
        samples=len(run.t), plant_rms=float(np.sqrt(np.mean(f_plant**2))), plant_peak=float(np.max(np.abs(f_plant))),
        sweep=sweep, best=best, best_w_continuous=w_single, separate=split,
    )


# -- identify_model ---------------------------------------------------------------------------


@dataclass(frozen=True)
class TrajectoryFit:
    """How the identified split fits one validation motion: ``identified`` at the fitted split, ``default``
    at the mass dataclass's default (the thesis's ``w = 2/3``), both over the plant's ``samples`` efforts."""

    trajectory: str
    duration: float
    samples: int
    plant_rms: float
    plant_peak: float
    identified: WError
    default: WError


@dataclass(frozen=True)
class Identification:
    """The leg mass split that best fits the plant over one or more validation motions (:func:`identify_model`).

    ``w_inertia``, ``w_gravity`` minimise the sum over the motions of the squared effort errors, each motion's
    divided by its plant RMS (so that the fast cycle's large efforts do not drown the helix's); ``fits`` the
    errors per motion; ``reports`` each motion's own sweep (:func:`validate_model`).
    """

    robot: str
    fidelity: str
    effort_unit: str
    h: float
    w_inertia: float
    w_gravity: float
    fits: tuple[TrajectoryFit, ...]
    reports: tuple[ValidationReport, ...]
    w_rotation: float = 1.0

    def text(self) -> str:
        u = self.effort_unit
        names = " + ".join(f.trajectory for f in self.fits)
        lines = [f"identified on {names}: w_inertia = {self.w_inertia:.4f}, w_gravity = {self.w_gravity:.4f} "
                 f"(rods' rotational inertia share w_rotation = {self.w_rotation:g}, held)"]
        for f in self.fits:
            i, d = f.identified, f.default
            lines.append(f"  {f.trajectory}: RMS {100 * i.rms_rel:.3f} % ({i.rms_abs:.4g} {u}), peak "
                         f"{100 * i.peak_rel:.3f} %; at the default split ({d.w_inertia:.4g}, {d.w_gravity:.4g}): "
                         f"RMS {100 * d.rms_rel:.3f} %, peak {100 * d.peak_rel:.3f} %")
        return "\n".join(lines)


def identify_model(robot_preset: str, trajectories=("pick_place", "helix"), masses=None, h: float = 2e-4,
                   fidelity: str = "full", ws=None, progress: Progress | None = None,
                   w_rotation: float = 1.0) -> Identification:
    """Identify ``(w_inertia, w_gravity)`` of the analytic model against the Exudyn plant over several motions.

    The model fitted includes the rods' rotational inertia at ``w_rotation`` (default 1: uniform rods, see
    :mod:`delta.dynamics`; 0: the thesis's two point masses per rod); the default split it is compared with
    is ``masses`` as given (the thesis's, ``w = 2/3`` and no rod rotation, by default).

    Each motion of :data:`VALIDATION_TRAJECTORIES` is run once on the plant (prescribed joints, as in
    :func:`validate_model`). The analytic efforts are affine in both splits, so the joint fit is a linear
    least-squares problem over ``[0, 1]^2``: the rows of each motion are divided by its plant RMS (a relative
    fit, every motion weighted alike). The fast pick cycle determines the inertial split, the slow helix the
    gravity split (on the pick cycle alone the weight barely varies and ``w_gravity`` drifts to a bound).

    Returns
    -------
    Identification
    """
    robot = get_preset(robot_preset)
    masses = masses or _default_masses(robot)
    fitted_masses = masses.with_(w_rotation=float(w_rotation))
    ws = np.linspace(0.0, 1.0, 11) if ws is None else np.asarray(ws, dtype=float).reshape(-1)
    motions = [(name, validation_trajectory(robot, name)) for name in dict.fromkeys(trajectories)]
    if not motions:
        raise ParameterError("identify_model needs at least one validation trajectory")
    steps = [prescribed_steps(float(m.duration), h) for _, m in motions]
    total = sum(steps) + len(motions) * (5 + len(ws)) + 2 * len(motions)
    done = [0]

    def advance(k: int, _n: int, before: int) -> None:
        if progress is not None:
            progress(before + k, total)

    runs, reports, rows, rhs = [], [], [], []
    for (name, motion), n in zip(motions, steps):
        before = done[0]
        run = run_prescribed(robot, motion, masses, h=h, fidelity=fidelity,
                             progress=lambda k, m, b=before: advance(k, m, b))
        done[0] = before + n
        end = float(motion.duration)
        reports.append(_analyse(run, robot, name, fitted_masses, ws, True, h, end, fidelity, done, total, progress))
        f00 = _model_efforts(run, robot, fitted_masses.with_(w_inertia=0.0, w_gravity=0.0))
        f10 = _model_efforts(run, robot, fitted_masses.with_(w_inertia=1.0, w_gravity=0.0))
        f01 = _model_efforts(run, robot, fitted_masses.with_(w_inertia=0.0, w_gravity=1.0))
        scale = float(np.sqrt(np.mean(run.f_plant**2)))
        rows.append(np.column_stack([(f10 - f00).ravel(), (f01 - f00).ravel()]) / scale)
        rhs.append((run.f_plant - f00).ravel() / scale)
        runs.append((name, end, run))
    w_i, w_g = _unit_box_least_squares(np.vstack(rows), np.concatenate(rhs))
    fits = []
    for name, end, run in runs:
        f_plant = run.f_plant
        fitted = _error(_model_efforts(run, robot, fitted_masses.with_(w_inertia=w_i, w_gravity=w_g)), f_plant, w_i,
                        w_g)
        default = _error(_model_efforts(run, robot, masses), f_plant, masses.w_inertia, masses.w_gravity)
        done[0] += 2
        if progress is not None:
            progress(done[0], total)
        fits.append(TrajectoryFit(name, end, len(run.t), float(np.sqrt(np.mean(f_plant**2))),
                                  float(np.max(np.abs(f_plant))), fitted, default))
    unit = kind_of(robot.kind).units[3].replace(".", "*")
    return Identification(robot.name, fidelity, unit, float(h), w_i, w_g, tuple(fits), tuple(reports),
                          float(w_rotation))
