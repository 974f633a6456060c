"""Parameter groups shared by the adapters: robot geometry and masses (paper presets)."""

from __future__ import annotations

from dataclasses import fields
from typing import Any

from delta.actuators import KINDS, kind_of
from delta.masses import validate as validate_masses
from delta.robots import Robot, get_preset
from delta.robots import validate as validate_robot

from .._names import axis_names, joint_names

__all__ = ["PRESET", "declared", "declare_robot", "robot_values", "robot_from", "declare_masses", "mass_values", "masses_from",
           "MASS_PARAMETERS", "GEOMETRY_PARAMETERS", "check_parameters", "q_units"]

PRESET = {kind: cls.preset for kind, cls in KINDS.items()}
"""Robot preset whose geometry gives the parameter start values of each robot kind's FMUs."""

_GEOMETRY = {
    "rail_radius": ("m", "planar distance from the base centre to each rail (thesis U_A)"),
    "base_radius": ("m", "distance from the base centre to each motor axis (seed 004 OF)"),
    "arm_length": ("m", "upper arm length (seed 004 rf)"),
    "forearm_length": ("m", "parallelogram forearm length (seed 004 re)"),
    "rod_length": ("m", "parallelogram rod length (thesis l)"),
    "platform_radius": ("m", "planar distance from the platform centre to each platform joint"),
}
_MASSES = {
    "carriage": ("mass.carriage", "kg", "mass of one carriage (thesis m_s)"),
    "motor_inertia": ("mass.motor_inertia", "kg.m2", "rotor and gearbox inertia about the motor axis"),
    "arm": ("mass.arm", "kg", "upper arm mass, uniform along the arm"),
    "elbow": ("mass.elbow", "kg", "concentrated mass at the elbow"),
    "rod": ("mass.rod", "kg", "mass of one parallelogram rod (thesis m_l); two per leg"),
    "rod_radius": ("geometry.rod_radius", "m", "rod radius (multibody rod inertia)"),
    "parallelogram_width": ("geometry.parallelogram_width", "m", "distance between the two rods of a leg"),
    "platform": ("mass.platform", "kg", "platform mass without payload (thesis m_p)"),
    "payload": ("mass.payload", "kg", "payload carried by the platform"),
    "w_inertia": ("model.w_inertia", "1", "share of each rod lumped at the platform, inertia terms (thesis w)"),
    "w_gravity": ("model.w_gravity", "1", "share of each rod lumped at the platform, gravity terms (thesis w)"),
    "w_rotation": ("model.w_rotation", "1", "share of the rods' rotational inertia about their centres (uniform rods: 1)"),
    "gravity": ("model.gravity", "m/s2", "gravitational acceleration along -z"),
}


def declared(adapter: type, kind: str | None, name: str) -> Any:
    """An instance of ``adapter`` for robot ``kind`` named ``name``, made in Python for its declarations (nothing is
    computed until it is started): what :meth:`fmus.definition.FmuDefinition.declared` gives, and what the native
    build reads the interface from (:func:`fmus.native.interface.interface`)."""
    return type(name, (adapter,), {"KIND": kind})(instance_name=name, resources="", visible=False)


def q_units(kind: str) -> tuple[str, str, str, str]:
    """Units of q, qd, qdd and u for a robot kind."""
    return kind_of(kind).units


def declare_robot(fmu, kind: str) -> None:
    """Fixed ``geometry.*`` parameters with the preset of ``kind`` as start values."""
    robot = get_preset(PRESET[kind])
    for f in fields(robot):
        if f.name in _GEOMETRY:
            unit, text = _GEOMETRY[f.name]
            fmu.parameter(f"geometry.{f.name}", float(getattr(robot, f.name)), unit, text)
    qu = q_units(kind)[0]
    fmu.parameter("geometry.q_min", float(robot.q_min), qu, "lower joint limit")
    fmu.parameter("geometry.q_max", float(robot.q_max), qu, "upper joint limit")
    fmu.parameters3(joint_names("geometry.leg_angle"), robot.leg_angles, "rad", "leg angle about +z from +x")


def robot_values(kind: str, values) -> dict:  # noqa: ANN001
    """The robot dataclass's geometry fields of ``kind`` from parameter values (FMU name -> value or symbol)."""
    cls = kind_of(kind).robot_type
    out = {f.name: values[f"geometry.{f.name}"] for f in fields(cls) if f.name in _GEOMETRY}
    out.update(leg_angles=tuple(values[n] for n in joint_names("geometry.leg_angle")),
               q_min=values["geometry.q_min"], q_max=values["geometry.q_max"])
    return out


def robot_from(fmu, kind: str) -> Robot:
    """The robot described by the current ``geometry.*`` parameter values (their checks name the parameters)."""
    check_parameters(kind, fmu.values)
    return kind_of(kind).robot_type(name=f"{PRESET[kind]} (FMU {fmu.modelName})", **robot_values(kind, fmu.values))


def _mass_class(kind: str):
    return kind_of(kind).masses_type


TUNABLE_MASSES = ("payload",)
"""Mass fields that may change during a run (FMI ``variability="tunable"``): a part picked and placed changes the
payload; every other mass and the geometry are fixed."""


def declare_masses(fmu, kind: str) -> None:
    """``mass.*`` / ``model.*`` parameters, start values from the mass dataclass defaults; those of
    :data:`TUNABLE_MASSES` tunable, the others fixed."""
    defaults = _mass_class(kind)()
    for f in fields(defaults):
        name, unit, text = _MASSES[f.name]
        fmu.parameter(name, float(getattr(defaults, f.name)), unit, text, tunable=f.name in TUNABLE_MASSES)


def mass_values(kind: str, values) -> dict:  # noqa: ANN001
    """The mass dataclass's fields of ``kind`` from parameter values (FMU name -> value or symbol)."""
    return {f.name: values[_MASSES[f.name][0]] for f in fields(_mass_class(kind))}


def masses_from(fmu, kind: str):
    """The mass dataclass of the current ``mass.*`` / ``model.*`` parameter values (their checks name the
    parameters)."""
    check_parameters(kind, fmu.values)
    return _mass_class(kind)(**mass_values(kind, fmu.values))


MASS_PARAMETERS = {field: name for field, (name, _, _) in _MASSES.items()}
"""The mass dataclasses' fields by the FMU parameters that hold them (``payload`` -> ``mass.payload``): the names the
checks of :mod:`delta.masses` use in our FMUs' messages, in both builds."""
GEOMETRY_PARAMETERS = {**{field: f"geometry.{field}" for field in _GEOMETRY},
                       "q_min": "geometry.q_min", "q_max": "geometry.q_max"}
"""The robot dataclasses' fields by the FMU parameters that hold them, as :data:`MASS_PARAMETERS`."""


def _unchecked(cls: type, values: dict):
    obj = object.__new__(cls)  # the dataclass's own check would name its class, not the FMU's parameters
    for name, value in values.items():
        object.__setattr__(obj, name, value)
    return obj


def check_parameters(kind: str, values) -> None:  # noqa: ANN001
    """The checks of :mod:`delta.robots` and :mod:`delta.masses` on the ``geometry.*`` and ``mass.*`` / ``model.*``
    parameters among ``values`` (FMU name -> number; a group absent is not checked), raised as they raise
    (:class:`~delta.errors.RobotError`, :class:`~delta.errors.ParameterError`) with the FMU's parameter names
    (``mass.payload must be >= 0, got -1.0``): what the FMUs refuse at initialization, which a master's pre-flight
    also checks by the same function before any FMU is instantiated."""
    cls = kind_of(kind)
    if all(name in values for name in _names_of(cls.masses_type)):
        validate_masses(_unchecked(cls.masses_type, mass_values(kind, values)), names=MASS_PARAMETERS)
    if "geometry.q_min" in values:
        robot = _unchecked(cls.robot_type, {"name": PRESET[kind], **robot_values(kind, values)})
        validate_robot(robot, names=GEOMETRY_PARAMETERS)


def _names_of(masses_type: type) -> set[str]:
    return {MASS_PARAMETERS[f.name] for f in fields(masses_type)}


def home(kind: str) -> tuple[float, float, float]:
    """Default platform position of each kind (plant initial state; linear = start of the default helix), m."""
    return kind_of(kind).home


def home_joints(kind: str) -> tuple[float, float, float]:
    """Joint values of the kind's home position for its preset (start values of the plant state)."""
    from delta.kinematics import ik

    return tuple(float(x) for x in ik(get_preset(PRESET[kind]), home(kind)).require())


def hold_effort(kind: str) -> tuple[float, float, float]:
    """Effort that holds the preset still at its home joints (start value of the plant inputs u)."""
    from delta.dynamics import gravity
    from delta.model import Data, build_model

    return gravity(model := build_model(get_preset(PRESET[kind])), Data(model), home_joints(kind))


P0, V0 = axis_names("initial.p"), axis_names("initial.v")


def declare_initial_state(fmu, kind: str) -> None:
    """``initial.p.*`` and ``initial.v.*``: the plant starts at this platform state (joints through IK)."""
    fmu.parameters3(P0, home(kind), "m", "initial platform position")
    fmu.parameters3(V0, (0.0, 0.0, 0.0), "m/s", "initial platform velocity")


def initial_joint_state(fmu, model) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """(q, qd) from the ``initial.p`` / ``initial.v`` parameters (raises if unreachable)."""
    from delta.kinematics import joint_state_from_platform

    q, qd, _ = joint_state_from_platform(model, fmu.vec(P0), fmu.vec(V0))
    return tuple(q.tolist()), tuple(qd.tolist())
