"""Exudyn plant of the linear delta (thesis preset and any :class:`delta.robots.LinearDelta`).

Full fidelity
    Three carriages on vertical prismatic rails, each leg a parallelogram of two rigid rods (solid cylinders of
    ``masses.rod`` kg and radius ``masses.rod_radius``) with spherical joints at both ends, ``masses.parallelogram_width``
    apart along the rail tangent, and a rigid free-floating platform (disc of radius ``platform_radius``, 10 mm
    thick) kept level by the parallelograms. A rod is represented by its two ends (its kinetic energy a constant
    quadratic form of their velocities, :func:`multibody.inertia.rod_end_masses`, its weight half at each end) and
    its length by one distance constraint: its lower end is a point of its carriage, its upper end a point node
    joined to the platform. The spin of a cylinder about its own axis is never excited between spherical joints
    and is left out; what remains is the rigid cylinder's motion exactly. Only the time discretisation differs
    from rigid bodies on Euler parameters: the helix golden baselines recorded with those hold to 4e-13 m, the
    7 g pick cycle's moved by 7.9e-9 m (tests/golden/README.md).
Lumped fidelity
    The analytic model's assumptions: each rod's mass split ``(1 - w)`` to the carriage
    and ``w`` to the platform (``masses.w_inertia`` for inertia, ``masses.w_gravity`` for
    the weight; :func:`delta.masses.lumps`), carriages and platform as point masses, each
    leg a single distance constraint of rod length between carriage joint and platform joint.

Carriages: an ideal prismatic rail locks every carriage motion but the travel, so a carriage is
modelled exactly as a 1-DOF body (``ObjectMass1D``) whose coordinate *is* ``q[i]`` (its rotational
inertia never enters); this removes six constraints per carriage from the rigid model. Its points move linearly
with ``q[i]``, so its mass and weight, and its rods' lower ends, are point masses of one constant mass matrix per
leg (:meth:`LinearDeltaPlant._add_leg`). The full model has 51 unknowns (27 coordinates, 24 constraint
equations); with the rods as rigid bodies on Euler parameters it had 95.

Actuator effort ``u[i]``: force on carriage i along +q (down the rail), N.
"""

from __future__ import annotations

import numpy as np

from delta.dynamics import LinearDeltaMasses
from delta.kinematics import actuator_points, joint_state_from_platform, leg_axes, platform_offsets
from delta.masses import lumps
from delta.robots import LinearDelta

from .errors import RobotTypeError
from .plant import DeltaPlant, JointTrajectory
from .settings import SolverSettings

__all__ = ["LinearDeltaPlant"]

RAIL = np.array([0.0, 0.0, -1.0])
"""Direction in which a carriage moves as its coordinate q grows (down its vertical rail)."""


class LinearDeltaPlant(DeltaPlant):
    """Exudyn plant of a linear delta; see the module docstring for the two fidelities.

    Parameters
    ----------
    robot : LinearDelta
    masses : LinearDeltaMasses, optional
    fidelity : {"full", "lumped"}
    settings : SolverSettings, optional
    p0, v0 : (3,) arrays
        Initial platform position and velocity (default: 0.5 m below the base, at rest).
    prescribed : callable, optional
        ``t -> (q, qd)``; if given, the carriages follow it exactly (drive constraints) and
        ``output.reaction`` is the drive force along +q (inverse dynamics).
    h_nominal : float
        Expected macro step, s (only used to initialise the solver; any h may be stepped).
    """

    kind = "linear"

    def __init__(self, robot: LinearDelta, masses: LinearDeltaMasses | None = None, fidelity: str = "full",
                 settings: SolverSettings | None = None, p0=(0.0, 0.0, -0.5), v0=(0.0, 0.0, 0.0),
                 t0: float = 0.0, prescribed: JointTrajectory | None = None, h_nominal: float = 1e-3) -> None:
        if not isinstance(robot, LinearDelta):
            raise RobotTypeError(f"LinearDeltaPlant needs a LinearDelta robot, got {type(robot).__name__}")
        super().__init__(robot, masses or LinearDeltaMasses(), fidelity, settings, prescribed, p0, v0, t0, h_nominal)

    # ------------------------------------------------------------------------------------
    def _build(self, p0: np.ndarray, v0: np.ndarray, t0: float) -> None:
        from exudyn.itemInterface import (
            CoordinateConstraint,
            DistanceConstraint,
            LoadCoordinate,
            Mass1D,
            MarkerBodyPosition,
            MarkerNodeCoordinate,
            Node1D,
            NodePointGround,
            ObjectGround,
        )

        robot, m = self.robot, self.masses
        mbs = self.mbs
        q0, qd0, _ = joint_state_from_platform(robot, p0, v0)
        self._q0 = q0
        e = leg_axes(robot)
        tangent = np.stack([-e[:, 1], e[:, 0], np.zeros(3)], axis=1)  # z x e_i
        b = platform_offsets(robot)
        B = actuator_points(robot, q0)
        length = robot.rod_length
        full = self.fidelity == "full"
        self._ground = mbs.AddObject(ObjectGround())
        lumped = lumps(m, self.kind)  # the rods' shares (lumped fidelity; in the full one the rods are bodies)
        self._add_platform(p0, v0)

        self._carriages: list[int] = []
        self._carriage_markers: list[int] = []
        ground_node = mbs.AddNode(NodePointGround(referenceCoordinates=[0.0, 0.0, 0.0]))
        ground_coord = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=ground_node, coordinate=0))
        rail_down = [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]  # local x -> global -z (RAIL)
        carriage_mass = lumped.actuator_alone if full else lumped.actuator_inertial
        carriage_weight = lumped.actuator_alone if full else lumped.actuator_weight_mass
        for i in range(3):
            # carriage on its rail: a 1-DOF node whose total coordinate is q_i (rail top at z = 0); the Mass1D is the
            # carriage's geometry (its points for the markers), its mass and weight are point masses of its leg
            node = mbs.AddNode(Node1D(referenceCoordinates=[float(q0[i])], initialCoordinates=[0.0],
                                      initialVelocities=[float(qd0[i])]))
            carriage = mbs.AddObject(Mass1D(mass=0.0, nodeNumber=node,
                                            referencePosition=[float(x) for x in robot.rail_radius * e[i]],
                                            referenceRotation=rail_down))
            self._carriages.append(carriage)
            self._joint_nodes.append(node)
            marker = mbs.AddMarker(MarkerBodyPosition(bodyNumber=carriage, localPosition=[0.0, 0.0, 0.0]))
            self._carriage_markers.append(marker)
            coord = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=node, coordinate=0))
            if self.prescribed is None:
                load = mbs.AddLoad(LoadCoordinate(markerNumber=coord, load=0.0))
                self._effort_values.append(self._symbolic_load(load, "loadUserFunction", 0.0))
            else:
                self._drives.append(mbs.AddObject(CoordinateConstraint(
                    markerNumbers=[ground_coord, coord], offsetUserFunction=self._coord_offset(i),
                    offsetUserFunction_t=self._coord_offset_t(i))))
            if full:
                offsets = [side * m.parallelogram_width * tangent[i] for side in (-0.5, 0.5)]
                self._add_leg(carriage, node, B[i], [(B[i] + o, p0 + b[i] + o) for o in offsets], v0)
            else:
                self._add_point_masses([node], RAIL.reshape(3, 1), B[i].reshape(1, 3), np.array([[carriage_mass]]),
                                       np.array([carriage_weight]))
                pm = mbs.AddMarker(MarkerBodyPosition(bodyNumber=self._platform, localPosition=list(b[i])))
                mbs.AddObject(DistanceConstraint(markerNumbers=[marker, pm], distance=length))

    def _add_leg(self, carriage: int, node: int, centre: np.ndarray, rods: list[tuple[np.ndarray, np.ndarray]],
                 v0: np.ndarray) -> None:
        """A full leg: the carriage (point mass at ``centre``) and its parallelogram's rods, each ``(lower, upper)``
        end at the reset pose, as one set of point masses (:meth:`multibody.builder.SystemBuilder._add_point_masses`).
        A rod's lower end is a point of the carriage, moving with ``RAIL * qd``: linear in the carriage's coordinate,
        it needs no coordinates and no joint of its own, only the rod's distance constraint to its upper end (a point
        node joined to the platform, :meth:`multibody.builder.SystemBuilder._add_rod_end`). Rod masses:
        :meth:`multibody.builder.SystemBuilder._rod_mass`."""
        m = self.masses
        ups = [self._add_rod_end(self._body_marker(carriage, low), low, up, v0) for low, up in rods]
        n = 1 + 3 * len(rods)
        points = [centre] + [end for rod in rods for end in rod]  # C, then each rod's lower and upper end
        jacobian = np.zeros((3 * len(points), n))
        jacobian[0:3, 0] = RAIL
        mass = np.zeros((len(points), len(points)))
        mass[0, 0] = m.carriage
        weight = np.full(len(points), 0.5 * m.rod)
        weight[0] = m.carriage
        for k, (low, up) in enumerate(rods):
            lo, hi = 1 + 2 * k, 2 + 2 * k  # point indices
            jacobian[3 * lo:3 * lo + 3, 0] = RAIL
            jacobian[3 * hi:3 * hi + 3, 1 + 3 * k:4 + 3 * k] = np.eye(3)
            mass[np.ix_([lo, hi], [lo, hi])] = self._rod_mass(low, up)
        self._add_point_masses([node] + ups, jacobian, np.stack(points), mass, weight)

    # prescribed-motion offsets (relative to the reset pose) ---------------------------
    def _coord_offset(self, i: int):
        def offset(mbs, t, item, l_offset):
            return float(self.prescribed(t)[0][i] - self._q0[i])  # node coordinate = displacement from q0
        return offset

    def _coord_offset_t(self, i: int):
        def offset_t(mbs, t, item, l_offset):
            return float(self.prescribed(t)[1][i])
        return offset_t
