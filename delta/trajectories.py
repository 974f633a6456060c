"""Platform trajectories with analytic position, velocity and acceleration.

Every trajectory is a frozen dataclass with :meth:`Trajectory.evaluate` (one time),
:meth:`Trajectory.evaluate_scalar` (one time, plain floats: the per-step path of the
FMUs and co-simulation loops) and :meth:`Trajectory.sample` (vectorised), SI units (m, m/s, m/s**2, s), and
:meth:`Trajectory.check` against the workspace (:func:`delta.workspace.check_trajectory`).
Point-to-point motions use rest-to-rest cubic or quintic time scalings; before its
start and after its end a trajectory holds its first / last point at rest (the helix
is the exception: its formula is defined for every ``t``).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from bisect import bisect_left
from dataclasses import dataclass

import numpy as np

from .actuators import SCALAR
from .errors import ParameterError
from .robots import Robot
from .workspace import TrajectoryCheck, check_trajectory

__all__ = [
    "Trajectory",
    "Helix",
    "Hold",
    "PointToPoint",
    "PickAndPlace",
    "Waypoints",
    "seed004_z_steps",
    "PROFILES",
    "TYPES",
    "G0",
]

G0 = 9.80665
"""Standard gravity used to express accelerations in g, m/s^2."""

PROFILES = ("cubic", "quintic")
# Peak |s''| of the rest-to-rest scalings on tau in [0, 1]: cubic 6 (at the ends),
# quintic 10 / sqrt(3) (at tau = 1/2 -+ sqrt(3)/6).
_PEAK_SDD = {"cubic": 6.0, "quintic": 10.0 / math.sqrt(3.0)}

_Vec = tuple[float, float, float]


def _vec3(name: str, value: object) -> tuple[float, float, float]:
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ParameterError(f"{name} must be 3 finite numbers (x, y, z) in m, got {value!r}")
    return float(arr[0]), float(arr[1]), float(arr[2])


def _positive(cls: str, name: str, value: float, allow_inf: bool = False, xp=SCALAR) -> None:  # noqa: ANN001
    _require(xp.both(value > 0.0, True if allow_inf else xp.isfinite(value)),
             f"{cls}.{name} must be > 0{'' if allow_inf else ' and finite'}", value, xp)


def _require(ok, reason: str, value, xp) -> None:  # noqa: ANN001
    """A condition on a trajectory's parameters: raises on numbers, recorded on symbols (``fmus.native``)."""
    if not xp.check(ok, reason):
        raise ParameterError(f"{reason}, got {value!r}")


def _finite(name: str, values, xp) -> None:  # noqa: ANN001
    """Finite coordinates (on numbers :func:`_vec3` checked them when the trajectory was made)."""
    if xp.symbolic:
        for x in values:
            _require(xp.isfinite(x), f"{name} must be finite", x, xp)


def _profile(cls: str, profile: str) -> None:
    if profile not in PROFILES:
        raise ParameterError(f"{cls}.profile must be one of {PROFILES}, got {profile!r}")


def _scaling(profile: str, tau, xp=SCALAR):  # noqa: ANN001
    """Time scaling s(tau) and its derivatives d/dtau, d2/dtau2 on tau in [0, 1].

    ``tau`` is an array or a float; the same IEEE operations in the same order either way
    (``(1 - tau)**2`` is written as a product, which is what NumPy's ``**2`` computes), so
    the scalar and the vectorised paths agree bit for bit. On symbols (``xp.symbolic``) ``profile``
    is the index of the profile in :data:`PROFILES` (the native FMU's String parameter) and both
    scalings are traced, selected by ``where``.
    """
    if xp.symbolic:
        cubic, quintic = _scaling("cubic", tau), _scaling("quintic", tau)
        is_cubic = profile == PROFILES.index("cubic")
        return tuple(xp.where(is_cubic, c, q) for c, q in zip(cubic, quintic))
    if profile == "cubic":
        return tau * tau * (3.0 - 2.0 * tau), 6.0 * tau * (1.0 - tau), 6.0 - 12.0 * tau
    t2 = tau * tau
    rest = 1.0 - tau
    return (
        t2 * tau * (10.0 + tau * (-15.0 + 6.0 * tau)),
        30.0 * t2 * (rest * rest),
        60.0 * tau * (1.0 + tau * (-3.0 + 2.0 * tau)),
    )


class Trajectory(ABC):
    """Base class: a platform motion ``t -> (p, v, a)`` in the base frame."""

    duration: float
    """Length of the motion, s (``math.inf`` if endless); a :class:`PointToPoint` starts at ``t0``."""

    @property
    def end_time(self) -> float:
        """Time at which the motion ends, s."""
        return self.duration

    @abstractmethod
    def sample(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and accelerations at ``times`` (N,) s: three (N, 3) arrays."""

    def evaluate(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position (3,) m, velocity (3,) m/s and acceleration (3,) m/s^2 at time ``t`` s."""
        p, v, a = self.evaluate_scalar(t)
        return np.array(p), np.array(v), np.array(a)

    def evaluate_scalar(self, t: float) -> tuple[_Vec, _Vec, _Vec]:
        """:meth:`evaluate` as three ``(x, y, z)`` tuples of floats (no arrays: the per-step path).

        Subclasses compute it with ``math`` on floats, with the operations of :meth:`sample`
        in the same order, so both paths give the same numbers; this default samples.
        """
        p, v, a = self.sample(np.array([float(t)]))
        return tuple(p[0].tolist()), tuple(v[0].tolist()), tuple(a[0].tolist())

    def check(self, robot: Robot, dt: float = 0.01, singularity_margin: float | None = None) -> TrajectoryCheck:
        """Check positions sampled every ``dt`` s over ``[0, duration]`` against the workspace."""
        if not math.isfinite(self.end_time):
            raise ParameterError(f"{type(self).__name__}: cannot check an endless trajectory; give a finite duration")
        _positive(type(self).__name__ + ".check", "dt", dt)
        n = int(math.ceil(self.end_time / dt)) + 1
        times = np.linspace(0.0, self.end_time, n)
        return check_trajectory(robot, self.sample(times)[0], times, singularity_margin)


@dataclass(frozen=True)
class Helix(Trajectory):
    """Helix of thesis eq. (27): ``x = cx + rx cos(w t)``, ``y = cy + ry sin(w t)``, ``z = z0 + vz t``.

    Defaults are the platform's reference helix: centre (0, 0), radii 0.1 m,
    ``omega = pi`` rad/s, ``z0 = -0.45`` m, ``vz = -0.01`` m/s, 10 s.
    """

    centre: tuple[float, float] = (0.0, 0.0)
    rx: float = 0.1
    ry: float = 0.1
    omega: float = math.pi
    z0: float = -0.45
    vz: float = -0.01
    duration: float = 10.0

    def __post_init__(self) -> None:
        c = np.asarray(self.centre, dtype=float).reshape(-1)
        if c.shape != (2,):
            raise ParameterError(f"Helix.centre must be (x, y) in m, got {self.centre!r}")
        object.__setattr__(self, "centre", (float(c[0]), float(c[1])))
        self.validate()

    def validate(self, xp=SCALAR) -> None:  # noqa: ANN001
        """The conditions on the parameters (raised on numbers, recorded on symbols)."""
        for name in ("rx", "ry"):
            _require(getattr(self, name) >= 0.0, f"Helix.{name} must be >= 0 m", getattr(self, name), xp)
        _positive("Helix", "duration", self.duration, allow_inf=True, xp=xp)

    def sample(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(times, dtype=float).reshape(-1)
        w = self.omega
        c, s = np.cos(w * t), np.sin(w * t)
        p = np.stack([self.centre[0] + self.rx * c, self.centre[1] + self.ry * s, self.z0 + self.vz * t], axis=1)
        v = np.stack([-self.rx * w * s, self.ry * w * c, np.full_like(t, self.vz)], axis=1)
        a = np.stack([-self.rx * w * w * c, -self.ry * w * w * s, np.zeros_like(t)], axis=1)
        return p, v, a

    def evaluate_scalar(self, t: float, xp=SCALAR) -> tuple[_Vec, _Vec, _Vec]:  # noqa: ANN001
        """Thesis eq. (27) at ``t`` in the number namespace ``xp`` (symbols: ``fmus.native``)."""
        if not xp.symbolic:
            t = float(t)
        w = self.omega
        wt = w * t
        c, s = xp.cos(wt), xp.sin(wt)
        rx, ry, vz = self.rx, self.ry, self.vz
        return (
            (self.centre[0] + rx * c, self.centre[1] + ry * s, self.z0 + vz * t),
            (-rx * w * s, ry * w * c, vz if xp.symbolic else float(vz)),
            (-rx * w * w * c, -ry * w * w * s, 0.0),
        )


class _Segments(Trajectory):
    """Piecewise rest-to-rest moves: segment k goes from ``_p0[k]`` to ``_p1[k]`` over ``[_t0[k], _t1[k]]``."""

    _t0: np.ndarray
    _t1: np.ndarray
    _p0: np.ndarray
    _p1: np.ndarray

    def _set_segments(self, knots: list[tuple[float, float, tuple, tuple]], xp=SCALAR) -> None:  # noqa: ANN001
        if xp.symbolic:  # the knots as rows only (evaluate_scalar's view; no arrays of symbols)
            object.__setattr__(self, "_t1_list", [t1 for _, t1, _, _ in knots])
            object.__setattr__(self, "_rows", [(t0, t1, tuple(p0), tuple(b - a for a, b in zip(p0, p1)))
                                               for t0, t1, p0, p1 in knots])
            return
        arr = list(zip(*knots))
        object.__setattr__(self, "_t0", np.array(arr[0], dtype=float))
        object.__setattr__(self, "_t1", np.array(arr[1], dtype=float))
        object.__setattr__(self, "_p0", np.array(arr[2], dtype=float))
        object.__setattr__(self, "_p1", np.array(arr[3], dtype=float))
        # The same knots as float lists for evaluate_scalar: (t0, t1, p0, p1 - p0) per segment.
        delta = self._p1 - self._p0
        object.__setattr__(self, "_t1_list", self._t1.tolist())
        object.__setattr__(self, "_rows", [
            (t0, t1, tuple(p0), tuple(d))
            for t0, t1, p0, d in zip(self._t0.tolist(), self._t1.tolist(), self._p0.tolist(), delta.tolist())
        ])

    @property
    def end_time(self) -> float:
        return float(self._t1[-1])

    @property
    def peak_acceleration(self) -> float:
        """Largest |a| over the motion, m/s^2 (analytic: peak |s''| |delta p| / T^2 per segment)."""
        dist = np.linalg.norm(self._p1 - self._p0, axis=1)
        return float(np.max(_PEAK_SDD[self.profile] * dist / (self._t1 - self._t0) ** 2))

    def sample(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(times, dtype=float).reshape(-1)
        k = np.clip(np.searchsorted(self._t1, t, side="left"), 0, len(self._t1) - 1)
        span = self._t1[k] - self._t0[k]
        tau = np.clip((t - self._t0[k]) / span, 0.0, 1.0)
        moving = ((t > self._t0[k]) & (t < self._t1[k]))[:, None]
        s, sd, sdd = _scaling(self.profile, tau)
        delta = self._p1[k] - self._p0[k]
        p = self._p0[k] + delta * s[:, None]
        v = np.where(moving, delta * (sd / span)[:, None], 0.0)
        a = np.where(moving, delta * (sdd / span**2)[:, None], 0.0)
        return p, v, a

    def evaluate_scalar(self, t: float, xp=SCALAR) -> tuple[_Vec, _Vec, _Vec]:  # noqa: ANN001
        """The segment that ends at or after ``t`` (the last one after the end), at ``t``.

        On symbols the segment is chosen by ``where`` over all of them (the number of knots below ``t``
        is what ``bisect_left`` counts), and a segment of zero length (a hold or dwell of 0 s, which
        the float path leaves out) evaluates to its start point at rest."""
        t1s, where = self._t1_list, xp.where
        if xp.symbolic:
            t0, t1, p0, d = self._symbolic_segment(t, xp)
        else:
            t = float(t)
            k = bisect_left(t1s, t)  # np.searchsorted(side="left")
            if k > len(t1s) - 1:
                k = len(t1s) - 1
            t0, t1, p0, d = self._rows[k]
        span = t1 - t0
        span = span + (span == 0.0)  # a zero-length segment (symbols only): tau = 0, at rest
        tau = (t - t0) / span
        tau = where(tau < 0.0, 0.0, where(tau > 1.0, 1.0, tau))
        s, sd, sdd = _scaling(self.profile, tau, xp)
        p = (p0[0] + d[0] * s, p0[1] + d[1] * s, p0[2] + d[2] * s)
        if not xp.symbolic and not t0 < t < t1:
            return p, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
        vs, as_ = sd / span, sdd / (span * span)
        v, a = (d[0] * vs, d[1] * vs, d[2] * vs), (d[0] * as_, d[1] * as_, d[2] * as_)
        if xp.symbolic:
            moving = xp.both(t0 < t, t < t1)
            v, a = tuple(where(moving, x, 0.0) for x in v), tuple(where(moving, x, 0.0) for x in a)
        return p, v, a

    def _symbolic_segment(self, t, xp):  # noqa: ANN001, ANN202
        """On symbols: ``(t0, t1, p0, p1 - p0)`` of the segment at ``t``, chosen by ``where`` over every knot."""
        return _select(self._rows, sum(t1 < t for t1 in self._t1_list), xp.where)


def _select(rows: list, k, where) -> tuple:  # noqa: ANN001
    """On symbols: the row ``k`` of ``rows`` (``(t0, t1, p0, d)``; past the last: the last), by ``where``."""
    last = len(rows) - 1
    t0, t1, p0, d = rows[last]
    for i in range(last - 1, -1, -1):
        r0, r1, q0, e = rows[i]
        pick = k == i
        t0, t1 = where(pick, r0, t0), where(pick, r1, t1)
        p0 = tuple(where(pick, a, b) for a, b in zip(q0, p0))
        d = tuple(where(pick, a, b) for a, b in zip(e, d))
    return t0, t1, p0, d


@dataclass(frozen=True)
class Hold(_Segments):
    """The platform at rest at ``point`` (3,) m for ``duration`` s (regulation tests)."""

    point: tuple[float, float, float]
    duration: float = 1.0
    profile: str = "quintic"

    def __post_init__(self) -> None:
        object.__setattr__(self, "point", _vec3("Hold.point", self.point))
        _positive("Hold", "duration", self.duration)
        self._set_segments([(0.0, self.duration, self.point, self.point)])


@dataclass(frozen=True)
class PointToPoint(_Segments):
    """Rest-to-rest straight move from ``start`` to ``end`` (3,) m in ``duration`` s, starting at ``t0`` s.

    Before ``t0`` the platform rests at ``start``; :attr:`end_time` is ``t0 + duration``.

    ``profile``: ``"quintic"`` (zero velocity and acceleration at both ends) or
    ``"cubic"`` (zero velocity; acceleration jumps at the ends).
    """

    start: tuple[float, float, float]
    end: tuple[float, float, float]
    duration: float
    profile: str = "quintic"
    t0: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", _vec3("PointToPoint.start", self.start))
        object.__setattr__(self, "end", _vec3("PointToPoint.end", self.end))
        _profile("PointToPoint", self.profile)
        self.validate()
        self._set_segments(self.knots())

    def validate(self, xp=SCALAR) -> None:  # noqa: ANN001
        """The conditions on the parameters (raised on numbers, recorded on symbols)."""
        _finite("PointToPoint.start", self.start, xp)
        _finite("PointToPoint.end", self.end, xp)
        _positive("PointToPoint", "duration", self.duration, xp=xp)
        _require(xp.both(xp.isfinite(self.t0), self.t0 >= 0.0), "PointToPoint.t0 must be >= 0 s", self.t0, xp)

    def knots(self, xp=SCALAR) -> list:  # noqa: ANN001
        """(t0, t1, p0, p1) of each segment: a rest at ``start`` until ``t0`` (on symbols always, of zero
        length when ``t0`` = 0), then the move."""
        knots = [(0.0, self.t0, self.start, self.start)] if xp.symbolic or self.t0 > 0.0 else []
        knots.append((self.t0, self.t0 + self.duration, self.start, self.end))
        return knots


def _unit2(d, xp):  # noqa: ANN001, ANN202
    """The planar vector ``d`` scaled to unit length."""
    dx, dy = d
    n = xp.sqrt(dx * dx + dy * dy)
    return dx / n, dy / n


NATIVE_MAX_CYCLES = 16
"""Pick-and-place cycles a native FMU can generate (its code holds the knots of that many cycles)."""


def instance_like(obj, **changes):  # noqa: ANN001, ANN201
    """A copy of the dataclass instance ``obj`` with ``changes``, without ``__post_init__`` (its checks and
    derived fields): for formulas evaluated on symbols."""
    new = object.__new__(type(obj))
    new.__dict__.update(obj.__dict__)
    new.__dict__.update(changes)
    return new


def _starts(moves: list) -> list:
    """The start times of consecutive moves of durations ``moves`` from 0."""
    starts = [0.0]
    for m in moves[:-1]:
        starts.append(starts[-1] + m)
    return starts


def _legs_with_dwell(points: np.ndarray, starts: list[float], moves: list[float], dwell: float, xp=SCALAR
                     ) -> list[tuple[float, float, tuple, tuple]]:
    """Knots of the moves through ``points``, with a rest of ``dwell`` at each intermediate point (on symbols
    always, of zero length when ``dwell`` = 0)."""
    knots = []
    for k in range(len(points) - 1):
        t0 = starts[k]
        knots.append((t0, t0 + moves[k], tuple(points[k]), tuple(points[k + 1])))
        if (xp.symbolic or dwell > 0.0) and k < len(points) - 2:
            knots.append((t0 + moves[k], t0 + moves[k] + dwell, tuple(points[k + 1]), tuple(points[k + 1])))
    return knots


@dataclass(frozen=True)
class Waypoints(_Segments):
    """Rest-to-rest moves through ``points`` (K, 3) m, stopping at each one.

    Give either ``segment_time`` (s per move, plus ``dwell`` s at rest at every
    intermediate point) or ``times`` (K,) (arrival time of each point, increasing,
    ``times[0]`` = time at the first point; no dwell, hold by repeating a point).
    """

    points: tuple[tuple[float, float, float], ...]
    segment_time: float | None = None
    times: tuple[float, ...] | None = None
    dwell: float = 0.0
    profile: str = "quintic"

    def __post_init__(self) -> None:
        pts = np.asarray(self.points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2 or not np.all(np.isfinite(pts)):
            raise ParameterError(f"Waypoints.points must be K >= 2 points of (x, y, z) m, got shape {pts.shape}")
        object.__setattr__(self, "points", tuple(tuple(float(x) for x in row) for row in pts))
        _profile("Waypoints", self.profile)
        if (self.segment_time is None) == (self.times is None):
            raise ParameterError("Waypoints: give exactly one of segment_time (s per move) or times (arrival times)")
        self.validate()
        if self.segment_time is not None:
            self._set_segments(self.knots())
            return
        times = np.asarray(self.times, dtype=float).reshape(-1)
        if times.shape != (len(pts),) or times[0] < 0.0 or np.any(np.diff(times) <= 0.0):
            raise ParameterError(f"Waypoints.times must be {len(pts)} increasing times >= 0 s, got {self.times!r}")
        if self.dwell != 0.0:
            raise ParameterError("Waypoints: dwell applies to segment_time only; with times, repeat a point to rest")
        object.__setattr__(self, "times", tuple(float(t) for t in times))
        knots = [(0.0, float(times[0]), tuple(pts[0]), tuple(pts[0]))] if times[0] > 0.0 else []
        knots += _legs_with_dwell(pts, list(times[:-1]), list(np.diff(times)), 0.0)
        self._set_segments(knots)

    def validate(self, xp=SCALAR) -> None:  # noqa: ANN001
        """The conditions on the parameters (raised on numbers, recorded on symbols)."""
        for k, point in enumerate(self.points):
            _finite(f"Waypoints.points[{k}]", point, xp)
        _require(xp.both(self.dwell >= 0.0, xp.isfinite(self.dwell)), "Waypoints.dwell must be >= 0 s", self.dwell, xp)
        if self.segment_time is not None:
            _positive("Waypoints", "segment_time", self.segment_time, xp=xp)

    def knots(self, xp=SCALAR) -> list:  # noqa: ANN001
        """(t0, t1, p0, p1) of each segment with ``segment_time`` per move and ``dwell`` at each intermediate point."""
        pts = self.points
        step = self.segment_time + self.dwell
        starts = [k * step for k in range(len(pts) - 1)]
        return _legs_with_dwell(pts, starts, [self.segment_time] * (len(pts) - 1), self.dwell, xp)

    @property
    def duration(self) -> float:
        return self.end_time

    @property
    def arrival_times(self) -> np.ndarray:
        """Time at which each point is reached (at rest), (K,) s."""
        if self.times is not None:
            return np.asarray(self.times)
        step = self.segment_time + self.dwell
        return np.array([0.0] + [k * step + self.segment_time for k in range(len(self.points) - 1)])


@dataclass(frozen=True)
class PickAndPlace(_Segments):
    """Industrial pick-and-place cycle: ``up`` m, ``across`` m, ``down`` m, and back the same way.

    The platform starts at ``start`` (3,) m, rises by ``up``, moves ``across`` along the
    horizontal unit ``direction``, lowers by ``down`` (place), then returns: up by ``down``,
    back across, down by ``up``. Every leg is a rest-to-rest move (quintic by default,
    zero velocity at each of the seven stops). Leg times are proportional to
    ``sqrt(distance)`` so every leg reaches the same peak acceleration; the default
    ``cycle_time = 0.5`` s gives 69.7 m/s^2 = 7.1 g (quintic, 25/305/25 mm).
    """

    start: tuple[float, float, float]
    up: float = 0.025
    across: float = 0.305
    down: float = 0.025
    cycle_time: float = 0.5
    direction: tuple[float, float] = (1.0, 0.0)
    cycles: int = 1
    profile: str = "quintic"

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", _vec3("PickAndPlace.start", self.start))
        self.validate()
        d = np.asarray(self.direction, dtype=float).reshape(-1)
        if d.shape != (2,) or not np.linalg.norm(d) > 0.0:
            raise ParameterError(f"PickAndPlace.direction must be a non-zero (x, y) vector, got {self.direction!r}")
        if not (isinstance(self.cycles, int) and self.cycles >= 1):
            raise ParameterError(f"PickAndPlace.cycles must be an integer >= 1, got {self.cycles!r}")
        _profile("PickAndPlace", self.profile)
        object.__setattr__(self, "direction", tuple(float(x) for x in _unit2(self.direction, SCALAR)))
        self._set_segments(self.knots())

    def validate(self, xp=SCALAR) -> None:  # noqa: ANN001
        """The conditions on the numbers (raised on numbers, recorded on symbols); the direction's and the cycle
        count's type and shape are checked where the trajectory is made."""
        _finite("PickAndPlace.start", self.start, xp)
        for name in ("up", "across", "down", "cycle_time"):
            _positive("PickAndPlace", name, getattr(self, name), xp=xp)
        if xp.symbolic:
            dx, dy = self.direction
            _require(dx * dx + dy * dy > 0.0, "PickAndPlace.direction must be a non-zero (x, y) vector", self.direction,
                     xp)

    def knots(self, xp=SCALAR) -> list:  # noqa: ANN001
        """(t0, t1, p0, p1) of each segment, cycle after cycle.

        On symbols (``fmus.native``) ``cycles`` is a symbol too, checked here, and the knots are those of the first
        cycle: the cycle under way is found when the trajectory is evaluated (:meth:`_symbolic_segment`)."""
        if not xp.symbolic:
            pts, moves = self._cycle_plan()
            starts = _starts(moves)
            knots = []
            for c in range(self.cycles):
                knots += _legs_with_dwell(pts, [t + c * self.cycle_time for t in starts], moves, 0.0)
            return knots
        xp.check(xp.both(self.cycles >= 1, self.cycles <= NATIVE_MAX_CYCLES),
                 f"cycle.count must be a whole number from 1 to {NATIVE_MAX_CYCLES} in the native build")
        pts, moves = self._unit_plan(xp)
        return _legs_with_dwell(pts, _starts(moves), moves, 0.0, xp)

    def _unit_plan(self, xp):  # noqa: ANN001, ANN202
        """On symbols: :meth:`_cycle_plan` with ``direction`` made a unit vector (the float path does it when the
        trajectory is made)."""
        return instance_like(self, direction=_unit2(self.direction, xp))._cycle_plan(xp)

    def _symbolic_segment(self, t, xp):  # noqa: ANN001, ANN202
        """On symbols: the segment at ``t`` among the knots of :data:`NATIVE_MAX_CYCLES` cycles, those of the cycles
        beyond ``cycles`` replaced by a rest at the final point from the start of that cycle on (which is what the
        float path gives after the end), without tracing every knot: the knots' ends rise, so the cycles whose last
        move ended before ``t`` are counted first (``done``), then the segments of cycle ``done``, whose knots are
        computed for that index as the float path computes those of each cycle (the same roundings)."""
        pts, moves = self._unit_plan(xp)
        starts, ct = _starts(moves), self.cycle_time
        done = 0
        for c in range(NATIVE_MAX_CYCLES):
            done = done + xp.both(c < self.cycles, (starts[-1] + c * ct) + moves[-1] < t)
        rows = [(t0, t1, tuple(p0), tuple(b - a for a, b in zip(p0, p1)))
                for t0, t1, p0, p1 in _legs_with_dwell(pts, [s + done * ct for s in starts], moves, 0.0, xp)]
        t0, t1, p0, d = _select(rows, sum(t1 < t for _, t1, _, _ in rows), xp.where)
        _, _, last0, last1 = _legs_with_dwell(pts, starts, moves, 0.0, xp)[-1]
        end = tuple(a + (b - a) for a, b in zip(last0, last1))  # where the last move ends (its tau = 1)
        finished, where = done >= self.cycles, xp.where
        return (where(finished, done * ct, t0), where(finished, math.inf, t1),
                tuple(where(finished, e, x) for e, x in zip(end, p0)),
                tuple(where(finished, 0.0, x) for x in d))

    def _cycle_plan(self, xp=SCALAR) -> tuple[list[tuple], list]:  # noqa: ANN001
        """The seven stops of one cycle and the time of each move (proportional to sqrt(distance))."""
        ax, ay, az = self.start
        hx, hy = self.direction
        a = (ax, ay, az)
        b_up = (ax, ay, az + self.up)
        c_up = (ax + self.across * hx, ay + self.across * hy, b_up[2])
        place = (c_up[0], c_up[1], c_up[2] - self.down)
        pts = [a, b_up, c_up, place, c_up, b_up, a]
        roots = []
        for p, q in zip(pts, pts[1:]):
            dx, dy, dz = q[0] - p[0], q[1] - p[1], q[2] - p[2]
            roots.append(xp.sqrt(xp.sqrt(dx * dx + dy * dy + dz * dz)))
        total = roots[0]
        for r in roots[1:]:
            total = total + r
        return pts, [self.cycle_time * r / total for r in roots]

    @property
    def duration(self) -> float:
        return self.end_time

    @property
    def waypoints(self) -> np.ndarray:
        """The seven stops of one cycle (pick, up, across, place, up, back, pick), (7, 3) m."""
        return np.array(self._cycle_plan()[0])

    @property
    def waypoint_times(self) -> np.ndarray:
        """Times of every stop over all cycles, (6 cycles + 1,) s."""
        return np.concatenate([[0.0], self._t1])


SEED004_HOME = (0.0, 0.0, -0.411)
"""Seed 004 Fig. 24 home position of the rotary prototype, m."""


def seed004_z_steps(segment_time: float = 1.0, dwell: float = 0.5, home: tuple[float, float, float] = SEED004_HOME,
                    profile: str = "quintic") -> Waypoints:
    """Seed 004's experiment: home -> (0, 0, -0.561) -> (0, 0, -0.311) -> home, m (Fig. 24, Table 6)."""
    x, y, _ = home
    return Waypoints(points=(tuple(home), (x, y, -0.561), (x, y, -0.311), tuple(home)),
                     segment_time=segment_time, dwell=dwell, profile=profile)


TYPES: dict[str, type[Trajectory]] = {"helix": Helix, "pick_and_place": PickAndPlace,
                                      "point_to_point": PointToPoint, "waypoints": Waypoints}
"""A scenario's ``trajectory.type`` -> its class (constructor arguments: ``trajectory.params``)."""
