"""Mass and inertia formulas of the plants' bodies: a rod as masses at its two ends, a cylinder's and a point
mass's inertia tensors, and Exudyn's rigid-body inertia of a given tensor."""

from __future__ import annotations

import numpy as np

__all__ = ["rod_end_masses", "rod_inertia", "point_inertia", "rigid_body_inertia"]


def rod_end_masses(mass: float, radius: float, length: float) -> tuple[float, float]:
    """A uniform rigid cylinder's kinetic energy as a quadratic form of its end velocities, kg:
    ``T = (a |v_A|^2 + 2 b v_A.v_B + a |v_B|^2) / 2``.

    Derivation: the centre moves with ``(v_A + v_B) / 2``, and a rod of constant length turns with
    ``|w_perp| = |v_B - v_A| / L`` (its ends' relative velocity is perpendicular to it), so with the
    transverse moment of inertia ``J = m (3 r^2 + L^2) / 12``
    ``T = m |v_A + v_B|^2 / 8 + J |v_B - v_A|^2 / (2 L^2)``: ``a = m / 4 + J / L^2``, ``b = m / 4 - J / L^2``
    (a thin rod, r = 0: m / 3 and m / 6). The spin about the rod's own axis is left out: between spherical
    joints nothing applies a torque about that axis, so a cylinder that starts without spin never spins
    (Euler's equations of an axisymmetric body). On the constraint |x_B - x_A| = L this is the cylinder's
    exact kinetic energy, constant in the ends' coordinates."""
    transverse = mass * (3.0 * radius**2 + length**2) / 12.0 / length**2
    return mass / 4.0 + transverse, mass / 4.0 - transverse


def rod_inertia(mass: float, radius: float, length: float, axis: np.ndarray) -> np.ndarray:
    """Inertia tensor (3, 3) of a solid cylinder about its centre, axis ``axis`` (unit), kg m^2."""
    axial = 0.5 * mass * radius**2
    transverse = mass * (3.0 * radius**2 + length**2) / 12.0
    aa = np.outer(axis, axis)
    return transverse * (np.eye(3) - aa) + axial * aa


def point_inertia(mass: float, r: np.ndarray) -> np.ndarray:
    """Parallel-axis term of a point mass at offset ``r`` from the reference point."""
    r = np.asarray(r, dtype=float)
    return mass * (float(r @ r) * np.eye(3) - np.outer(r, r))


def rigid_body_inertia(mass: float, tensor: np.ndarray):
    """``RigidBodyInertia`` without the triangle-inequality check: an arm carrying a rotor
    inertia about its axis (rotor lumped into the arm body) legitimately violates it."""
    import exudyn.utilities as eu

    out = eu.RigidBodyInertia(mass=mass, inertiaTensor=np.eye(3) * max(float(np.trace(tensor)), 1e-12),
                              com=[0.0, 0.0, 0.0])
    out.inertiaTensor = np.asarray(tensor, dtype=float)
    return out
