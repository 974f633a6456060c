"""The building blocks of a plant's Exudyn system (:class:`SystemBuilder`, a base of
:class:`multibody.plant.DeltaPlant`): bodies and point masses, the platform, the rods with their spherical joints
and distance constraints, weights, and loads driven through symbolic user functions.

Every body is created in its reference configuration at the reset pose with
the identity as reference rotation, so body-local axes coincide with the base
frame at ``reset`` time and inertia tensors are given in base-frame axes.
"""

from __future__ import annotations

import numpy as np

from delta.masses import lumps

from .inertia import rigid_body_inertia, rod_end_masses

__all__ = ["SystemBuilder", "MIN_ROD_MASS", "PLATFORM_THICKNESS"]


MIN_ROD_MASS = 1e-6
"""kg. A zero rod mass is represented by this in the rods' end masses (their weight stays zero), so that a rod's
end nodes keep a regular mass matrix."""

PLATFORM_THICKNESS = 0.01
"""Platform disc thickness, m (the full plants' platform inertia)."""


class SystemBuilder:
    """The methods a plant's ``_build`` adds its system with. They add to ``self.mbs`` (the plant's Exudyn system)
    and record what :meth:`multibody.plant.DeltaPlant.energy` and :meth:`multibody.plant.DeltaPlant.set_payload`
    read: ``self._bodies`` (body, mass, inertia), ``self._weights`` (body, local point, mass), ``self._point_masses``
    and ``self._symbolic``, all set up by :meth:`multibody.plant.DeltaPlant.reset`; they read ``self.robot``,
    ``self.masses``, ``self.fidelity`` and ``self.kind``."""

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
        """The platform body at (p0, v0) and its weight (a load even when it weighs nothing, for
        :meth:`multibody.plant.DeltaPlant.set_payload`):
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
