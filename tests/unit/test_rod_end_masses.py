"""The rods of the Exudyn plants as masses at their two ends (multibody.inertia.rod_end_masses)."""

import numpy as np

from multibody.inertia import rod_end_masses, rod_inertia


def test_end_masses_give_the_rigid_cylinders_kinetic_energy():
    """For ends moving at constant distance (their relative velocity perpendicular to the rod), the quadratic form
    of the end velocities equals a solid cylinder's kinetic energy, translation of its centre plus rotation with
    its transverse moment of inertia (rod_inertia, the tensor the plants gave their rigid rods), spin excepted."""
    rng = np.random.default_rng(27)
    for _ in range(50):
        mass, radius, length = rng.uniform(0.01, 1.0), rng.uniform(0.0, 0.02), rng.uniform(0.1, 0.5)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        omega = rng.normal(size=3)
        omega -= (omega @ axis) * axis  # no spin about the rod's own axis
        v_a = rng.normal(size=3)
        v_b = v_a + np.cross(omega, length * axis)
        centre = 0.5 * (v_a + v_b)
        rigid = 0.5 * mass * centre @ centre + 0.5 * omega @ rod_inertia(mass, radius, length, axis) @ omega
        a, b = rod_end_masses(mass, radius, length)
        ends = 0.5 * (a * v_a @ v_a + 2.0 * b * v_a @ v_b + a * v_b @ v_b)
        assert abs(ends - rigid) <= 1e-13 * rigid, (ends, rigid)


def test_a_thin_rod_is_a_third_at_each_end_and_a_sixth_between():
    a, b = rod_end_masses(0.6, 0.0, 0.3)
    assert np.isclose(a, 0.2, rtol=0, atol=1e-15) and np.isclose(b, 0.1, rtol=0, atol=1e-15)
