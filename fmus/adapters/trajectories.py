"""Trajectory generator FMUs (delta.trajectories): time -> p_ref, v_ref, a_ref.

Robot-independent; the start values are the trajectory dataclasses' presets. Outputs are
evaluated at the FMU's current time (after ``doStep(t, h)`` they describe ``t + h``).

One adapter per entry of :data:`delta.trajectories.TYPES`, the single list of trajectory
types: :data:`ADAPTERS` maps every type to its adapter, and :mod:`fmus.registry` lists one FMU
per adapter. A type whose FMU interface is part of the platform's published names is declared
below with :func:`serves` (its FMU name, preset and parameter names); any other type gets an
adapter derived from its dataclass (:func:`derived_adapter`), so a new trajectory type needs
no edit here or in the registry.

Each adapter declares its parameters once, in ``PARAMS``: FMU name <-> dataclass field
(and element of a tuple field). The same table declares the FMI variables, builds the
trajectory from the parameter values (:meth:`_Trajectory.from_parameters`) and gives the
parameter values of a trajectory (:meth:`_Trajectory.parameters_of`), which the master
uses to set a component from the scenario's ``trajectory:`` section. What a trajectory FMU computes is its native
model's (:class:`fmus.native.models.Trajectory`: ``evaluate_scalar`` of the trajectory these parameters make), which
both builds evaluate (:mod:`fmus.traced`).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Callable, Mapping

from delta.errors import ParameterError
from delta.trajectories import TYPES, Helix, PickAndPlace, PointToPoint, seed004_z_steps

from ..export2 import Adapter, axis_names
from ..traced import TracedCS

P_REF, V_REF, A_REF = axis_names("p_ref"), axis_names("v_ref"), axis_names("a_ref")


@dataclass(frozen=True)
class Param:
    """One FMU parameter: ``name`` <-> ``getattr(trajectory, field)[at[0]][at[1]]...``."""

    name: str
    field: str
    at: tuple[int, ...] = ()
    unit: str | None = "m"
    description: str = ""
    cast: Callable[[Any], Any] = float


def _xyz(prefix: str, field: str, description: str, outer: tuple[int, ...] = ()) -> tuple[Param, ...]:
    """The three parameters ``prefix.x/.y/.z`` (or ``prefix[k].x ...``) of a (3,) m field."""
    return tuple(Param(name, field, outer + (i,), "m", f"{description} ({axis})")
                 for i, (axis, name) in enumerate(zip("xyz", axis_names(prefix))))


class _Trajectory(TracedCS, Adapter):
    """Base: ``TYPE`` (the scenario's trajectory type, a key of TYPES), ``FMU`` (the FMU's name),
    ``CLASS`` (``TYPES[TYPE]``), ``DEFAULT``, ``PARAMS`` and ``DESCRIPTION``."""

    TYPE: str
    FMU: str
    CLASS: type
    DEFAULT: Any
    PARAMS: tuple[Param, ...]
    DESCRIPTION: str
    LIMITS: str = ""  # what the FMU cannot represent, for error messages

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = self.DESCRIPTION
        defaults = self.parameters_of(self.DEFAULT)
        for p in self.PARAMS:
            self.parameter(p.name, defaults[p.name], p.unit, p.description)
        # functions of time and the parameters alone: no inputs
        self.outputs3(P_REF, "m", "desired platform position", depends=())
        self.outputs3(V_REF, "m/s", "desired platform velocity", depends=())
        self.outputs3(A_REF, "m/s2", "desired platform acceleration", depends=())

    @classmethod
    def from_parameters(cls, values: Mapping[str, Any], make: Callable[..., Any] | None = None):
        """The trajectory whose FMU parameters are ``values`` (name -> value, every name of ``PARAMS``), made by
        ``make(**fields)`` (default: the trajectory class; ``fmus.native`` passes symbols to an unchecked one)."""
        kwargs: dict[str, Any] = {}
        for p in cls.PARAMS:
            value = values[p.name] if make is not None else p.cast(values[p.name])
            if not p.at:
                kwargs[p.field] = value
                continue
            node = kwargs.setdefault(p.field, [])
            for i in p.at[:-1]:
                while len(node) <= i:
                    node.append([])
                node = node[i]
            while len(node) <= p.at[-1]:
                node.append(None)
            node[p.at[-1]] = value
        return (make or cls.CLASS)(**{k: _tuples(v) for k, v in kwargs.items()})

    @classmethod
    def parameters_of(cls, trajectory) -> dict[str, Any]:
        """FMU parameter values (name -> value) that make this FMU generate ``trajectory``.

        The inverse of :meth:`from_parameters`. Raises :class:`~delta.errors.ParameterError`
        (a ValueError) naming the field if the FMU cannot represent the trajectory (e.g. a number
        of waypoints other than its own), and :class:`TrajectoryTypeError` (a TypeError) for a
        trajectory of another type.
        """
        if type(trajectory) is not cls.CLASS:
            raise TrajectoryTypeError(f"{cls.__name__} generates {cls.CLASS.__name__}, got {type(trajectory).__name__}")
        out: dict[str, Any] = {}
        for p in cls.PARAMS:
            value = getattr(trajectory, p.field)
            try:
                for i in p.at:
                    value = value[i]
                out[p.name] = p.cast(value)
            except (IndexError, TypeError, ValueError):
                raise ParameterError(cls._unrepresentable(trajectory, p.field)) from None
        back = cls.from_parameters(out)
        for f in fields(trajectory):
            if getattr(back, f.name) != getattr(trajectory, f.name):
                raise ParameterError(cls._unrepresentable(trajectory, f.name))
        return out

    @classmethod
    def _unrepresentable(cls, trajectory, field: str) -> str:
        return (f"{cls.CLASS.__name__}.{field} = {getattr(trajectory, field)!r} cannot be set on this FMU"
                + (f" ({cls.LIMITS})" if cls.LIMITS else ""))


class TrajectoryTypeError(ParameterError, TypeError):
    """An adapter was asked for the parameters of a trajectory of another type."""


def _tuples(value):
    return tuple(_tuples(v) for v in value) if isinstance(value, list) else value


ADAPTERS: dict[str, type[_Trajectory]] = {}
"""Scenario trajectory type (every key of :data:`delta.trajectories.TYPES`, in its order) -> adapter."""


def serves(kind: str, fmu: str | None = None):
    """Class decorator: the adapter serves trajectory type ``kind`` (a key of TYPES) as FMU ``fmu``
    (default: the type's name). Sets ``TYPE``, ``FMU`` and ``CLASS`` and records it in ADAPTERS."""

    def declare(cls: type[_Trajectory]) -> type[_Trajectory]:
        if kind not in TYPES:  # a developer error, caught when this module is imported
            raise ParameterError(f"{cls.__name__}: {kind!r} is not a trajectory type; "
                                 f"valid types (delta.trajectories.TYPES): {', '.join(TYPES)}")
        cls.TYPE, cls.FMU, cls.CLASS = kind, fmu or kind, TYPES[kind]
        ADAPTERS[kind] = cls
        return cls

    return declare


def _params_of(prefix: str, field: str, value: Any, at: tuple[int, ...], unit: str | None,
               description: str) -> tuple[Param, ...]:
    """Parameters of one field value: a scalar is one parameter, a pair or triple of numbers
    ``prefix.x/.y(/.z)``, any other tuple ``prefix[1..n]`` element by element."""
    if isinstance(value, tuple):
        if len(value) in (2, 3) and all(isinstance(v, (int, float)) for v in value):
            names = [f"{prefix}.{axis}" for axis in "xyz"[:len(value)]]
            return tuple(Param(n, field, at + (i,), unit, f"{description} ({n[-1]})") for i, n in enumerate(names))
        return tuple(q for k, v in enumerate(value)
                     for q in _params_of(f"{prefix}[{k + 1}]", field, v, at + (k,), unit, f"{description} {k + 1}"))
    cast = str if isinstance(value, str) else int if isinstance(value, int) and not isinstance(value, bool) \
        else bool if isinstance(value, bool) else float
    return (Param(prefix, field, at, None if cast is str else unit, description, cast),)


def derived_adapter(kind: str) -> type[_Trajectory]:
    """An adapter for trajectory type ``kind`` derived from its dataclass: FMU ``kind``, preset
    ``TYPES[kind]()``, one parameter ``kind.field`` per field (elements of tuple fields as
    ``.x/.y/.z`` or ``[k]``), unit and description from the field's metadata (``unit``,
    ``description``) when it gives them. Fields whose default is None are not parameters
    (the FMU generates only trajectories that leave them None).
    """
    cls = TYPES[kind]
    try:
        default = cls()
    except TypeError as exc:  # a developer error, caught when this module is imported
        raise ParameterError(f"trajectory type {kind!r} ({cls.__name__}) has no preset ({exc}); give every field "
                             f"a default or declare its FMU with @serves({kind!r}) in {__name__}") from None
    params = tuple(p for f in fields(cls) if getattr(default, f.name) is not None
                   for p in _params_of(f"{kind}.{f.name}", f.name, getattr(default, f.name), (), f.metadata.get("unit"),
                                       f.metadata.get("description", f"{cls.__name__}.{f.name}")))
    end = getattr(default, "end_time", getattr(default, "duration", 1.0))
    summary = (cls.__doc__ or kind).strip().splitlines()[0]
    namespace = {"DEFAULT": default, "PARAMS": params, "EXPERIMENT": (0.0, float(end), 1e-3),
                 "DESCRIPTION": f"{cls.__name__} trajectory ({summary})",
                 "__doc__": f"{cls.__name__} trajectory generator (derived from its dataclass)."}
    return serves(kind)(type(f"{cls.__name__}Trajectory", (_Trajectory,), namespace))


@serves("helix")
class HelixTrajectory(_Trajectory):
    """Helix of thesis eq. (27)."""

    DEFAULT = Helix()
    DESCRIPTION = "Helix reference (thesis eq. 27): x = cx + rx cos(w t), y = cy + ry sin(w t), z = z0 + vz t"
    EXPERIMENT = (0.0, DEFAULT.duration, 1e-3)
    PARAMS = (
        Param("helix.centre.x", "centre", (0,), "m", "helix axis x"),
        Param("helix.centre.y", "centre", (1,), "m", "helix axis y"),
        Param("helix.rx", "rx", (), "m", "radius along x"),
        Param("helix.ry", "ry", (), "m", "radius along y"),
        Param("helix.omega", "omega", (), "rad/s", "angular rate"),
        Param("helix.z0", "z0", (), "m", "height at t = 0"),
        Param("helix.vz", "vz", (), "m/s", "vertical speed"),
        Param("helix.duration", "duration", (), "s", "duration of the motion"),
    )


@serves("point_to_point")
class PointToPointTrajectory(_Trajectory):
    """Rest-to-rest straight move (cubic or quintic time scaling)."""

    DESCRIPTION = "Rest-to-rest point-to-point platform move"
    DEFAULT = PointToPoint(start=(0.0, 0.0, -0.5), end=(0.1, 0.05, -0.55), duration=1.0)
    EXPERIMENT = (0.0, DEFAULT.end_time + 0.5, 1e-3)
    PARAMS = (
        *_xyz("move.start", "start", "start point"),
        *_xyz("move.end", "end", "end point"),
        Param("move.duration", "duration", (), "s", "duration of the move"),
        Param("move.t0", "t0", (), "s", "start time of the move"),
        Param("move.profile", "profile", (), None, "time scaling: quintic or cubic", str),
    )


@serves("pick_and_place", fmu="pick_place")
class PickAndPlaceTrajectory(_Trajectory):
    """Pick-and-place cycle (up, across, down and back)."""

    DEFAULT = PickAndPlace(start=(-0.1525, 0.0, -0.5))
    DESCRIPTION = "Pick-and-place cycle: up, across, down, and back"
    EXPERIMENT = (0.0, DEFAULT.end_time, 1e-3)
    PARAMS = (
        *_xyz("cycle.start", "start", "pick point"),
        Param("cycle.up", "up", (), "m", "lift height"),
        Param("cycle.across", "across", (), "m", "horizontal travel"),
        Param("cycle.down", "down", (), "m", "descent at the place point"),
        Param("cycle.time", "cycle_time", (), "s", "duration of one cycle"),
        Param("cycle.direction.x", "direction", (0,), "1", "horizontal travel direction x"),
        Param("cycle.direction.y", "direction", (1,), "1", "horizontal travel direction y"),
        Param("cycle.count", "cycles", (), None, "number of cycles", int),
        Param("cycle.profile", "profile", (), None, "time scaling: quintic or cubic", str),
    )


@serves("waypoints")
class WaypointsTrajectory(_Trajectory):
    """Rest-to-rest moves through four waypoints (default: seed 004's z-steps)."""

    DEFAULT = seed004_z_steps()
    DESCRIPTION = "Rest-to-rest moves through waypoints (default: seed 004 z-steps)"
    N_WAYPOINTS = len(DEFAULT.points)
    EXPERIMENT = (0.0, DEFAULT.end_time + 0.5, 1e-3)
    LIMITS = f"it takes {len(DEFAULT.points)} points with segment_time, dwell and profile; no times"
    PARAMS = (
        *(q for k in range(N_WAYPOINTS) for q in _xyz(f"waypoint[{k + 1}]", "points", f"waypoint {k + 1}", (k,))),
        Param("waypoints.segment_time", "segment_time", (), "s", "duration of each move"),
        Param("waypoints.dwell", "dwell", (), "s", "rest at each intermediate waypoint"),
        Param("waypoints.profile", "profile", (), None, "time scaling: quintic or cubic", str),
    )


for _kind in TYPES:  # every other type: an adapter derived from its dataclass, importable by its class name
    if _kind not in ADAPTERS:
        globals()[derived_adapter(_kind).__name__] = ADAPTERS[_kind]
ADAPTERS = {kind: ADAPTERS[kind] for kind in TYPES}  # TYPES order

