"""The robot model (immutable, compiled once) and its scratch data, in the style of Pinocchio.

:func:`build_model` compiles a geometry preset (:mod:`delta.robots`) and its masses
(:mod:`delta.masses`) into a :class:`Model`: per-leg directions and platform offsets,
rod length, joint limits, the actuator path (:mod:`delta.actuators`) and the mass
lumps of the analytic dynamics. A :class:`Data`, made from its model (``Data(model)``), holds the
quantities of one pose that the algorithms of :mod:`delta.kinematics` and :mod:`delta.dynamics`
compute and share (platform position, rods, Jacobian, its inverse), so a controller or an integrator
that asks for several terms at one ``q`` computes the kinematics once.

The per-pose fields are plain floats (the ``*_arr`` fields of the model serve the batch path): the
per-step path allocates no arrays.

Mass lumps: :func:`delta.masses.lumps` (thesis eqs. (28)-(29), Codourey's lumping for the rotary delta)
splits the rods between the platform (``m_p`` of the inertial and of the gravity terms) and the actuators,
whose constant inertia ``D`` and weight the actuator path makes of its lump (:meth:`delta.actuators.Rail.inertia`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from .actuators import SCALAR, Actuator, actuator_for
from .errors import ParameterError
from .masses import Lumps, Masses, lumps
from .robots import Robot

__all__ = ["Model", "Data", "build_model", "compile_model", "as_model"]


@dataclass(frozen=True, eq=False)
class Model:
    """Immutable description of one robot with its masses (build with :func:`build_model`).

    Attributes
    ----------
    robot, masses : the geometry preset and the mass parameters it was compiled from.
    actuator : the actuator path (:class:`delta.actuators.Rail` or :class:`~delta.actuators.Arm`).
    kind : ``"linear"`` or ``"rotary"``.
    legs : per leg ``(ex, ey, ox, oy)``: the unit radial direction ``e_i`` in the base plane and the
        horizontal offset ``o_i = b_i - R e_i = (r - R) e_i`` of the platform joint from the actuator
        axis (rail or motor), m.
    ex_arr, ey_arr, ox_arr, oy_arr : the same as (3,) arrays for the batch path.
    rod : rod length ``L``, m.  q_min, q_max : joint limits (m or rad).
    inertia : actuator lump ``D`` (kg or kg m^2).  platform_mass : ``m_p`` of the inertial terms, kg.
    platform_weight : ``m_p g`` of the gravity terms, N.  actuator_weight : see the actuator's ``weight``.
    rod_inertia : ``mu = -w_rotation m_l / 3``, kg: each leg's two rods' rotational inertia as a (negative)
        point mass moving with the rod vector ``l_i`` (see :mod:`delta.dynamics`); 0 in the thesis's lumping.
    lumps : the point masses all of these come from (:func:`delta.masses.lumps`).
    """

    robot: Robot
    masses: Masses
    actuator: Actuator
    kind: str
    legs: tuple[tuple[float, float, float, float], ...]
    ex_arr: np.ndarray
    ey_arr: np.ndarray
    ox_arr: np.ndarray
    oy_arr: np.ndarray
    rod: float
    q_min: float
    q_max: float
    inertia: float
    platform_mass: float
    platform_weight: float
    actuator_weight: float
    rod_inertia: float
    lumps: Lumps
    xp: Any = SCALAR
    """The number namespace of the per-pose algorithms (:data:`delta.actuators.SCALAR`; symbols when
    ``fmus.native`` traces the formulas to C)."""


class Data:
    """Scratch quantities of the last pose an algorithm evaluated (see :func:`delta.kinematics.update`), made
    from its model as Pinocchio's ``Data(model)``.

    ``model`` is the :class:`Model` whose pose the data holds, ``q`` (3 floats) the pose: together they key the
    forward-kinematics cache, so a data used with another model computes that model's pose instead of answering
    with the first one's (by identity: a model is compiled once, :func:`build_model`). ``p`` is the platform
    position; ``legs[i]`` holds, for leg i, ``(lx, ly, lz, d1x, d1y, d1z, l.B'', l.B')``: the rod
    ``l_i = p + b_i - B_i(q_i)``, the actuator tangent ``B_i'``, and the products ``l_i . B_i''`` and
    ``l_i . B_i'``; ``jinv`` the inverse task Jacobian ``J^-1`` row-major (9 floats) or None when not computed.
    """

    __slots__ = ("model", "q", "p", "legs", "jinv")

    def __init__(self, model: Model) -> None:
        if not isinstance(model, Model):
            raise TypeError(f"Data(model) needs the compiled delta.model.Model, got {type(model).__name__} "
                            "(delta.model.as_model gives the model of a robot preset or an AnalyticModel)")
        self.model = model
        self.q: tuple[float, float, float] | None = None
        self.p: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.legs: list[tuple[float, ...]] = []
        self.jinv: tuple[float, ...] | None = None


@lru_cache(maxsize=64)
def build_model(robot: Robot, masses: Masses | None = None) -> Model:
    """Compile ``robot`` and ``masses`` (default: the kind's mass defaults) into a :class:`Model`."""
    actuator = actuator_for(robot)
    if masses is None:
        masses = actuator.masses_type()
    elif not isinstance(masses, actuator.masses_type):
        raise ParameterError(f"{actuator.kind} delta {robot.name!r} needs {actuator.masses_type.__name__}, "
                             f"got {type(masses).__name__}")
    return compile_model(robot, masses, actuator)


def compile_model(robot: Any, masses: Any, actuator: Actuator, xp: Any = SCALAR) -> Model:
    """The :class:`Model` of validated ``robot`` and ``masses`` (or of objects with their attributes holding
    symbols, with the symbolic namespace ``xp``: ``fmus.native``), without the checks of :func:`build_model`."""
    angles = robot.leg_angles
    ex = tuple(xp.cos(a) for a in angles)
    ey = tuple(xp.sin(a) for a in angles)
    offset = actuator.offset
    ox, oy = tuple(offset * c for c in ex), tuple(offset * s for s in ey)
    lumped = lumps(masses, actuator.kind)
    arrays = (None,) * 4 if xp.symbolic else (np.array(ex), np.array(ey), np.array(ox), np.array(oy))
    return Model(
        robot=robot, masses=masses, actuator=actuator, kind=actuator.kind,
        legs=tuple(zip(ex, ey, ox, oy)),
        ex_arr=arrays[0], ey_arr=arrays[1], ox_arr=arrays[2], oy_arr=arrays[3],
        rod=actuator.rod, q_min=robot.q_min, q_max=robot.q_max,
        inertia=actuator.inertia(masses, lumped), platform_mass=lumped.platform_inertial,
        platform_weight=lumped.platform_weight_mass * masses.gravity,
        actuator_weight=actuator.weight(masses, lumped), rod_inertia=lumped.rod_inertia, lumps=lumped, xp=xp,
    )


def as_model(robot_or_model: Any) -> Model:
    """The :class:`Model` of a robot preset (default masses), the model itself, or the model of its
    numpy facade (:class:`delta.dynamics.AnalyticModel`, whose ``model`` it is)."""
    if isinstance(robot_or_model, Model):
        return robot_or_model
    inner = getattr(robot_or_model, "model", None)
    return inner if isinstance(inner, Model) else build_model(robot_or_model)
