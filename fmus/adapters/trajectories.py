"""Trajectory generator FMUs (delta.trajectories): time -> p_ref, v_ref, a_ref.

Robot-independent; the start values are the trajectory dataclasses' presets. Outputs are
evaluated at the FMU's current time (after ``doStep(t, h)`` they describe ``t + h``).
"""

from __future__ import annotations

from dataclasses import fields

from delta.trajectories import Helix, PickAndPlace, PointToPoint, Waypoints, seed004_z_steps

from .._fmi import Adapter, axis_names

P_REF, V_REF, A_REF = axis_names("p_ref"), axis_names("v_ref"), axis_names("a_ref")


class _Trajectory(Adapter):
    def _declare_outputs(self) -> None:
        self.outputs3(P_REF, "m", "desired platform position")
        self.outputs3(V_REF, "m/s", "desired platform velocity")
        self.outputs3(A_REF, "m/s2", "desired platform acceleration")

    def make(self):
        raise NotImplementedError

    def start(self) -> None:
        self.trajectory = self.make()

    def refresh(self) -> None:
        p, v, a = self.trajectory.evaluate(self.time)
        self.put(P_REF, p)
        self.put(V_REF, v)
        self.put(A_REF, a)


class HelixTrajectory(_Trajectory):
    """Helix of thesis eq. (27)."""

    EXPERIMENT = (0.0, Helix().duration, 1e-3)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = "Helix reference (thesis eq. 27): x = cx + rx cos(w t), y = cy + ry sin(w t), z = z0 + vz t"
        h = Helix()
        self.parameter("helix.centre.x", h.centre[0], "m", "helix axis x")
        self.parameter("helix.centre.y", h.centre[1], "m", "helix axis y")
        self.parameter("helix.rx", h.rx, "m", "radius along x")
        self.parameter("helix.ry", h.ry, "m", "radius along y")
        self.parameter("helix.omega", h.omega, "rad/s", "angular rate")
        self.parameter("helix.z0", h.z0, "m", "height at t = 0")
        self.parameter("helix.vz", h.vz, "m/s", "vertical speed")
        self.parameter("helix.duration", h.duration, "s", "duration of the motion")
        self._declare_outputs()

    def make(self):
        v = self.values
        return Helix(centre=(v["helix.centre.x"], v["helix.centre.y"]), rx=v["helix.rx"], ry=v["helix.ry"],
                     omega=v["helix.omega"], z0=v["helix.z0"], vz=v["helix.vz"], duration=v["helix.duration"])


DEFAULT_P2P = PointToPoint(start=(0.0, 0.0, -0.5), end=(0.1, 0.05, -0.55), duration=1.0)
DEFAULT_PICK = PickAndPlace(start=(-0.1525, 0.0, -0.5))
DEFAULT_WAYPOINTS = seed004_z_steps()


class PointToPointTrajectory(_Trajectory):
    """Rest-to-rest straight move (cubic or quintic time scaling)."""

    EXPERIMENT = (0.0, DEFAULT_P2P.end_time + 0.5, 1e-3)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = "Rest-to-rest point-to-point platform move"
        d = DEFAULT_P2P
        self.parameters3(axis_names("move.start"), d.start, "m", "start point")
        self.parameters3(axis_names("move.end"), d.end, "m", "end point")
        self.parameter("move.duration", d.duration, "s", "duration of the move")
        self.parameter("move.t0", d.t0, "s", "start time of the move")
        self.parameter("move.profile", d.profile, None, "time scaling: quintic or cubic")
        self._declare_outputs()

    def make(self):
        return PointToPoint(start=tuple(self.vec(axis_names("move.start"))), end=tuple(self.vec(axis_names("move.end"))),
                            duration=self.values["move.duration"], profile=self.values["move.profile"],
                            t0=self.values["move.t0"])


class PickAndPlaceTrajectory(_Trajectory):
    """Pick-and-place cycle (up, across, down and back)."""

    EXPERIMENT = (0.0, DEFAULT_PICK.end_time, 1e-3)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = "Pick-and-place cycle: up, across, down, and back"
        d = DEFAULT_PICK
        self.parameters3(axis_names("cycle.start"), d.start, "m", "pick point")
        self.parameter("cycle.up", d.up, "m", "lift height")
        self.parameter("cycle.across", d.across, "m", "horizontal travel")
        self.parameter("cycle.down", d.down, "m", "descent at the place point")
        self.parameter("cycle.time", d.cycle_time, "s", "duration of one cycle")
        self.parameter("cycle.direction.x", d.direction[0], "1", "horizontal travel direction x")
        self.parameter("cycle.direction.y", d.direction[1], "1", "horizontal travel direction y")
        self.parameter("cycle.count", d.cycles, None, "number of cycles")
        self.parameter("cycle.profile", d.profile, None, "time scaling: quintic or cubic")
        self._declare_outputs()

    def make(self):
        v = self.values
        return PickAndPlace(start=tuple(self.vec(axis_names("cycle.start"))), up=v["cycle.up"],
                            across=v["cycle.across"], down=v["cycle.down"], cycle_time=v["cycle.time"],
                            direction=(v["cycle.direction.x"], v["cycle.direction.y"]), cycles=v["cycle.count"],
                            profile=v["cycle.profile"])


N_WAYPOINTS = len(DEFAULT_WAYPOINTS.points)


class WaypointsTrajectory(_Trajectory):
    """Rest-to-rest moves through four waypoints (default: seed 004's z-steps)."""

    EXPERIMENT = (0.0, DEFAULT_WAYPOINTS.end_time + 0.5, 1e-3)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = "Rest-to-rest moves through waypoints (default: seed 004 z-steps)"
        d = DEFAULT_WAYPOINTS
        for k, point in enumerate(d.points, start=1):
            self.parameters3(axis_names(f"waypoint[{k}]"), point, "m", f"waypoint {k}")
        self.parameter("waypoints.segment_time", d.segment_time, "s", "duration of each move")
        self.parameter("waypoints.dwell", d.dwell, "s", "rest at each intermediate waypoint")
        self.parameter("waypoints.profile", d.profile, None, "time scaling: quintic or cubic")
        self._declare_outputs()

    def make(self):
        v = self.values
        points = tuple(tuple(self.vec(axis_names(f"waypoint[{k}]"))) for k in range(1, N_WAYPOINTS + 1))
        return Waypoints(points=points, segment_time=v["waypoints.segment_time"], dwell=v["waypoints.dwell"],
                         profile=v["waypoints.profile"])
