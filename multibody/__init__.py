"""Exudyn multibody plants of the linear and rotary delta (the ADAMS side of the platform).

``make_plant(robot, masses, fidelity, settings)`` builds a plant with a stepping API::

    plant = make_plant(get_preset("linear_delta_thesis"))
    plant.reset(p0=(0.0, 0.0, -0.45))
    out = plant.step(plant.time, 1e-3, u=(-5.0, -5.0, -5.0))   # PlantOutput

Fidelities: ``"full"`` (rigid rods with spherical joints, rigid platform) and ``"lumped"``
(rod masses lumped at the rod ends as the analytic model assumes, rods as distance constraints).
No renderer is ever started and no solution file is written.

``plant.get_state()`` / ``plant.set_state(state)`` save and restore the whole plant and solver state as
plain data (stepping on repeats the original bit for bit, in this plant or in another built alike), and
``plant.set_payload(kg)`` changes the payload in the running system.
"""

from __future__ import annotations

from delta.dynamics import LinearDeltaMasses, RotaryDeltaMasses
from delta.robots import Robot

from .errors import PlantError, RobotTypeError
from .linear import LinearDeltaPlant
from .plant import DeltaPlant, JointTrajectory, PlantOutput
from .rotary import RotaryDeltaPlant
from .settings import SolverSettings

__all__ = [
    "make_plant",
    "DeltaPlant",
    "LinearDeltaPlant",
    "RotaryDeltaPlant",
    "PlantOutput",
    "PlantError",
    "RobotTypeError",
    "SolverSettings",
    "JointTrajectory",
]


def make_plant(robot: Robot, masses: LinearDeltaMasses | RotaryDeltaMasses | None = None, fidelity: str = "full",
               settings: SolverSettings | None = None, p0=None, v0=(0.0, 0.0, 0.0), t0: float = 0.0,
               prescribed: JointTrajectory | None = None, h_nominal: float = 1e-3) -> DeltaPlant:
    """Build the Exudyn plant of ``robot``.

    Parameters
    ----------
    robot : LinearDelta or RotaryDelta
    masses : LinearDeltaMasses or RotaryDeltaMasses, optional
        Defaults of :mod:`delta.dynamics`.
    fidelity : {"full", "lumped"}
    settings : SolverSettings, optional
    p0, v0 : (3,) arrays, optional
        Initial platform position (default: linear (0, 0, -0.5) m, rotary (0, 0, home_z)) and velocity.
    prescribed : callable ``t -> (q, qd)``, optional
        Drive the joints along this motion (inverse dynamics); ``output.reaction`` is the drive effort.
    """
    kwargs = dict(fidelity=fidelity, settings=settings, v0=v0, t0=t0, prescribed=prescribed, h_nominal=h_nominal)
    if p0 is not None:
        kwargs["p0"] = p0
    plant = PLANTS.get(getattr(robot, "kind", None))
    if plant is None:
        raise RobotTypeError(f"make_plant: unknown robot type {type(robot).__name__}; expected LinearDelta or RotaryDelta")
    return plant(robot, masses, **kwargs)


PLANTS = {"linear": LinearDeltaPlant, "rotary": RotaryDeltaPlant}
"""Robot kind -> its Exudyn plant class."""
